"""Compiled (numba) float kernels of the 2D env's hot path: the ray scan, the nearest obstacle,
the rectangle–circle overlaps of a double step and the footstep placement.

Obstacles come as a C-contiguous float64 ``(n, 3)`` array of ``(x, y, r)`` rows
(:func:`circle_array`), built once per episode; poses and steps as plain floats.  Each kernel
replaces pure-Python code and does the same float operations in the same order (no fast-math,
so no contraction into fused multiply-adds), so results are bit-identical;
:func:`nearest_circle` returns an index so that the caller takes the distance with CPython's
``math.hypot`` (the C library's ``hypot`` may differ in the last bit).  ``tests/test_kernels2d.py``
keeps the replaced pure-Python code as the reference and checks the kernels against it.

Compiled code is cached on disk (``cache=True``: ``NUMBA_CACHE_DIR`` if set, else next to this
file, else numba's user-wide cache directory; without any writable one, each process compiles
again, with a warning).  A process without a cache compiles on first use (seconds, see
``docs/BENCHMARKS.md``).  ``NUMBA_DISABLE_JIT=1`` runs the kernels as plain Python.
"""

from __future__ import annotations

import math
import warnings

import numba
import numpy as np
from numba import njit

_TWO_PI = 2.0 * math.pi
_uncached: list[str] = []


def _compiled(func):
    """``njit(cache=True)``; without the on-disk cache (a warning, compiled once per process) where
    numba finds no writable cache directory: a read-only install, no writable home directory and
    no ``NUMBA_CACHE_DIR``."""
    try:
        return njit(cache=True)(func)
    except RuntimeError as err:  # numba: "cannot cache function ...: no locator available ..."
        if not _uncached:
            warnings.warn(
                f"footsim.kernels2d: {err}; compiling without a cache "
                "(set NUMBA_CACHE_DIR to a writable directory to keep the compiled code)",
                RuntimeWarning,
                stacklevel=2,
            )
        _uncached.append(func.__name__)
        return njit(func)


def typed_entry(kernel, *example):
    """``kernel``'s compiled code for exactly the argument types of ``example``, callable without
    numba's per-call type resolution: about 0.5 µs less a call in a tight loop, and more where a
    physics step has left the caches cold.  For per-tick loops whose argument types never change
    (the caller guarantees that; other types are not checked).  Getting it costs ~0.1 ms (numba's
    compile lock), so get it once, not per double step.  The kernel itself where numba offers no
    entry point (``NUMBA_DISABLE_JIT=1``)."""
    compile_for = getattr(kernel, "compile", None)
    if compile_for is None:
        return kernel
    entry = compile_for(tuple(numba.typeof(a) for a in example))
    return entry if callable(entry) else kernel


def ray_directions(n_rays: int) -> np.ndarray:
    """``(2, n_rays)`` array: cos and sin of the ray headings ``k·2π/n`` in the robot frame."""
    k = np.arange(n_rays) * (2.0 * math.pi / n_rays)
    return np.ascontiguousarray(np.stack([np.cos(k), np.sin(k)]))


@_compiled
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


@_compiled
def scan_rays(px, py, theta, circles, directions, max_range, out):
    """Distance along each ray (``directions``: :func:`ray_directions`) from the pose to the first
    circle hit, written into ``out``: misses report ``max_range``, an origin inside a circle
    reports 0 on every ray."""
    if not _ray_scan(px, py, theta, circles, directions, max_range, out):
        for k in range(out.shape[0]):
            out[k] = 0.0


@_compiled
def ray_observation(px, py, theta, circles, directions, max_range, scale, miss, obs, start):
    """Write the observation's ray block into ``obs[start:start + n]``: ``tanh(distance / scale)``
    per ray, ``miss`` (= ``tanh(max_range / scale)``, computed by the caller) for the rays that
    hit nothing, 0 on every ray when the origin is inside a circle."""
    n = directions.shape[1]
    out = np.empty(n)
    inside = not _ray_scan(px, py, theta, circles, directions, max_range, out)
    for k in range(n):
        obs[start + k] = 0.0 if inside else math.tanh(out[k] / scale) if out[k] < max_range else miss


