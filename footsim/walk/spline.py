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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from footsim.compiled import compiled

_POWERS = np.arange(6.0)
_ZEROS = {1: (0.0, 0.0, 0.0), 2: (0.0, 0.0), 3: (0.0,), 4: ()}  # a knot's missing (vel, acc) entries
_VEL_FACTORS = np.arange(1.0, 6.0)  # d/dt t^k = k t^(k-1)
_ACC_FACTORS = np.array([2.0, 6.0, 12.0, 20.0])  # d2/dt2 t^k = k (k-1) t^(k-2)

# A knot: (time, position) or (time, position, velocity) or (time, position, velocity, acceleration).
Knot = Sequence[float]


def quintic_coefficients(p0, v0, a0, p1, v1, a1, duration) -> np.ndarray:
    """Coefficients ``c0..c5`` (last axis) of ``p(t) = sum c_k t^k`` on ``[0, duration]``.

    All arguments broadcast against each other; the result has shape ``broadcast + (6,)``.
    """
    p0, v0, a0, p1, v1, a1, T = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (p0, v0, a0, p1, v1, a1, duration))
    )
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


@compiled
def _quintic_high(dp, v0, a0, v1, a1, T):
    """``c3, c4, c5`` of the quintic through (p0, v0, a0) → (p0 + dp, v1, a1) over ``T``
    (``c0, c1, c2`` are p0, v0, a0 / 2): :func:`quintic_coefficients` on scalars."""
    T2 = T * T
    T3 = T2 * T
    return (
        (20.0 * dp - (8.0 * v1 + 12.0 * v0) * T - (3.0 * a0 - a1) * T2) / (2.0 * T3),
        (-30.0 * dp + (14.0 * v1 + 16.0 * v0) * T + (3.0 * a0 - 2.0 * a1) * T2) / (2.0 * T3 * T),
        (12.0 * dp - 6.0 * (v1 + v0) * T - (a0 - a1) * T2) / (2.0 * T3 * T2),
    )


_quintic_high_python = getattr(_quintic_high, "py_func", _quintic_high)  # NUMBA_DISABLE_JIT: the function itself


def knots_state(knots: Sequence[Knot], t: float) -> tuple[float, float, float]:
    """Position, velocity, acceleration at time ``t`` of the one channel through ``knots``.

    Plain float arithmetic on the single segment containing ``t`` — much cheaper than building
    a spline when only one state is needed (the walk engine's half-step hand-over).  Matches
    :class:`PiecewiseQuintic` (including extrapolation of the first / last segment).
    """
    k = 1
    while k < len(knots) - 1 and knots[k][0] <= t:
        k += 1
    a, b = knots[k - 1], knots[k]
    t0, p0 = a[0], a[1]
    v0 = a[2] if len(a) > 2 else 0.0
    a0 = a[3] if len(a) > 3 else 0.0
    T, p1 = b[0] - t0, b[1]
    v1 = b[2] if len(b) > 2 else 0.0
    a1 = b[3] if len(b) > 3 else 0.0
    if not T > 0.0:
        raise ValueError("knot times must strictly increase")
    c2 = 0.5 * a0
    # The same formula as the compiled tables, run as Python: a compiled call from Python costs
    # more than these few float operations, by far when the caches are cold (after physics).
    c3, c4, c5 = _quintic_high_python(p1 - p0, v0, a0, v1, a1, T)
    x = t - t0
    pos = p0 + x * (v0 + x * (c2 + x * (c3 + x * (c4 + x * c5))))
    vel = v0 + x * (2.0 * c2 + x * (3.0 * c3 + x * (4.0 * c4 + x * 5.0 * c5)))
    acc = 2.0 * c2 + x * (6.0 * c3 + x * (12.0 * c4 + x * 20.0 * c5))
    return pos, vel, acc


