"""Compiled (numba) kernels of the planar footstep geometry: the overlap band of two feet, the
landing of one footstep (limits and foot–foot interference) and the placement of a double step.

:class:`footsim.walk.footsteps.FootstepGeometry` calls them on every 2D env step, the walk engine
(:mod:`footsim.walk.engine`) for the swing-path check.  Poses and steps come as plain floats;
the conventions of :mod:`footsim.compiled` apply (bit-identical to the Python code they replace,
``tests/test_kernels2d.py`` keeps that code as the reference).
"""

from __future__ import annotations

import math

import numpy as np

from footsim.compiled import compiled

_TWO_PI = 2.0 * math.pi


@compiled
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


@compiled
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


@compiled
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


@compiled
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


@compiled
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


@compiled
def place_double_step(lx, ly, lt, x1, y1, t1, x2, y2, t2, g):
    """Both footsteps of a double step from the left foot at ``(lx, ly, lt)``: the right foot
    flies ``(x1, y1, t1)``, then the left foot ``(x2, y2, t2)`` from where the right one landed.
    Returns :func:`place_footstep`'s 7 values for the right foot, then for the left foot."""
    right = place_footstep(False, lx, ly, lt, x1, y1, t1, g)
    return right + place_footstep(True, right[0], right[1], right[2], x2, y2, t2, g)