@_compiled
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


@_compiled
def _box_hits_circle(x, y, c, s, half_length, half_width, cx, cy, r):
    """Does the rectangle ``2·half_length × 2·half_width`` centred at ``(x, y)`` with heading
    ``(cos, sin) = (c, s)`` overlap (or touch) the circle ``(cx, cy, r)``?  The closest point of
    the rectangle to the circle's centre lies within ``r`` (centre inside: distance 0)."""
    dx, dy = cx - x, cy - y
    u = abs(c * dx + s * dy) - half_length  # > 0: outside the rectangle along its length
    if u > r:
        return False
    v = abs(c * dy - s * dx) - half_width
    if v > r:
        return False
    u = u if u > 0.0 else 0.0
    v = v if v > 0.0 else 0.0
    return u * u + v * v <= r * r


@_compiled
def box_hits_circles(x, y, theta, half_length, half_width, circles):
    """Does the rectangle ``2·half_length × 2·half_width`` centred at ``(x, y)``, turned by
    ``theta``, overlap (or touch) any circle of ``circles``?

    Closed form of a pymunk shape query of that polygon against static circles.
    """
    c, s = math.cos(theta), math.sin(theta)
    for i in range(circles.shape[0]):
        if _box_hits_circle(x, y, c, s, half_length, half_width, circles[i, 0], circles[i, 1], circles[i, 2]):
            return True
    return False


@_compiled
def _mean_heading(at, bt):
    """``footsim.geometry.mean_pose``'s heading: the bisector of two headings, wrapped."""
    w = np.fmod(bt - at + math.pi, _TWO_PI)
    if w <= 0.0:
        w += _TWO_PI
    w = np.fmod(at + 0.5 * (w - math.pi) + math.pi, _TWO_PI)
    if w <= 0.0:
        w += _TWO_PI
    return w - math.pi


@_compiled
def double_step_collides(circles, dims, sx, sy, st, rx, ry, rt, mx, my, mt, ex, ey, et):
    """Does a double step touch a circle?  The right foot flies from ``s`` to ``r`` while the left
    stands at ``m``, then the left foot flies from ``m`` to ``e``; ``dims`` = ``(reach, foot
    half-length, foot half-width, trunk half-length, trunk half-width)``, ``reach`` the larger
    circumradius (with a rounding margin).

    Each flying foot is tested at mid-swing and at put-down, and the trunk (the mean of the two
    feet, :func:`footsim.geometry.mean_pose`) at each put-down.  Broad phase first: every one of
    those six shapes is centred inside the bounding box of the four foot positions, so a circle
    farther from that box than its radius plus ``reach`` can't touch any of them.
    """
    reach, foot_hl, foot_hw, trunk_hl, trunk_hw = dims[0], dims[1], dims[2], dims[3], dims[4]
    lo_x, hi_x = min(min(sx, rx), min(mx, ex)) - reach, max(max(sx, rx), max(mx, ex)) + reach
    lo_y, hi_y = min(min(sy, ry), min(my, ey)) - reach, max(max(sy, ry), max(my, ey)) + reach
    n = circles.shape[0]
    near = np.empty(n, dtype=np.bool_)
    any_near = False
    for i in range(n):
        x, y, r = circles[i, 0], circles[i, 1], circles[i, 2]
        near[i] = x + r >= lo_x and x - r <= hi_x and y + r >= lo_y and y - r <= hi_y
        any_near = any_near or near[i]
    if not any_near:
        return False
    # (centre x, centre y, cos and sin of the heading, half length, half width) of the six shapes;
    # the trunk is mean_pose(left foot, right foot)
    h1, h2, h3, h4 = _mean_heading(st, rt), _mean_heading(mt, rt), _mean_heading(mt, et), _mean_heading(et, rt)
    shapes = (
        (0.5 * (sx + rx), 0.5 * (sy + ry), math.cos(h1), math.sin(h1), foot_hl, foot_hw),  # right foot, mid-swing
        (rx, ry, math.cos(rt), math.sin(rt), foot_hl, foot_hw),  # right foot put down
        (0.5 * (mx + rx), 0.5 * (my + ry), math.cos(h2), math.sin(h2), trunk_hl, trunk_hw),  # trunk
        (0.5 * (mx + ex), 0.5 * (my + ey), math.cos(h3), math.sin(h3), foot_hl, foot_hw),  # left foot, mid-swing
        (ex, ey, math.cos(et), math.sin(et), foot_hl, foot_hw),  # left foot put down
        (0.5 * (ex + rx), 0.5 * (ey + ry), math.cos(h4), math.sin(h4), trunk_hl, trunk_hw),  # trunk
    )
    for i in range(n):
        if near[i]:
            for b in shapes:
                if _box_hits_circle(b[0], b[1], b[2], b[3], b[4], b[5], circles[i, 0], circles[i, 1], circles[i, 2]):
                    return True
    return False


