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
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

import numpy as np

from footsim.geometry import Pose2D, mean_pose


class Side(str, Enum):
    LEFT = "left"
    RIGHT = "right"

    @property
    def other(self) -> "Side":
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
    for x in values:
        if not -_INF < x < _INF:  # NaN compares false
            raise ValueError(f"action contains NaN or inf: {values}")
    return [-1.0 if x < -1.0 else 1.0 if x > 1.0 else x for x in values]


class DoubleStep(NamedTuple):
    """The unit every controller emits: the right foot's step, then the left foot's."""

    first: Footstep  # right foot (flies in left support, phase < 0.5)
    second: Footstep  # left foot

    @classmethod
    def from_action(cls, action, limits: StepLimits) -> "DoubleStep":
        """Scale a 6-D action in [-1, 1] by the step limits.

        Non-finite values raise ``ValueError``; finite values outside [-1, 1] are clipped.
        """
        return cls.from_unit(action_values(action), limits)

    @classmethod
    def from_unit(cls, v: list[float], limits: StepLimits) -> "DoubleStep":
        """Scale 6 already validated and clipped values (see :func:`action_values`)."""
        lx, ly, lt = limits.x, limits.y, limits.theta
        return _new(cls, (_new(Footstep, (v[0] * lx, v[1] * ly, v[2] * lt)),
                          _new(Footstep, (v[3] * lx, v[4] * ly, v[5] * lt))))

    @classmethod
    def from_array(cls, values) -> "DoubleStep":
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

    def with_foot(self, side: Side, pose: Pose2D) -> "FeetState":
        return FeetState(pose, self.right) if side is Side.LEFT else FeetState(self.left, pose)

    @property
    def nav_pose(self) -> Pose2D:
        """The navigation frame: the mean of the two feet (thesis Fig. 5.1)."""
        return mean_pose(self.left, self.right)


def _overlap_band_y(x: float, theta: float, half_l: float, half_w: float) -> tuple[float, float] | None:
    """Lateral offsets y at which a foot at (x, y, theta) overlaps an identical foot at the origin.

    Separating-axis theorem on the four box axes: on axis n the boxes overlap iff
    |n·(x, y)| <= r_support(n) + r_flying(n), which bounds y linearly; the overlap set is the
    intersection of those bands (an interval), or None when some axis separates for every y.
    (The four axes (1, 0), (0, 1), (c, s), (−s, c) written out: this runs on most env steps.)
    """
    return _overlap_band_cs(x, math.cos(theta), math.sin(theta), half_l, half_w)


def _overlap_band_cs(x: float, c: float, s: float, half_l: float, half_w: float) -> tuple[float, float] | None:
    """:func:`_overlap_band_y` given ``c, s = cos(theta), sin(theta)``."""
    ac, as_ = abs(c), abs(s)
    # axis (1, 0): bounds x only
    if abs(x) > half_l + half_l * ac + half_w * as_:
        return None
    # axis (0, 1): |y| <= reach
    reach = half_w + half_l * as_ + half_w * ac
    lo, hi = -reach, reach
    # axis (c, s)
    reach = half_l * ac + half_w * as_ + half_l * abs(c * c + s * s) + half_w * abs(-c * s + s * c)
    if as_ < 1e-12:
        if abs(c * x) > reach:
            return None
    else:
        a, b = (-reach - c * x) / s, (reach - c * x) / s
        if a > b:
            a, b = b, a
        if a > lo:
            lo = a
        if b < hi:
            hi = b
        if lo > hi:
            return None
    # axis (−s, c)
    reach = half_l * as_ + half_w * ac + half_l * abs(-s * c + c * s) + half_w * abs(s * s + c * c)
    if ac < 1e-12:
        if abs(-s * x) > reach:
            return None
    else:
        a, b = (-reach + s * x) / c, (reach + s * x) / c
        if a > b:
            a, b = b, a
        if a > lo:
            lo = a
        if b < hi:
            hi = b
        if lo > hi:
            return None
    return lo, hi


def _overlap_band_y_reference(x: float, theta: float, half_l: float, half_w: float) -> tuple[float, float] | None:
    """:func:`_overlap_band_y` as a loop over the four axes (kept for the tests)."""
    c, s = math.cos(theta), math.sin(theta)
    lo, hi = -math.inf, math.inf
    for nx, ny in ((1.0, 0.0), (0.0, 1.0), (c, s), (-s, c)):
        reach = (half_l * abs(nx) + half_w * abs(ny)
                 + half_l * abs(nx * c + ny * s) + half_w * abs(-nx * s + ny * c))
        if abs(ny) < 1e-12:
            if abs(nx * x) > reach:
                return None
            continue
        a, b = (-reach - nx * x) / ny, (reach - nx * x) / ny
        lo, hi = max(lo, min(a, b)), min(hi, max(a, b))
        if lo > hi:
            return None
    return lo, hi


