"""Planar footstep geometry: where a commanded footstep puts the flying foot.

This is the one place that turns a policy's action into foot poses on the ground.  The 2D
backend uses it directly; the quintic walk engine uses it for its put-down targets, so 2D and 3D
agree on step limits, foot spacing, foot–foot interference and step duration.

Conventions (thesis Fig. 5.6): a footstep ``(x, y, theta)`` is relative to the flying foot's
*resting pose*, which has the support foot's x and heading and lies ``foot_distance`` to the
side.  So the landing pose relative to the support foot is ``(x, ±foot_distance + y, theta)``
(+ when the left foot flies).  A double step starts in left support (walk phase < 0.5): the
right foot flies first, then the left foot.  ``y`` is in the support frame (+ = left) for both
feet, not mirrored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from footsim.geometry import Pose2D, mean_pose
from footsim.walk import kernels


class Side(str, Enum):
    LEFT = "left"
    RIGHT = "right"

    @property
    def other(self) -> Side:
        return Side.RIGHT if self is Side.LEFT else Side.LEFT

    @property
    def sign(self) -> float:
        """+1 for the left side (robot frame +y), -1 for the right."""
        return 1.0 if self is Side.LEFT else -1.0


@dataclass(frozen=True)
class StepLimits:
    """Largest footstep per axis, relative to the resting pose (symmetric)."""

    x: float = 0.156
    y: float = 0.103
    theta: float = 0.764

    def __post_init__(self) -> None:
        for name in ("x", "y", "theta"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"StepLimits.{name} must be a positive number, got {value!r}")

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta], dtype=float)

    def clip(self, x: float, y: float, theta: float) -> tuple[float, float, float]:
        return (
            min(max(x, -self.x), self.x),
            min(max(y, -self.y), self.y),
            min(max(theta, -self.theta), self.theta),
        )


class Footstep(NamedTuple):
    """One footstep relative to the flying foot's resting pose (a tuple: cheap on hot paths)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


_INF = math.inf


def action_values(action) -> list[float]:
    """A 6-D action as 6 plain floats clipped to [-1, 1] (any array-like holding 6 values).

    Non-finite values raise ``ValueError`` (plain floats and lists: this runs every env step).
    """
    if type(action) is np.ndarray and action.shape == (6,) and action.dtype.char in "fd":
        values = action.tolist()
    else:
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (6,):
            raise ValueError(f"a double-step action has 6 values, got shape {np.shape(action)}")
        values = a.tolist()
    total = sum(values)
    if not -_INF < total < _INF:  # NaN or inf somewhere, or (rarely) finite values overflowing the sum
        for x in values:
            if not -_INF < x < _INF:  # NaN compares false
                raise ValueError(f"action contains NaN or inf: {values}")
    if -1.0 <= min(values) and max(values) <= 1.0:  # all finite here, so min and max are exact
        return values
    return [-1.0 if x < -1.0 else 1.0 if x > 1.0 else x for x in values]


class DoubleStep(NamedTuple):
    """The unit every controller emits: the right foot's step, then the left foot's."""

    first: Footstep  # right foot (flies in left support, phase < 0.5)
    second: Footstep  # left foot

    @classmethod
    def from_action(cls, action, limits: StepLimits) -> DoubleStep:
        """Scale a 6-D action in [-1, 1] by the step limits.

        Non-finite values raise ``ValueError``; finite values outside [-1, 1] are clipped.
        """
        return cls.from_unit(action_values(action), limits)

    @classmethod
    def from_unit(cls, v: list[float], limits: StepLimits) -> DoubleStep:
        """Scale 6 already validated and clipped values (see :func:`action_values`)."""
        lx, ly, lt = limits.x, limits.y, limits.theta
        return _new(
            cls, (_new(Footstep, (v[0] * lx, v[1] * ly, v[2] * lt)), _new(Footstep, (v[3] * lx, v[4] * ly, v[5] * lt)))
        )

    @classmethod
    def from_array(cls, values) -> DoubleStep:
        v = [float(x) for x in np.asarray(values, dtype=float).reshape(6)]
        return cls(Footstep(*v[:3]), Footstep(*v[3:]))

    def as_array(self) -> np.ndarray:
        f, s = self.first, self.second
        return np.array([f.x, f.y, f.theta, s.x, s.y, s.theta], dtype=float)

    def steps(self) -> tuple[tuple[Side, Footstep], tuple[Side, Footstep]]:
        return (Side.RIGHT, self.first), (Side.LEFT, self.second)


