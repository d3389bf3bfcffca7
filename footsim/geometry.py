"""Planar (SE(2)) geometry shared by every part of footsim.

Poses are ``(x, y, theta)`` in metres and radians, theta wrapped to (-pi, pi].  The hot paths
(the 2D backend runs tens of thousands of steps per second) use plain ``math`` on floats, so
``Pose2D`` is a small immutable tuple rather than a numpy array.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

_TWO_PI = 2.0 * math.pi


def wrap_angle(angle: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    wrapped = math.fmod(angle + math.pi, _TWO_PI)
    if wrapped <= 0.0:
        wrapped += _TWO_PI
    return wrapped - math.pi


def wrap_angles(angles: np.ndarray) -> np.ndarray:
    """Vectorised :func:`wrap_angle`."""
    wrapped = np.mod(np.asarray(angles, dtype=float) + np.pi, _TWO_PI)
    wrapped = np.where(wrapped <= 0.0, wrapped + _TWO_PI, wrapped)
    return wrapped - np.pi


class Pose2D(NamedTuple):
    """A rigid planar transform / pose: translation (x, y) then rotation theta."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    @classmethod
    def of(cls, x: float, y: float, theta: float) -> Pose2D:
        """Build a pose with theta wrapped."""
        return cls(float(x), float(y), wrap_angle(float(theta)))

    def compose(self, other: Pose2D) -> Pose2D:
        """``self ∘ other``: ``other`` expressed in this pose's frame, returned in the world frame."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            wrap_angle(self.theta + other.theta),
        )

    def inverse(self) -> Pose2D:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, wrap_angle(-self.theta))

    def relative(self, other: Pose2D) -> Pose2D:
        """``other`` expressed in this pose's frame: ``self.inverse() ∘ other``."""
        dx, dy = other.x - self.x, other.y - self.y
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2D(c * dx + s * dy, -s * dx + c * dy, wrap_angle(other.theta - self.theta))

    def transform_point(self, px: float, py: float) -> tuple[float, float]:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return self.x + c * px - s * py, self.y + s * px + c * py

    def distance_to(self, other: Pose2D) -> float:
        return math.hypot(other.x - self.x, other.y - self.y)

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta], dtype=float)


def mean_pose(a: Pose2D, b: Pose2D) -> Pose2D:
    """Midpoint of two poses; heading is the circular mean (the bisector of the two headings)."""
    # = Pose2D(0.5 (a.x + b.x), 0.5 (a.y + b.y), wrap_angle(a.theta + 0.5 wrap_angle(b.theta - a.theta)))
    # with both wraps inlined: the 2D backend calls this several times per step.
    ax, ay, at = a
    bx, by, bt = b
    w = _fmod(bt - at + _PI, _TWO_PI)
    if w <= 0.0:
        w += _TWO_PI
    w = _fmod(at + 0.5 * (w - _PI) + _PI, _TWO_PI)
    if w <= 0.0:
        w += _TWO_PI
    return _new(Pose2D, (0.5 * (ax + bx), 0.5 * (ay + by), w - _PI))


_new = tuple.__new__
_PI = math.pi
_fmod = math.fmod