# -- footstep placement (footsim.walk.footsteps.FootstepGeometry) ------------------------------
@_compiled
def _axis_band(lo, hi, y_coeff, x_term, reach):
    """Intersect the band [lo, hi] with the y satisfying |x_term + y_coeff * y| <= reach (one
    separating axis of :func:`overlap_band`); ``(False, lo, hi)`` when nothing is left."""
    if abs(y_coeff) < 1e-12:
        return not abs(x_term) > reach, lo, hi  # written as the rejections so NaN behaves as before
    a, b = (-reach - x_term) / y_coeff, (reach - x_term) / y_coeff
    if a > b:
        a, b = b, a
    if a > lo:
        lo = a
    if b < hi:
        hi = b
    return not lo > hi, lo, hi


@_compiled
def overlap_band(x, c, s, half_l, half_w):
    """Lateral offsets y at which a foot at ``(x, y, theta)`` (``c, s = cos θ, sin θ``) overlaps an
    identical foot at the origin: ``(True, lo, hi)``, or ``(False, 0, 0)`` when some axis separates
    for every y (:func:`footsim.walk.footsteps._overlap_band_y`).

    Separating-axis theorem on the four box axes (1, 0), (0, 1), (c, s), (−s, c): on axis n the
    boxes overlap iff |n·(x, y)| <= r_support(n) + r_flying(n), which bounds y linearly; the
    overlap set is the intersection of those bands.
    """
    ac, as_ = abs(c), abs(s)
    # axis (1, 0): bounds x only
    if abs(x) > half_l + half_l * ac + half_w * as_:
        return False, 0.0, 0.0
    # axis (0, 1): |y| <= reach
    reach = half_w + half_l * as_ + half_w * ac
    lo, hi = -reach, reach
    # axis (c, s)
    reach = half_l * ac + half_w * as_ + half_l * abs(c * c + s * s) + half_w * abs(-c * s + s * c)
    ok, lo, hi = _axis_band(lo, hi, s, c * x, reach)
    if not ok:
        return False, 0.0, 0.0
    # axis (−s, c)
    reach = half_l * as_ + half_w * ac + half_l * abs(-s * c + c * s) + half_w * abs(s * s + c * c)
    ok, lo, hi = _axis_band(lo, hi, c, -s * x, reach)
    if not ok:
        return False, 0.0, 0.0
    return True, lo, hi


@_compiled
def overlap_bands(x, c, s, half_l, half_w, lo, hi):
    """:func:`overlap_band` for every sample of the arrays ``x``, ``c``, ``s``, written into ``lo``
    and ``hi`` (NaN where no y overlaps): the walk engine's check of a swing path
    (``footsim.walk.engine._overlap_bands``)."""
    for i in range(x.shape[0]):
        overlaps, a, b = overlap_band(x[i], c[i], s[i], half_l, half_w)
        if overlaps:
            lo[i], hi[i] = a, b
        else:
            lo[i], hi[i] = np.nan, np.nan