@dataclass(frozen=True)
class QuinticSegment:
    """One quintic on ``[0, duration]`` from end conditions (pos, vel, acc) at both ends."""

    coefficients: np.ndarray  # (6,)
    duration: float

    @classmethod
    def from_boundary(cls, start: Sequence[float], end: Sequence[float], duration: float) -> QuinticSegment:
        """``start`` and ``end`` are ``(pos, vel, acc)``."""
        (p0, v0, a0), (p1, v1, a1) = start, end
        return cls(quintic_coefficients(p0, v0, a0, p1, v1, a1, duration), float(duration))

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at times ``t`` (array-like, seconds from the start)."""
        return evaluate_polynomial(self.coefficients, np.asarray(t, dtype=float))


def _padded_knots(channels: Sequence[Sequence[Knot]]) -> tuple[np.ndarray, np.ndarray]:
    """Every channel's knots as ``(time, pos, vel, acc)`` rows (velocity and acceleration default
    to zero) in one ``(channels, knots, 4)`` array, shorter channels padded by repeating their
    last knot (zero-length segments, never selected); and each channel's number of segments."""
    if len(channels) == 0:
        raise ValueError("a spline needs at least one channel")
    counts = [len(knots) for knots in channels]
    if min(counts) < 2:
        raise ValueError(f"every channel needs at least two knots, got {counts}")
    max_knots = max(counts)
    values: list[float] = []  # every row, flat: numpy converts a flat list of floats fastest
    for knots in channels:
        for knot in knots:
            values += knot
            values += _ZEROS[len(knot)]
        values += values[-4:] * (max_knots - len(knots))
    return np.array(values, dtype=float).reshape(len(channels), max_knots, 4), np.array(counts) - 1


def _raise_for(status: int) -> None:
    """The error of a ``_segment_tables`` status."""
    if status == 1:
        raise ValueError("knot times, positions, velocities and accelerations must be finite")
    if status == 2:
        raise ValueError("knot times must strictly increase within each channel")


def sample_positions(channels: Sequence[Sequence[Knot]], times: np.ndarray) -> np.ndarray:
    """``PiecewiseQuintic(channels).positions(times)`` for per-channel ``times`` ``(channels, n)``,
    in one compiled call and without the spline object (the walk engine samples each double
    step's splines once): the same float operations, so the same positions."""
    data, n_segments = _padded_knots(channels)
    times = np.ascontiguousarray(times, dtype=float)
    if times.ndim != 2 or times.shape[0] != data.shape[0]:
        raise ValueError(f"per-channel times need {data.shape[0]} rows, got {times.shape}")
    out = np.empty(times.shape)
    _raise_for(_tables_and_positions(data, n_segments, times, out))
    return out


