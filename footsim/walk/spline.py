"""Quintic splines: the trajectory primitive of the walk engine.

A quintic segment is the unique degree-5 polynomial that matches position, velocity and
acceleration at both ends of an interval.  Chaining such segments through knots that each carry
(position, velocity, acceleration) gives a C2-continuous curve, which is why the walk engine
can rebuild its splines at every half step without jerking the joints.

:class:`PiecewiseQuintic` holds several channels at once (x, y, z, roll, pitch, yaw of a foot
or of the trunk), each with its own knot times, and evaluates all of them at an array of times
in one vectorised call: the walk engine evaluates a whole half step this way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

# A knot: (time, position) or (time, position, velocity) or (time, position, velocity, acceleration).
Knot = Sequence[float]


def quintic_coefficients(p0, v0, a0, p1, v1, a1, duration) -> np.ndarray:
    """Coefficients ``c0..c5`` (last axis) of ``p(t) = sum c_k t^k`` on ``[0, duration]``.

    All arguments broadcast against each other; the result has shape ``broadcast + (6,)``.
    """
    p0, v0, a0, p1, v1, a1, T = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (p0, v0, a0, p1, v1, a1, duration)))
    if np.any(T <= 0.0):
        raise ValueError("a quintic segment needs a positive duration")
    T2 = T * T
    T3 = T2 * T
    dp = p1 - p0
    c = np.empty(T.shape + (6,))
    c[..., 0] = p0
    c[..., 1] = v0
    c[..., 2] = 0.5 * a0
    c[..., 3] = (20.0 * dp - (8.0 * v1 + 12.0 * v0) * T - (3.0 * a0 - a1) * T2) / (2.0 * T3)
    c[..., 4] = (-30.0 * dp + (14.0 * v1 + 16.0 * v0) * T + (3.0 * a0 - 2.0 * a1) * T2) / (2.0 * T3 * T)
    c[..., 5] = (12.0 * dp - 6.0 * (v1 + v0) * T - (a0 - a1) * T2) / (2.0 * T3 * T2)
    return c


def evaluate_polynomial(coefficients: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of quintics ``coefficients[..., 6]`` at local times ``tau``."""
    c = coefficients
    c0, c1, c2, c3, c4, c5 = (c[..., k] for k in range(6))
    pos = c0 + tau * (c1 + tau * (c2 + tau * (c3 + tau * (c4 + tau * c5))))
    vel = c1 + tau * (2.0 * c2 + tau * (3.0 * c3 + tau * (4.0 * c4 + tau * 5.0 * c5)))
    acc = 2.0 * c2 + tau * (6.0 * c3 + tau * (12.0 * c4 + tau * 20.0 * c5))
    return pos, vel, acc


@dataclass(frozen=True)
class QuinticSegment:
    """One quintic on ``[0, duration]`` from end conditions (pos, vel, acc) at both ends."""

    coefficients: np.ndarray  # (6,)
    duration: float

    @classmethod
    def from_boundary(cls, start: Sequence[float], end: Sequence[float], duration: float) -> "QuinticSegment":
        """``start`` and ``end`` are ``(pos, vel, acc)``."""
        (p0, v0, a0), (p1, v1, a1) = start, end
        return cls(quintic_coefficients(p0, v0, a0, p1, v1, a1, duration), float(duration))

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at times ``t`` (array-like, seconds from the start)."""
        return evaluate_polynomial(self.coefficients, np.asarray(t, dtype=float))


class PiecewiseQuintic:
    """Several channels of piecewise quintic splines, each through its own knots.

    Every knot fixes position, velocity and acceleration (velocity and acceleration default to
    zero), so each channel is C2 at its knots.  Knot times of a channel must strictly increase.
    Times outside a channel's knot range extrapolate its first / last segment.
    """

    def __init__(self, channels: Sequence[Sequence[Knot]]):
        if len(channels) == 0:
            raise ValueError("a spline needs at least one channel")
        n_channels = len(channels)
        max_knots = max(len(knots) for knots in channels)
        if max_knots < 2:
            raise ValueError("every channel needs at least two knots")
        # Knots padded to a rectangular array; padding repeats the last knot's time as +inf so
        # that the segment search below never selects a padded segment.
        data = np.zeros((n_channels, max_knots, 4))
        data[:, :, 0] = np.inf
        n_segments = np.empty(n_channels, dtype=int)
        for c, knots in enumerate(channels):
            if len(knots) < 2:
                raise ValueError(f"channel {c} has {len(knots)} knot(s); at least two are needed")
            for k, knot in enumerate(knots):
                data[c, k, : len(knot)] = knot
            n_segments[c] = len(knots) - 1
        times = data[:, :, 0]
        valid_seg = np.arange(max_knots - 1)[None, :] < n_segments[:, None]
        durations = np.diff(times, axis=1)
        if np.any(~(durations[valid_seg] > 0.0)):
            raise ValueError("knot times must strictly increase within each channel")
        if not np.all(np.isfinite(data[:, :, 1:][np.isfinite(times)])):
            raise ValueError("knot positions, velocities and accelerations must be finite")
        start, end = data[:, :-1], data[:, 1:]
        safe_durations = np.where(valid_seg, durations, 1.0)
        self.coefficients = quintic_coefficients(
            start[..., 1], start[..., 2], start[..., 3], end[..., 1], end[..., 2], end[..., 3], safe_durations
        )  # (channels, max_knots - 1, 6)
        self.times = times  # (channels, max_knots), +inf padded
        self.n_segments = n_segments
        self._channel_index = np.arange(n_channels)[:, None]
        # Inner breakpoints (exclude first and last knot) for the segment search; padding = +inf.
        inner = np.full((n_channels, max(max_knots - 2, 1)), np.inf)
        for c in range(n_channels):
            inner[c, : n_segments[c] - 1] = times[c, 1 : n_segments[c]]
        self._inner = inner

    @property
    def n_channels(self) -> int:
        return self.times.shape[0]

    def start_time(self) -> np.ndarray:
        return self.times[:, 0].copy()

    def end_time(self) -> np.ndarray:
        return self.times[self._channel_index[:, 0], self.n_segments].copy()

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration of every channel at times ``t``: each ``(channels, len(t))``."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        segment = (t[None, :, None] >= self._inner[:, None, :]).sum(axis=2)  # (channels, n)
        coefficients = self.coefficients[self._channel_index, segment]  # (channels, n, 6)
        tau = t[None, :] - self.times[self._channel_index, segment]
        return evaluate_polynomial(coefficients, tau)

    def state(self, t: float) -> np.ndarray:
        """``(channels, 3)``: position, velocity, acceleration of every channel at one time."""
        pos, vel, acc = self.evaluate(np.array([t]))
        return np.stack([pos[:, 0], vel[:, 0], acc[:, 0]], axis=1)