@_compiled
def land(left, x, y, theta, g):
    """Clip a footstep ``(x, y, theta)`` (relative to the flying foot's resting pose) to the limits
    and back its lateral offset off to the edge of the overlap band if the feet would come closer
    than the gap; returns the executed ``(x, y, theta, interfered)``
    (:meth:`footsim.walk.footsteps.FootstepGeometry.landing`).

    ``g`` = (limit x, limit y, limit theta, foot distance, clear distance, half length and half
    width of a foot grown by half the gap); ``left``: the left foot flies.
    """
    lx, ly, lt, foot_distance, clear, half_l, half_w = g[0], g[1], g[2], g[3], g[4], g[5], g[6]
    x = -lx if x < -lx else lx if x > lx else x  # clip to the limits (= min(max(v, -l), l))
    y = -ly if y < -ly else ly if y > ly else y
    theta = -lt if theta < -lt else lt if theta > lt else theta
    rest_y = foot_distance if left else -foot_distance
    if abs(rest_y + y) >= clear:  # farther apart than two circumradii: no overlap
        return x, y, theta, False
    c, s = math.cos(theta), math.sin(theta)
    # The band lies within |y| <= its (0, 1)-axis bound: outside that, no overlap either.
    if abs(rest_y + y) >= half_w + half_l * abs(s) + half_w * abs(c):
        return x, y, theta, False
    overlaps, lo, hi = overlap_band(x, c, s, half_l, half_w)
    interfered = overlaps and lo < rest_y + y and rest_y + y < hi
    if interfered:  # the resting side of the band is clear (checked at construction)
        y = (hi if left else lo) - rest_y
    return x, y, theta, interfered


@_compiled
def place_footstep(left, sx, sy, st, x, y, theta, g):
    """:func:`land`, then the landed foot's pose in the world from the support foot's ``(sx, sy,
    st)``: ``(world x, y, theta, executed x, y, theta, interfered)``."""
    x, y, theta, interfered = land(left, x, y, theta, g)
    ry = y + g[3] if left else y - g[3]  # relative to the support foot
    c, s = math.cos(st), math.sin(st)
    wrapped = np.fmod(st + theta + math.pi, _TWO_PI)  # wrap_angle(st + theta)
    if wrapped <= 0.0:
        wrapped += _TWO_PI
    return sx + c * x - s * ry, sy + s * x + c * ry, wrapped - math.pi, x, y, theta, interfered


@_compiled
def place_double_step(lx, ly, lt, x1, y1, t1, x2, y2, t2, g):
    """Both footsteps of a double step from the left foot at ``(lx, ly, lt)``: the right foot
    flies ``(x1, y1, t1)``, then the left foot ``(x2, y2, t2)`` from where the right one landed.
    Returns :func:`place_footstep`'s 7 values for the right foot, then for the left foot."""
    right = place_footstep(False, lx, ly, lt, x1, y1, t1, g)
    return right + place_footstep(True, right[0], right[1], right[2], x2, y2, t2, g)


@_compiled
def execute_double_step(sx, sy, st, lx, ly, lt, x1, y1, t1, x2, y2, t2, g, circles, dims):
    """A whole 2D double step in one call: :func:`place_double_step` from the left foot at ``(lx,
    ly, lt)`` (the right foot standing at ``(sx, sy, st)``), :func:`double_step_collides` on the
    result, and the navigation pose after it (:func:`footsim.geometry.mean_pose` of the feet).

    Returns :func:`place_double_step`'s 14 values, then ``collided`` and the navigation pose's
    ``x, y, theta``.
    """
    placed = place_double_step(lx, ly, lt, x1, y1, t1, x2, y2, t2, g)
    rx, ry, rt, ex, ey, et = placed[0], placed[1], placed[2], placed[7], placed[8], placed[9]
    collided = circles.shape[0] > 0 and double_step_collides(
        circles, dims, sx, sy, st, rx, ry, rt, lx, ly, lt, ex, ey, et
    )
    return placed + (collided, 0.5 * (ex + rx), 0.5 * (ey + ry), _mean_heading(et, rt))