class PiecewiseQuintic:
    """Several channels of piecewise quintic splines, each through its own knots.

    Every knot fixes position, velocity and acceleration (velocity and acceleration default to
    zero), so each channel is C2 at its knots.  Knot times of a channel must strictly increase.
    Times outside a channel's knot range extrapolate its first / last segment.
    """

    def __init__(self, channels: Sequence[Sequence[Knot]]):
        data, n_segments = _padded_knots(channels)
        n_channels, n_seg_max = data.shape[0], data.shape[1] - 1
        # Flat, power-major coefficient table: column = channel * n_seg_max + segment.  All
        # channels' breakpoints in one sorted array: channel c's are shifted by c * span, so one
        # searchsorted locates the segment of every (channel, time) pair at once.  One compiled
        # call fills them (a few dozen numpy calls on tiny arrays cost ~100 µs per spline).
        self._coefficients = np.empty((6, n_channels * n_seg_max))
        self._segment_start = np.empty(n_channels * n_seg_max)
        self._breaks = np.empty(n_channels * n_seg_max)
        status, t_min, span = _segment_tables(data, n_segments, self._coefficients, self._segment_start, self._breaks)
        _raise_for(status)
        self.times = data[:, :, 0]  # (channels, max_knots); padded with each channel's last knot time
        self.n_segments = n_segments
        # Queries are clamped into the band where the channel shift is unambiguous (times beyond a
        # channel's knots just extrapolate its first / last segment).  Within the band a time
        # before a channel's first breakpoint counts exactly the earlier channels' breakpoints,
        # i.e. lands on the channel's first column, so only the upper cap is needed.
        self._query_low, self._query_high, offsets, last_column = _query_frame(n_segments, n_seg_max, t_min, span)
        self._offsets, self._last_column = offsets[:, None], last_column[:, None]

    @property
    def n_channels(self) -> int:
        return self.times.shape[0]

    @property
    def coefficients(self) -> np.ndarray:
        """``(channels, segments, 6)`` polynomial coefficients (local time from each segment start)."""
        return self._coefficients.T.reshape(self.n_channels, -1, 6)

    def start_time(self) -> np.ndarray:
        return self.times[:, 0].copy()

    def end_time(self) -> np.ndarray:
        return self.times[:, -1].copy()

    def _locate(self, t: np.ndarray):
        """``t`` is ``(n,)`` (same times for every channel) or ``(channels, n)`` (per channel)."""
        t_query = np.minimum(np.maximum(t, self._query_low), self._query_high)  # see __init__
        if t.ndim == 1:
            t, t_query = t[None, :], t_query[None, :]
        q = t_query + self._offsets
        column = np.searchsorted(self._breaks, q.ravel(), side="right").reshape(q.shape)
        np.minimum(column, self._last_column, out=column)
        tau = t - np.take(self._segment_start, column)
        return np.take(self._coefficients, column, axis=1), tau  # (6, channels, n), (channels, n)

    def positions(self, t) -> np.ndarray:
        """Positions only, ``(channels, n)`` — the cheap path for sampling control ticks.

        ``t`` is ``(n,)`` for the same times on every channel or ``(channels, n)`` per channel.
        One compiled call (:func:`_sample_positions`): the segment search and Horner's rule of
        :meth:`_locate` and :meth:`evaluate`, the same float operations in the same order.
        """
        t = np.asarray(t, dtype=float)
        if t.ndim == 2 and t.shape[0] != self.n_channels:
            raise ValueError(f"per-channel times need {self.n_channels} rows, got {t.shape}")
        t = np.atleast_1d(t)
        times = np.ascontiguousarray(t.reshape(-1, t.shape[-1]))  # (1, n): the same times on every channel
        out = np.empty((self.n_channels, times.shape[1]))
        _sample_positions(
            self._coefficients,
            self._segment_start,
            self._breaks,
            self._offsets[:, 0],
            self._last_column[:, 0],
            self._query_low,
            self._query_high,
            times,
            out,
        )
        return out

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration of every channel at times ``t``: each ``(channels, len(t))``."""
        c, tau = self._locate(np.atleast_1d(np.asarray(t, dtype=float)))
        return evaluate_polynomial(np.moveaxis(c, 0, -1), tau)

    def state(self, t: float) -> np.ndarray:
        """``(channels, 3)``: position, velocity, acceleration of every channel at one time."""
        c, tau = self._locate(np.array([float(t)]))
        powers = tau**_POWERS  # (channels, 6): tau^0 .. tau^5
        out = np.empty((c.shape[1], 3))
        c = c[:, :, 0].T  # (channels, 6)
        out[:, 0] = (c * powers).sum(axis=1)
        out[:, 1] = (c[:, 1:] * _VEL_FACTORS * powers[:, :5]).sum(axis=1)
        out[:, 2] = (c[:, 2:] * _ACC_FACTORS * powers[:, :4]).sum(axis=1)
        return out


@compiled
def _sample_positions(coefficients, segment_start, breaks, offsets, last_column, low, high, times, out):
    """:meth:`PiecewiseQuintic.positions` compiled: ``times`` is ``(1, n)`` (every channel) or
    ``(channels, n)``; writes ``(channels, n)`` positions into ``out``."""
    per_channel = times.shape[0] > 1
    for ch in range(out.shape[0]):
        row = ch if per_channel else 0
        for i in range(times.shape[1]):
            t = times[row, i]
            query = min(max(t, low), high) + offsets[ch]  # clamped into the channel's band
            column = min(np.searchsorted(breaks, query, side="right"), last_column[ch])
            tau = t - segment_start[column]
            out[ch, i] = coefficients[0, column] + tau * (
                coefficients[1, column]
                + tau
                * (
                    coefficients[2, column]
                    + tau * (coefficients[3, column] + tau * (coefficients[4, column] + tau * coefficients[5, column]))
                )
            )


@compiled
def _segment_tables(data, n_segments, coefficients, segment_start, breaks):
    """:class:`PiecewiseQuintic`'s tables from its padded knots ``data (channels, knots, 4)``:
    per segment column the quintic's coefficients (the closed form of
    :func:`quintic_coefficients`), its start time and its breakpoint shifted by channel.
    Returns ``(status, t_min, span)``: status 0 ok, 1 a non-finite knot, 2 knot times not
    strictly increasing."""
    n_channels, n_knots = data.shape[0], data.shape[1]
    t_min, t_max = np.inf, -np.inf
    for ch in range(n_channels):
        for k in range(n_knots):
            for j in range(4):
                if not np.isfinite(data[ch, k, j]):
                    return 1, 0.0, 0.0
            t_min, t_max = min(t_min, data[ch, k, 0]), max(t_max, data[ch, k, 0])
    span = 2.0 * (t_max - t_min) + 1.0
    n_seg = n_knots - 1
    for ch in range(n_channels):
        for k in range(n_seg):
            column = ch * n_seg + k
            t0, t1 = data[ch, k, 0], data[ch, k + 1, 0]
            segment_start[column] = t0
            breaks[column] = t1 + ch * span
            if k < n_segments[ch]:
                T = t1 - t0
                if not T > 0.0:
                    return 2, 0.0, 0.0
            else:
                T = 1.0  # padded segment: any positive length, never evaluated
            p0, v0, a0 = data[ch, k, 1], data[ch, k, 2], data[ch, k, 3]
            p1, v1, a1 = data[ch, k + 1, 1], data[ch, k + 1, 2], data[ch, k + 1, 3]
            coefficients[0, column] = p0
            coefficients[1, column] = v0
            coefficients[2, column] = 0.5 * a0
            coefficients[3, column], coefficients[4, column], coefficients[5, column] = _quintic_high(
                p1 - p0, v0, a0, v1, a1, T
            )
    return 0, t_min, span


@compiled
def _query_frame(n_segments, n_seg_max, t_min, span):
    """The query band ``(low, high)``, each channel's breakpoint shift and its last coefficient
    column, for tables from :func:`_segment_tables` (see :class:`PiecewiseQuintic`)."""
    band = 0.5 * (span - 1.0)
    n_channels = n_segments.shape[0]
    offsets, last_column = np.empty(n_channels), np.empty(n_channels, dtype=np.int64)
    for ch in range(n_channels):
        offsets[ch] = ch * span
        last_column[ch] = ch * n_seg_max + (n_segments[ch] - 1)
    return t_min - band, t_min + span - band, offsets, last_column


@compiled
def _tables_and_positions(data, n_segments, times, out):
    """:func:`sample_positions`: :func:`_segment_tables`, :func:`_query_frame`, then
    :func:`_sample_positions`, as :class:`PiecewiseQuintic` does them.  Returns the tables'
    status (0: ``out`` written)."""
    n_channels, n_seg_max = data.shape[0], data.shape[1] - 1
    coefficients = np.empty((6, n_channels * n_seg_max))
    segment_start, breaks = np.empty(n_channels * n_seg_max), np.empty(n_channels * n_seg_max)
    status, t_min, span = _segment_tables(data, n_segments, coefficients, segment_start, breaks)
    if status != 0:
        return status
    query_low, query_high, offsets, last_column = _query_frame(n_segments, n_seg_max, t_min, span)
    _sample_positions(coefficients, segment_start, breaks, offsets, last_column, query_low, query_high, times, out)
    return 0
