"""The observation's ray scan and nearest obstacle, compiled (numba): the hot path of the
navigation task's observation and obstacle reward (:mod:`footsim.tasks.nav`).

Obstacles come as a C-contiguous float64 ``(n, 3)`` array of ``(x, y, r)`` rows
(:func:`footsim.scene.circle_array`), built once per episode; poses as plain floats.  The
conventions of :mod:`footsim.compiled` apply (bit-identical to the Python code they replace,
``tests/test_kernels2d.py`` keeps that code as the reference); :func:`nearest_circle` returns an
index so that the caller takes the distance with CPython's ``math.hypot`` (the C library's
``hypot`` may differ in the last bit).
"""

from __future__ import annotations

import math

import numpy as np

from footsim.compiled import compiled


def ray_directions(n_rays: int) -> np.ndarray:
    """``(2, n_rays)`` array: cos and sin of the ray headings ``k·2π/n`` in the robot frame."""
    k = np.arange(n_rays) * (2.0 * math.pi / n_rays)
    return np.ascontiguousarray(np.stack([np.cos(k), np.sin(k)]))


@compiled
def _ray_scan(px, py, theta, circles, directions, max_range, out):
    """Write into ``out`` (its size = the number of rays) each ray's distance to the first circle
    hit, ``max_range`` when it hits nothing; returns False (``out`` then undefined) when the
    origin is inside (or on) a circle.

    Closed form per ray and circle: with ``u`` the ray's unit direction and ``c`` the circle's
    centre relative to the origin, ``|t·u − c|² = r²`` gives ``t = u·c − sqrt((u·c)² − (|c|² − r²))``.
    Only rays within the circle's angular half-width ``asin(r/|c|)`` of its bearing can hit it, so
    each circle is tested against those rays only (plus a tiny angular margin for rounding), and
    circles whose nearest point is beyond ``max_range`` are skipped.
    """
    n = out.shape[0]
    for k in range(n):
        out[k] = max_range
    m = circles.shape[0]
    if m == 0:
        return True
    c, s = math.cos(theta), math.sin(theta)
    per_rad = n / (2.0 * math.pi)  # ray index per radian of heading
    far = max_range + 1e-6 * (1.0 + max_range)
    for i in range(m):
        dx, dy, r = circles[i, 0] - px, circles[i, 1] - py, circles[i, 2]
        d2 = dx * dx + dy * dy
        cc = d2 - r * r  # |c|² − r²
        if cc <= 0.0:  # the origin is inside (or on) a circle
            return False
        dist = math.sqrt(d2)
        if dist - r > far:  # every point of the circle is beyond the range
            continue
        rx, ry = c * dx + s * dy, c * dy - s * dx  # centre in the robot frame
        # Rays k with |k − bearing| <= half-width (in ray indices), widened by 1e-3 for rounding.
        bearing = math.atan2(ry, rx) * per_rad
        q = r / dist
        half = math.asin(q if q < 1.0 else 1.0) * per_rad + 1e-3
        lo, hi = math.ceil(bearing - half), math.floor(bearing + half)
        if hi - lo >= n:
            lo, hi = 0, n - 1
        for j in range(lo, hi + 1):
            k = j % n  # floor modulo, as in Python: the wrap-around at ±180°
            proj = rx * directions[0, k] + ry * directions[1, k]
            disc = proj * proj - cc
            if disc >= 0.0:
                t = proj - math.sqrt(disc)
                if t >= 0.0 and t < out[k]:
                    out[k] = t
    return True


@compiled
def scan_rays(px, py, theta, circles, directions, max_range, out):
    """Distance along each ray (``directions``: :func:`ray_directions`) from the pose to the first
    circle hit, written into ``out``: misses report ``max_range``, an origin inside a circle
    reports 0 on every ray."""
    if not _ray_scan(px, py, theta, circles, directions, max_range, out):
        for k in range(out.shape[0]):
            out[k] = 0.0


@compiled
def ray_observation(px, py, theta, circles, directions, max_range, scale, miss, obs, start):
    """Write the observation's ray block into ``obs[start:start + n]``: ``tanh(distance / scale)``
    per ray, ``miss`` (= ``tanh(max_range / scale)``, computed by the caller) for the rays that
    hit nothing, 0 on every ray when the origin is inside a circle."""
    n = directions.shape[1]
    out = np.empty(n)
    inside = not _ray_scan(px, py, theta, circles, directions, max_range, out)
    for k in range(n):
        obs[start + k] = 0.0 if inside else math.tanh(out[k] / scale) if out[k] < max_range else miss


@compiled
def nearest_circle(px, py, circles):
    """Index of the circle whose edge is nearest to ``(px, py)`` (-1 without circles).

    Callers compute that circle's distance with CPython's ``math.hypot``: the C library's
    ``hypot`` used here can differ from it by one unit in the last place, which only matters when
    two circles' distances tie to within that.
    """
    best, index = math.inf, -1
    for i in range(circles.shape[0]):
        d = math.hypot(circles[i, 0] - px, circles[i, 1] - py) - circles[i, 2]
        if d < best:
            best, index = d, i
    return index