@dataclass(frozen=True)
class FootstepGeometry:
    """Foot plate, spacing and limits: everything needed to place footsteps in the plane."""

    limits: StepLimits
    foot_length: float = 0.154
    foot_width: float = 0.106
    foot_distance: float = 0.1799
    min_foot_gap: float = 0.01  # feet closer than this count as interfering

    def __post_init__(self) -> None:
        for name in ("foot_length", "foot_width", "foot_distance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"FootstepGeometry.{name} must be > 0, got {getattr(self, name)!r}")
        if self.min_foot_gap < 0:
            raise ValueError(f"FootstepGeometry.min_foot_gap must be >= 0, got {self.min_foot_gap!r}")
        # Derived constants of the hot path (the dataclass is frozen: set once here).
        object.__setattr__(self, "_clear", math.hypot(self.foot_length + self.min_foot_gap,
                                                      self.foot_width + self.min_foot_gap))
        object.__setattr__(self, "_half_gapped", (0.5 * (self.foot_length + self.min_foot_gap),
                                                  0.5 * (self.foot_width + self.min_foot_gap)))
        # The resting pose must be interference-free at any allowed turn, or the lateral
        # back-off in ``landing`` could not find a valid pose.
        for theta in (-self.limits.theta, self.limits.theta):
            if self.feet_interfere(0.0, self.foot_distance, theta):
                raise ValueError(
                    "foot_distance is too small: the feet overlap at rest when a foot turns by "
                    f"{theta:.3f} rad (foot {self.foot_length} x {self.foot_width} m, gap {self.min_foot_gap} m)"
                )

    def initial_feet(self, pose: Pose2D = Pose2D()) -> FeetState:
        """Feet standing side by side around ``pose`` (the navigation frame)."""
        half = 0.5 * self.foot_distance
        return FeetState(pose.compose(Pose2D(0.0, half, 0.0)), pose.compose(Pose2D(0.0, -half, 0.0)))

    @property
    def _clear_distance(self) -> float:
        return self._clear

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
        x, y, theta, interfered = self._land(flying is Side.LEFT, step[0], step[1], step[2])
        return Pose2D(x, (self.foot_distance if flying is Side.LEFT else -self.foot_distance) + y, theta), \
            Footstep(x, y, theta), interfered

    def _land(self, left: bool, x: float, y: float, theta: float) -> tuple[float, float, float, bool]:
        """:meth:`landing` on plain floats: the executed ``(x, y, theta)`` and whether it interfered."""
        lim = self.limits
        lx, ly, lt = lim.x, lim.y, lim.theta  # clip to the limits (= min(max(v, -l), l))
        x = -lx if x < -lx else lx if x > lx else x
        y = -ly if y < -ly else ly if y > ly else y
        theta = -lt if theta < -lt else lt if theta > lt else theta
        rest_y = self.foot_distance if left else -self.foot_distance
        if abs(rest_y + y) >= self._clear:  # farther apart than two circumradii: no overlap
            return x, y, theta, False
        half_l, half_w = self._half_gapped
        c, s = math.cos(theta), math.sin(theta)
        # The band lies within |y| <= its (0, 1)-axis bound: outside that, no overlap either.
        if abs(rest_y + y) >= half_w + half_l * abs(s) + half_w * abs(c):
            return x, y, theta, False
        band = _overlap_band_cs(x, c, s, half_l, half_w)
        interfered = band is not None and band[0] < rest_y + y < band[1]
        if interfered:  # the resting side of the band is clear (checked at construction)
            y = (band[1] if left else band[0]) - rest_y
        return x, y, theta, interfered

    def execute(self, feet: FeetState, double_step: DoubleStep, perturb=None):
        """Place both footsteps of a double step.

        ``perturb(pose) -> pose``, if given, moves each landed foot (execution noise); the next
        step then starts from where the foot really is.  Returns ``(feet after the first half
        step, feet after the second, executed DoubleStep, number of interfering steps)``.
        """
        # The right foot flies first (left support), then the left foot (right support).
        # Plain floats and tuple.__new__ below: this runs on every 2D env step.
        first, second = double_step
        left = feet[0]
        x, y, theta, hit_first = self._land(False, first[0], first[1], first[2])
        right = _place(left, x, y - self.foot_distance, theta)
        if perturb is not None:
            right = perturb(right)
        done_first = _new(Footstep, (x, y, theta))
        x, y, theta, hit_second = self._land(True, second[0], second[1], second[2])
        left = _place(right, x, y + self.foot_distance, theta)
        if perturb is not None:
            left = perturb(left)
        return (_new(FeetState, (feet[0], right)), _new(FeetState, (left, right)),
                _new(DoubleStep, (done_first, _new(Footstep, (x, y, theta)))), int(hit_first) + int(hit_second))


_new = tuple.__new__  # NamedTuple construction without the Python-level __new__
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_fmod, _cos, _sin = math.fmod, math.cos, math.sin


def _place(support: Pose2D, x: float, y: float, theta: float) -> Pose2D:
    """``support.compose(Pose2D(x, y, theta))`` without the intermediate tuple (same arithmetic)."""
    sx, sy, st = support
    c, s = _cos(st), _sin(st)
    wrapped = _fmod(st + theta + _PI, _TWO_PI)  # wrap_angle(st + theta), inlined
    if wrapped <= 0.0:
        wrapped += _TWO_PI
    return _new(Pose2D, (sx + c * x - s * y, sy + s * x + c * y, wrapped - _PI))