class FeetState(NamedTuple):
    left: Pose2D
    right: Pose2D

    def foot(self, side: Side) -> Pose2D:
        return self.left if side is Side.LEFT else self.right

    def with_foot(self, side: Side, pose: Pose2D) -> FeetState:
        return FeetState(pose, self.right) if side is Side.LEFT else FeetState(self.left, pose)

    @property
    def nav_pose(self) -> Pose2D:
        """The navigation frame: the mean of the two feet (thesis Fig. 5.1)."""
        return mean_pose(self.left, self.right)


def _overlap_band_y(x: float, theta: float, half_l: float, half_w: float) -> tuple[float, float] | None:
    """Lateral offsets y at which a foot at (x, y, theta) overlaps an identical foot at the origin:
    an interval, or None when some axis separates for every y (compiled:
    :func:`footsim.walk.kernels.overlap_band`, the separating-axis theorem on the four box axes)."""
    overlaps, lo, hi = kernels.overlap_band(float(x), math.cos(theta), math.sin(theta), float(half_l), float(half_w))
    return (lo, hi) if overlaps else None


def _overlap_band_y_reference(x: float, theta: float, half_l: float, half_w: float) -> tuple[float, float] | None:
    """:func:`_overlap_band_y` as a loop over the four axes (kept for the tests)."""
    c, s = math.cos(theta), math.sin(theta)
    lo, hi = -math.inf, math.inf
    for nx, ny in ((1.0, 0.0), (0.0, 1.0), (c, s), (-s, c)):
        reach = half_l * abs(nx) + half_w * abs(ny) + half_l * abs(nx * c + ny * s) + half_w * abs(-nx * s + ny * c)
        if abs(ny) < 1e-12:
            if abs(nx * x) > reach:
                return None
            continue
        a, b = (-reach - nx * x) / ny, (reach - nx * x) / ny
        lo, hi = max(lo, min(a, b)), min(hi, max(a, b))
        if lo > hi:
            return None
    return lo, hi


_ORIGIN = Pose2D()


