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


@dataclass(frozen=True)
class Footstep:
    """One footstep relative to the flying foot's resting pose."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


@dataclass(frozen=True)
class DoubleStep:
    """The unit every controller emits: the right foot's step, then the left foot's."""

    first: Footstep  # right foot (flies in left support, phase < 0.5)
    second: Footstep  # left foot

    @classmethod
    def from_action(cls, action, limits: StepLimits) -> "DoubleStep":
        """Scale a 6-D action in [-1, 1] by the step limits.

        Non-finite values raise ``ValueError``; finite values outside [-1, 1] are clipped.
        """
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (6,):
            raise ValueError(f"a double-step action has 6 values, got shape {np.shape(action)}")
        if not np.isfinite(a).all():
            raise ValueError(f"action contains NaN or inf: {a.tolist()}")
        v = [min(max(x, -1.0), 1.0) for x in a.tolist()]
        lx, ly, lt = limits.x, limits.y, limits.theta
        return cls(Footstep(v[0] * lx, v[1] * ly, v[2] * lt), Footstep(v[3] * lx, v[4] * ly, v[5] * lt))

    @classmethod
    def from_array(cls, values) -> "DoubleStep":
        v = [float(x) for x in np.asarray(values, dtype=float).reshape(6)]
        return cls(Footstep(*v[:3]), Footstep(*v[3:]))

    def as_array(self) -> np.ndarray:
        f, s = self.first, self.second
        return np.array([f.x, f.y, f.theta, s.x, s.y, s.theta], dtype=float)

    def steps(self) -> tuple[tuple[Side, Footstep], tuple[Side, Footstep]]:
        return (Side.RIGHT, self.first), (Side.LEFT, self.second)


@dataclass(frozen=True)
class FeetState:
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


def _rect_corners(x: float, y: float, theta: float, half_l: float, half_w: float):
    c, s = math.cos(theta), math.sin(theta)
    return [
        (x + c * dx - s * dy, y + s * dx + c * dy)
        for dx, dy in ((half_l, half_w), (-half_l, half_w), (-half_l, -half_w), (half_l, -half_w))
    ]


def _rects_overlap(a, b) -> bool:
    """Separating-axis test for two convex quadrilaterals given by their corners."""
    for poly in (a, b):
        for i in range(4):
            x1, y1 = poly[i]
            x2, y2 = poly[(i + 1) % 4]
            nx, ny = y1 - y2, x2 - x1
            pa = [nx * px + ny * py for px, py in a]
            pb = [nx * px + ny * py for px, py in b]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True


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

    def feet_interfere(self, x: float, y: float, theta: float) -> bool:
        """Does a foot at (x, y, theta) relative to the other foot overlap it (with the gap)?"""
        hl = 0.5 * self.foot_length + 0.5 * self.min_foot_gap
        hw = 0.5 * self.foot_width + 0.5 * self.min_foot_gap
        # Cheap exit on the support foot's lateral axis (the separating axis in the common case):
        # the flying rectangle's half-extent along y is hl|sin θ| + hw|cos θ|.
        if abs(y) - (hl * abs(math.sin(theta)) + hw * abs(math.cos(theta))) > hw:
            return False
        return _rects_overlap(_rect_corners(0.0, 0.0, 0.0, hl, hw), _rect_corners(x, y, theta, hl, hw))

    def landing(self, flying: Side, step: Footstep) -> tuple[Pose2D, Footstep, bool]:
        """Where the flying foot lands relative to the support foot.

        Returns ``(landing pose in the support frame, the footstep actually executed, interfered)``.
        The step is first clipped to the limits; if the foot would then overlap the support foot,
        its lateral offset is backed off towards the resting pose (bisection) until it clears —
        this is the foot–foot interference that makes inward steps shorter than commanded.
        """
        x, y, theta = self.limits.clip(step.x, step.y, step.theta)
        rest_y = flying.sign * self.foot_distance
        interfered = False
        if self.feet_interfere(x, rest_y + y, theta):
            interfered = True
            lo, hi = 0.0, 1.0  # fraction of the commanded lateral offset; 0 is always clear
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                if self.feet_interfere(x, rest_y + mid * y, theta):
                    hi = mid
                else:
                    lo = mid
            y *= lo
        return Pose2D(x, rest_y + y, theta), Footstep(x, y, theta), interfered

    def execute(self, feet: FeetState, double_step: DoubleStep):
        """Place both footsteps of a double step.

        Returns ``(feet after the first half step, feet after the second, executed DoubleStep,
        number of interfering steps)``.
        """
        executed = []
        halves = []
        n_interfered = 0
        for flying, step in double_step.steps():
            support = feet.foot(flying.other)
            rel, done, interfered = self.landing(flying, step)
            feet = feet.with_foot(flying, support.compose(rel))
            executed.append(done)
            halves.append(feet)
            n_interfered += int(interfered)
        return halves[0], halves[1], DoubleStep(executed[0], executed[1]), n_interfered
