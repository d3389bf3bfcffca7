"""Closed-form, compiled (numba) collision tests of the 2D backend: rectangles (feet, trunk)
against static circles (obstacles, ball), one call per double step.

They answer what a pymunk shape query of the same polygons against the same circles answers
(``tests/test_backend_pymunk2d.py`` checks them against pymunk's own queries).  Obstacles come as
a C-contiguous float64 ``(n, 3)`` array of ``(x, y, r)`` rows (:func:`footsim.scene.circle_array`),
built once per episode; poses as plain floats.  The conventions of :mod:`footsim.compiled` apply
(bit-identical to the Python code they replace, ``tests/test_kernels2d.py`` keeps that code as the
reference).
"""

from __future__ import annotations

import math

import numpy as np

from footsim.compiled import compiled
from footsim.walk.kernels import place_double_step

_TWO_PI = 2.0 * math.pi


@compiled
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


@compiled
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


@compiled
def _mean_heading(at, bt):
    """``footsim.geometry.mean_pose``'s heading: the bisector of two headings, wrapped."""
    w = np.fmod(bt - at + math.pi, _TWO_PI)
    if w <= 0.0:
        w += _TWO_PI
    w = np.fmod(at + 0.5 * (w - math.pi) + math.pi, _TWO_PI)
    if w <= 0.0:
        w += _TWO_PI
    return w - math.pi


@compiled
def double_step_collides(circles, dims, n_tall, sx, sy, st, rx, ry, rt, mx, my, mt, ex, ey, et):
    """Does a double step touch a circle?  The right foot flies from ``s`` to ``r`` while the left
    stands at ``m``, then the left foot flies from ``m`` to ``e``; ``dims`` = ``(reach, foot
    half-length, foot half-width, trunk half-length, trunk half-width, upper-body half-length,
    upper-body half-width, upper-body offset)``, ``reach`` the largest distance from a shape's
    reference pose to its farthest corner (with a rounding margin).

    Each flying foot is tested at mid-swing and at put-down, and the trunk (the mean of the two
    feet, :func:`footsim.geometry.mean_pose`) at each put-down.  With an upper-body half-length
    > 0, the upper body's box (its centre ``offset`` ahead of the trunk) is tested at each put-down
    too, against the first ``n_tall`` circles only (the obstacles: the ball stays below the arms).
    Broad phase first: every shape's reference pose lies inside the bounding box of the four foot
    positions, so a circle farther from that box than its radius plus ``reach`` can't touch any.
    """
    reach, foot_hl, foot_hw, trunk_hl, trunk_hw = dims[0], dims[1], dims[2], dims[3], dims[4]
    upper_hl, upper_hw, upper_offset = dims[5], dims[6], dims[7]
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
    if upper_hl > 0.0:
        c2, s2, c4, s4 = shapes[2][2], shapes[2][3], shapes[5][2], shapes[5][3]
        upper = (
            (shapes[2][0] + upper_offset * c2, shapes[2][1] + upper_offset * s2, c2, s2),
            (shapes[5][0] + upper_offset * c4, shapes[5][1] + upper_offset * s4, c4, s4),
        )
        for i in range(min(n_tall, n)):
            if near[i]:
                for b in upper:
                    if _box_hits_circle(
                        b[0], b[1], b[2], b[3], upper_hl, upper_hw, circles[i, 0], circles[i, 1], circles[i, 2]
                    ):
                        return True
    return False


@compiled
def execute_double_step(sx, sy, st, lx, ly, lt, x1, y1, t1, x2, y2, t2, g, circles, dims, n_tall):
    """A whole 2D double step in one call: :func:`place_double_step` from the left foot at ``(lx,
    ly, lt)`` (the right foot standing at ``(sx, sy, st)``), :func:`double_step_collides` on the
    result, and the navigation pose after it (:func:`footsim.geometry.mean_pose` of the feet).

    Returns :func:`place_double_step`'s 14 values, then ``collided`` and the navigation pose's
    ``x, y, theta``.
    """
    placed = place_double_step(lx, ly, lt, x1, y1, t1, x2, y2, t2, g)
    rx, ry, rt, ex, ey, et = placed[0], placed[1], placed[2], placed[7], placed[8], placed[9]
    collided = circles.shape[0] > 0 and double_step_collides(
        circles, dims, n_tall, sx, sy, st, rx, ry, rt, lx, ly, lt, ex, ey, et
    )
    return placed + (collided, 0.5 * (ex + rx), 0.5 * (ey + ry), _mean_heading(et, rt))