@dataclass(frozen=True)
class FootstepGeometry:
    """Foot plate, spacing and limits: everything needed to place footsteps in the plane."""

    limits: StepLimits
    foot_length: float = 0.154
    foot_width: float = 0.106
    foot_distance: float = 0.1799
    min_foot_gap: float = 0.01  # feet closer than this count as interfering

    if TYPE_CHECKING:  # derived in __post_init__; declared for the type checker only (no dataclass fields)
        _half_gapped: tuple[float, float] = field(init=False)
        kernel_params: np.ndarray = field(init=False)
        _feet_at_origin: FeetState = field(init=False)

    def __post_init__(self) -> None:
        for name in ("foot_length", "foot_width", "foot_distance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"FootstepGeometry.{name} must be > 0, got {getattr(self, name)!r}")
        if self.min_foot_gap < 0:
            raise ValueError(f"FootstepGeometry.min_foot_gap must be >= 0, got {self.min_foot_gap!r}")
        # Derived constants of the hot path (the dataclass is frozen: set once here).
        object.__setattr__(
            self,
            "_half_gapped",
            (0.5 * (self.foot_length + self.min_foot_gap), 0.5 * (self.foot_width + self.min_foot_gap)),
        )
        # For the compiled placement (footsim.walk.kernels.land): the limits, the foot distance, the
        # distance beyond which the feet can't overlap (two circumradii) and the grown half plate.
        clear = math.hypot(self.foot_length + self.min_foot_gap, self.foot_width + self.min_foot_gap)
        object.__setattr__(
            self,
            "kernel_params",
            np.array(
                [self.limits.x, self.limits.y, self.limits.theta, self.foot_distance, clear, *self._half_gapped],
                dtype=np.float64,
            ),
        )
        # Every 2D episode starts standing at the origin (immutable, so shared).
        object.__setattr__(self, "_feet_at_origin", self._stance(_ORIGIN))
        # The resting pose must be interference-free at any allowed turn, or the lateral
        # back-off in ``landing`` could not find a valid pose.
        for theta in (-self.limits.theta, self.limits.theta):
            if self.feet_interfere(0.0, self.foot_distance, theta):
                raise ValueError(
                    "foot_distance is too small: the feet overlap at rest when a foot turns by "
                    f"{theta:.3f} rad (foot {self.foot_length} x {self.foot_width} m, gap {self.min_foot_gap} m)"
                )

    def initial_feet(self, pose: Pose2D = _ORIGIN) -> FeetState:
        """Feet standing side by side around ``pose`` (the navigation frame)."""
        return self._feet_at_origin if pose is _ORIGIN else self._stance(pose)

    def _stance(self, pose: Pose2D) -> FeetState:
        half = 0.5 * self.foot_distance
        return FeetState(pose.compose(Pose2D(0.0, half, 0.0)), pose.compose(Pose2D(0.0, -half, 0.0)))

    def _band(self, x: float, theta: float) -> tuple[float, float] | None:
        # Each plate grows by half the gap, so "overlap" means "closer than min_foot_gap".
        half_l, half_w = self._half_gapped
        return _overlap_band_y(x, theta, half_l, half_w)

    def feet_interfere(self, x: float, y: float, theta: float) -> bool:
        """Does a foot at (x, y, theta) relative to the other foot come closer than the gap?"""
        band = self._band(x, theta)
        return band is not None and band[0] < y < band[1]

    def landing(self, flying: Side, step: Footstep) -> tuple[Pose2D, Footstep, bool]:
        """Where the flying foot lands relative to the support foot.

        Returns ``(landing pose in the support frame, the footstep actually executed, interfered)``.
        The step is first clipped to the limits; if the foot would then come closer to the support
        foot than the gap, its lateral offset is backed off towards the resting pose to the edge
        of the overlap band — the foot–foot interference that makes inward steps shorter.
        """
        left = flying is Side.LEFT
        x, y, theta, interfered = kernels.land(left, float(step[0]), float(step[1]), float(step[2]), self.kernel_params)
        return (
            Pose2D(x, (self.foot_distance if left else -self.foot_distance) + y, theta),
            Footstep(x, y, theta),
            interfered,
        )

    def execute(self, feet: FeetState, double_step: DoubleStep, perturb=None):
        """Place both footsteps of a double step.

        ``perturb(pose) -> pose``, if given, moves each landed foot (execution noise); the next
        step then starts from where the foot really is.  Returns ``(feet after the first half
        step, feet after the second, executed DoubleStep, number of interfering steps)``.
        """
        # The right foot flies first (left support), then the left foot (right support).
        # Compiled placement (footsim.walk.kernels), tuple.__new__ below: this runs on every 2D env step.
        first, second = double_step
        left, g = feet[0], self.kernel_params
        if perturb is None:  # both footsteps in one call
            return placed_double_step(
                feet[0],
                kernels.place_double_step(
                    left[0], left[1], left[2], first[0], first[1], first[2], second[0], second[1], second[2], g
                ),
            )
        # the next step starts from where the perturbed foot really is
        rx, ry, rt, x1, y1, t1, hit_first = kernels.place_footstep(
            False, left[0], left[1], left[2], first[0], first[1], first[2], g
        )
        right = perturb(_new(Pose2D, (rx, ry, rt)))
        lx, ly, lt, x2, y2, t2, hit_second = kernels.place_footstep(
            True, right[0], right[1], right[2], second[0], second[1], second[2], g
        )
        left = perturb(_new(Pose2D, (lx, ly, lt)))
        return (
            _new(FeetState, (feet[0], right)),
            _new(FeetState, (left, right)),
            _new(DoubleStep, (_new(Footstep, (x1, y1, t1)), _new(Footstep, (x2, y2, t2)))),
            int(hit_first) + int(hit_second),
        )


def placed_double_step(left_before: Pose2D, placed) -> tuple[FeetState, FeetState, DoubleStep, int]:
    """:meth:`FootstepGeometry.execute`'s result from the left foot's pose before the double step
    and the first 14 values of :func:`footsim.walk.kernels.place_double_step` (or of a kernel that
    starts with them): ``(feet after the first half step, after the second, executed, interfering
    steps)``."""
    rx, ry, rt, x1, y1, t1, hit_first, lx, ly, lt, x2, y2, t2, hit_second = placed[:14]
    right = _new(Pose2D, (rx, ry, rt))
    return (
        _new(FeetState, (left_before, right)),
        _new(FeetState, (_new(Pose2D, (lx, ly, lt)), right)),
        _new(DoubleStep, (_new(Footstep, (x1, y1, t1)), _new(Footstep, (x2, y2, t2)))),
        int(hit_first) + int(hit_second),
    )


_new = tuple.__new__  # NamedTuple construction without the Python-level __new__
