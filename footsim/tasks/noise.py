"""What the robot believes its pose is: localization noise (thesis 6.1), bias and delay.

Three optional, independent corruptions of the true planar pose, all in the robot frame:

* **Gaussian** (thesis): zero-mean noise drawn afresh every step, σx 0.05 m, σy 0.03 m,
  σθ 0.07 rad in the ``localization`` preset.
* **Bias** (per episode): an offset ``b ~ N(0, diag(bias_sigma_x, bias_sigma_y, bias_sigma_theta)²)``
  drawn once in :meth:`NoiseModel.reset` and applied unchanged for the whole episode — a
  localization that is consistently off, e.g. after a wrong relocalization.
* **Delay** (``delay_steps = k``): the observation is the believed pose of ``k`` steps ago (the
  localization lags the robot).  Before ``k`` steps have passed, the first believed pose of the
  episode is repeated (the robot stood at its start pose before the episode began).

The believed pose of step ``t`` is ``true_t ∘ b ∘ n_t`` (bias, then the fresh Gaussian ``n_t``, both
in the robot frame); the model returns the believed pose of step ``t - k``.

**Odometry fusion** (``odometry_weight = w``, an option beyond the thesis, off at 0): the robot keeps
its own estimate instead of taking each measurement as it comes.  It moves the last estimate by the
walk's odometry of the step (the displacement the walk planned, :meth:`footsim.env.FootstepEnv.step`:
exact in plain 2D, blind to 2D footstep-landing randomization or a calibrated execution model and to
3D slip and creep) and blends it with the new measurement:
``estimate = predicted + (1 - w) (measured - predicted)`` per component (the angle wrapped).  For a
measurement with independent noise of spread σ and exact odometry the estimate's spread settles
at ``σ √((1 - w) / (1 + w))`` (half of σ at w = 0.6); an odometry error e per step leaves a bias of
about ``w e / (1 - w)``.  The first step of an episode, which has no odometry yet, takes the
measurement.  Fusion acts only on a noisy measurement (with no noise the robot knows its pose).
With a delay as well, the delayed measurement is blended with the current step's odometry, so the
estimate lags by the delay as the measurement does.

Random numbers are drawn only for the active parts, so switching bias or delay on leaves the
Gaussian stream of a preset unchanged, and switching everything off draws nothing.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.utils import check_count

SIGMA_KEYS = ("sigma_x", "sigma_y", "sigma_theta", "bias_sigma_x", "bias_sigma_y", "bias_sigma_theta")


@dataclass
class NoiseModel:
    """Noise configuration plus the per-episode state (bias, delay buffer) of one env."""

    sigma_x: float = 0.0
    sigma_y: float = 0.0
    sigma_theta: float = 0.0
    bias_sigma_x: float = 0.0
    bias_sigma_y: float = 0.0
    bias_sigma_theta: float = 0.0
    delay_steps: int = 0
    odometry_weight: float = 0.0

    _bias: Pose2D = field(default=Pose2D(), init=False, repr=False, compare=False)
    _history: deque = field(default_factory=deque, init=False, repr=False, compare=False)
    _estimate: Pose2D | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for key in SIGMA_KEYS:
            value = getattr(self, key)
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"noise.{key} must be a number >= 0, got {value!r}")
        self.delay_steps = check_count("noise.delay_steps", self.delay_steps)
        self._history = deque(maxlen=self.delay_steps + 1)
        w = self.odometry_weight
        if isinstance(w, bool) or not (isinstance(w, (int, float)) and 0.0 <= w < 1.0):
            raise ValueError(f"noise.odometry_weight must be a number in [0, 1), got {w!r}")
        self.odometry_weight = float(w)

    # -- what is switched on -------------------------------------------------------------
    @property
    def gaussian(self) -> bool:
        return self.sigma_x > 0 or self.sigma_y > 0 or self.sigma_theta > 0

    @property
    def biased(self) -> bool:
        return self.bias_sigma_x > 0 or self.bias_sigma_y > 0 or self.bias_sigma_theta > 0

    @property
    def active(self) -> bool:
        return self.gaussian or self.biased or self.delay_steps > 0

    @property
    def bias(self) -> Pose2D:
        """This episode's bias (robot frame); zero before the first :meth:`reset` or when off."""
        return self._bias

    # -- per episode / per step ------------------------------------------------------------
    def reset(self, rng: np.random.Generator) -> None:
        """Start an episode: draw the bias (if configured) and forget the delayed poses."""
        if self.biased:
            bx, by, bt = rng.normal(0.0, 1.0, size=3) * (self.bias_sigma_x, self.bias_sigma_y, self.bias_sigma_theta)
            self._bias = Pose2D(float(bx), float(by), float(bt))
        else:
            self._bias = Pose2D()
        self._history.clear()
        self._estimate = None

    def believe(self, true_pose: Pose2D, rng: np.random.Generator, odometry: Pose2D | None = None) -> Pose2D:
        """The pose the robot believes it has this step (call once per step, after :meth:`reset`);
        ``odometry``: the walk's displacement over the step in the robot frame (None: unknown)."""
        if not (
            self.sigma_x > 0
            or self.sigma_y > 0
            or self.sigma_theta > 0
            or self.bias_sigma_x > 0
            or self.bias_sigma_y > 0
            or self.bias_sigma_theta > 0
            or self.delay_steps > 0
        ):
            return true_pose  # not self.active, written out: this runs every env step
        pose = true_pose
        if self.biased:
            pose = pose.compose(self._bias)
        if self.gaussian:
            nx, ny, nt = rng.normal(0.0, 1.0, size=3) * (self.sigma_x, self.sigma_y, self.sigma_theta)
            pose = pose.compose(Pose2D(float(nx), float(ny), float(nt)))
        if self.delay_steps > 0:
            self._history.append(pose)  # maxlen k+1: the oldest entry is the pose of k steps ago
            pose = self._history[0]
        if self.odometry_weight == 0.0:
            return pose
        return self._fuse(pose, odometry)

    def _fuse(self, measured: Pose2D, odometry: Pose2D | None) -> Pose2D:
        """The new estimate: the last one moved by ``odometry``, blended with ``measured``."""
        if self._estimate is None or odometry is None:
            self._estimate = measured
            return measured
        predicted = self._estimate.compose(odometry)
        gain = 1.0 - self.odometry_weight
        self._estimate = Pose2D(
            predicted.x + gain * (measured.x - predicted.x),
            predicted.y + gain * (measured.y - predicted.y),
            wrap_angle(predicted.theta + gain * wrap_angle(measured.theta - predicted.theta)),
        )
        return self._estimate
