"""Compiled (numba) kernels of the footstep planner (:mod:`footsim.planners.footstep`): the
footprint check (rectangles against circles), the heuristic, and the weighted-A* search loop
(pop, duplicate detection, expansion through the transition set, push).

The search runs in :func:`search` until it needs the planner (the analytic goal expansion at a
double-step boundary within one double step's reach of the goal, more room for nodes, a look at
the clock) or ends; its whole state lives in a :class:`SearchState`'s arrays, so it resumes where
it stopped.  The conventions of :mod:`footsim.compiled` apply: the kernels do the float
operations of the numpy code they replaced in the same order, so plans are bit-identical to it
(``tests/test_footstep_search.py`` keeps that code as the reference).  That code took cos/sin of
arrays from numpy and the kernels take them from libm: the same values here (numpy 2.4 on
x86-64 with AVX2; the test compares them), which another numpy build need not give in the last bit.
"""

from __future__ import annotations

import math

import numpy as np

from footsim.compiled import compiled

_PI = math.pi
_TWO_PI = 2.0 * math.pi

# search() stops with one of these
EMPTY = 0  # no open node left
BUDGET = 1  # the expansion budget is used up
MAX_EXPANSIONS = 2  # more than max_expansions nodes expanded
GOAL_SHOT = 3  # a left-foot node (double-step boundary) was popped: try the goal double step, then resume
CLOCK = 4  # the pops allowed for this call are done (the wall-clock budget: read the clock)
GROW = 5  # no room for the children of the node being expanded: grow the arrays, then resume

# node columns: SearchState.pose (x, y, theta, g) and SearchState.link (side bit, parent, transition)
_CLOSED = -math.inf  # the best g of a closed lattice cell
_NO_CELL = np.iinfo(np.int64).min  # an empty slot of the lattice cells' hash table (no key is that low)


@compiled
def wrap(a):
    """``np.mod(a + π, 2π) − π`` for one float (the planner's wrap; a result of exactly 2π − π
    cannot occur, −π can)."""
    m = np.fmod(a + _PI, _TWO_PI)
    if m < 0.0:
        m += _TWO_PI
    elif m == 0.0:
        m = 0.0
    return m - _PI


@compiled
def rect_hits(circles, x, y, theta, half_l, half_w):
    """Does the rectangle ``2·half_l × 2·half_w`` centred at ``(x, y)`` and turned by ``theta``
    overlap a circle of ``circles`` (rows ``(x, y, (r + margin)²)``)?  The closest point of the
    rectangle to the centre lies strictly within the radius."""
    c, s = math.cos(theta), math.sin(theta)
    for i in range(circles.shape[0]):
        dx, dy = circles[i, 0] - x, circles[i, 1] - y
        u, v = c * dx + s * dy, -s * dx + c * dy
        qu = abs(u) - half_l
        qv = abs(v) - half_w
        qu = qu if qu > 0.0 else 0.0
        qv = qv if qv > 0.0 else 0.0
        if qu * qu + qv * qv < circles[i, 2]:
            return True
    return False


@compiled
def rects_hit(circles, x, y, theta, half_l, half_w):
    """:func:`rect_hits` for arrays of rectangles (poses and half extents of equal length)."""
    out = np.zeros(x.shape[0], dtype=np.bool_)
    for i in range(x.shape[0]):
        out[i] = rect_hits(circles, x[i], y[i], theta[i], half_l[i], half_w[i])
    return out


@compiled
def heuristic(hp, dist, direction, turn_from_direction, x, y, theta):
    """Expected footsteps to the goal from the navigation pose ``(x, y, theta)`` (inf off the map
    or unreachable); ``hp`` = (map origin x, y, 1 / resolution, goal heading, heading switch
    distance, 1 / limit x, turn weight / limit θ).  See ``FootstepPlanner._heuristic``."""
    i = int(np.rint((x - hp[0]) * hp[2]))
    j = int(np.rint((y - hp[1]) * hp[2]))
    if 0 <= i < dist.shape[0] and 0 <= j < dist.shape[1]:
        d = dist[i, j]
    else:
        i, j, d = 0, 0, math.inf
    if d > hp[4]:
        turn = abs(wrap(direction[i, j] - theta)) + turn_from_direction[i, j]
    else:
        turn = abs(wrap(hp[3] - theta))
    return d * hp[5] + hp[6] * turn


@compiled
def turn_table(goal_theta, direction):
    """Per cell, the turn from the downhill direction to the goal heading, ``|wrap(goal − direction)|``."""
    out = np.empty_like(direction)
    for i in range(direction.shape[0]):
        for j in range(direction.shape[1]):
            out[i, j] = abs(wrap(goal_theta - direction[i, j]))
    return out


@compiled
def goal_step(sx, sy, st, goal):
    """The right footstep from left support ``(sx, sy, st)`` that lands the right foot at the goal
    stance's, ``goal`` = (its x, y, θ, foot distance, limit x, y, θ with tolerance): ``(within
    the limits, x, y, θ)`` (the support's ``Pose2D.relative`` of the goal's right foot, shifted by
    the foot distance)."""
    dx, dy = goal[0] - sx, goal[1] - sy
    c, s = math.cos(st), math.sin(st)
    x, y = c * dx + s * dy, -s * dx + c * dy
    theta = np.fmod(goal[2] - st + _PI, _TWO_PI)  # wrap_angle(goal θ − st)
    if theta <= 0.0:
        theta += _TWO_PI
    theta -= _PI
    y = y + goal[3]
    within = not (abs(x) > goal[4] or abs(y) > goal[5] or abs(theta) > goal[6])
    return within, x, y, theta


@compiled
def lattice_key(x, y, theta, side_bit, inv_res, inv_bin, nbins):
    """The duplicate-detection cell of a node: x, y on the ``1 / inv_res`` lattice, the heading in
    ``nbins`` bins, the side."""
    ix = np.int64(np.rint(x * inv_res))
    iy = np.int64(np.rint(y * inv_res))
    it = np.int64(np.rint(theta * inv_bin)) % nbins
    return ((ix * 8192 + iy) * nbins + it) * 2 + side_bit


@compiled
def _slot(cell_key, key):
    """The slot of lattice cell ``key`` in the open-addressing table ``cell_key`` (a power of two
    long, at most half full): where it is, or the empty slot where it goes."""
    mask = cell_key.shape[0] - 1
    i = ((key * -7046029254386353131) >> 29) & mask  # Fibonacci hashing
    while cell_key[i] != key and cell_key[i] != _NO_CELL:
        i = (i + 1) & mask
    return i


@compiled
def rehash(cell_key, cell_g, new_key, new_g):
    """Insert the cells of one table into an empty larger one."""
    for i in range(cell_key.shape[0]):
        if cell_key[i] != _NO_CELL:
            j = _slot(new_key, cell_key[i])
            new_key[j], new_g[j] = cell_key[i], cell_g[i]


@compiled
def _before(hf, hg, hm, a, b):
    """Heap entry a before b: ``(f, g, node)`` compared as tuples."""
    if hf[a] != hf[b]:
        return hf[a] < hf[b]
    if hg[a] != hg[b]:
        return hg[a] < hg[b]
    return hm[a] < hm[b]


@compiled
def _swap(hf, hg, hm, a, b):
    hf[a], hf[b] = hf[b], hf[a]
    hg[a], hg[b] = hg[b], hg[a]
    hm[a], hm[b] = hm[b], hm[a]


@compiled
def _push(hf, hg, hm, size, f, g, m):
    hf[size], hg[size], hm[size] = f, g, m
    i = size
    while i > 0:
        up = (i - 1) >> 1
        if not _before(hf, hg, hm, i, up):
            break
        _swap(hf, hg, hm, i, up)
        i = up
    return size + 1


@compiled
def _pop(hf, hg, hm, size):
    """Remove the first entry (its node is returned); the heap has ``size − 1`` entries after."""
    top = hm[0]
    size -= 1
    _swap(hf, hg, hm, 0, size)
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        child = left
        if left + 1 < size and _before(hf, hg, hm, left + 1, left):
            child = left + 1
        if not _before(hf, hg, hm, child, i):
            break
        _swap(hf, hg, hm, i, child)
        i = child
    return top


@compiled
def _expand(
    st, pose, link, hf, hg, hm, cell_key, cell_g, sp, rels, costs, circles, feet, hp, dist, direction, turn_from, n
):
    """Push the collision-free, promising children of node ``n`` (see ``FootstepPlanner``);
    False (nothing done) when the node arrays have no room for them."""
    k = rels.shape[0]
    if st[0] + k > pose.shape[0]:
        return False
    x, y, t, g = pose[n, 0], pose[n, 1], pose[n, 2], pose[n, 3]
    parent = link[n, 1]
    if parent >= 0:
        ox, oy, ot = pose[parent, 0], pose[parent, 1], pose[parent, 2]
    else:
        ox, oy, ot = sp[7], sp[8], sp[9]
    eps, bound, inv_res, inv_bin = sp[0], sp[1], sp[2], sp[3]
    nbins = st[5]
    flying_bit = 1 - link[n, 0]
    foot_l, foot_w, trunk_l, trunk_w = feet[0], feet[1], feet[2], feet[3]
    upper_l, upper_w, upper_off = feet[4], feet[5], feet[6]  # the upper body's box (upper_l 0: none)
    tall = circles[: int(feet[7])]  # the circles that reach the upper body (the obstacles, not the ball)
    c, s = math.cos(t), math.sin(t)
    for j in range(k):
        rx, ry, rt = rels[j, 0], rels[j, 1], rels[j, 2]
        lx = x + c * rx - s * ry
        ly = y + s * rx + c * ry
        lt = t + rt
        # navigation pose after landing and the flying foot at mid-swing (circular means)
        nav_x, nav_y, nav_t = 0.5 * (x + lx), 0.5 * (y + ly), t + 0.5 * rt
        if rect_hits(circles, lx, ly, lt, foot_l, foot_w):
            continue
        if rect_hits(circles, 0.5 * (ox + lx), 0.5 * (oy + ly), ot + 0.5 * wrap(lt - ot), foot_l, foot_w):
            continue
        if rect_hits(circles, nav_x, nav_y, nav_t, trunk_l, trunk_w):
            continue
        if upper_l > 0.0:
            ux, uy = nav_x + upper_off * math.cos(nav_t), nav_y + upper_off * math.sin(nav_t)
            if rect_hits(tall, ux, uy, nav_t, upper_l, upper_w):
                continue
        h = heuristic(hp, dist, direction, turn_from, nav_x, nav_y, nav_t)
        gc = g + costs[j]
        if not (math.isfinite(h) and gc + h < bound):
            continue
        lt = wrap(lt)
        key = lattice_key(lx, ly, lt, flying_bit, inv_res, inv_bin, nbins)
        i = _slot(cell_key, key)
        if cell_key[i] == key and gc >= cell_g[i]:  # closed cells hold -inf
            continue
        cell_key[i], cell_g[i] = key, gc
        m = st[0]
        pose[m, 0], pose[m, 1], pose[m, 2], pose[m, 3] = lx, ly, lt, gc
        link[m, 0], link[m, 1], link[m, 2] = flying_bit, n, j
        st[0] = m + 1
        if h < sp[4]:
            sp[4] = h
            st[3] = m
        st[1] = _push(hf, hg, hm, st[1], gc + eps * h, gc, m)
    return True


@compiled
def search(
    st,
    pose,
    link,
    hf,
    hg,
    hm,
    cell_key,
    cell_g,
    sp,
    rels_l,
    costs_l,
    rels_r,
    costs_r,
    circles,
    feet,
    hp,
    dist,
    direction,
    turn_from,
    goal,
    pending,
    pops,
):
    """Run the weighted A* until it stops; returns ``(reason, node)``.

    ``st`` (int64): node count, heap size, expansions, partial node, expansion budget, lattice
    heading bins, max expansions; ``sp`` (float64): ε, cost bound, 1 / lattice_xy, heading bins /
    2π, partial node's heuristic, unused, unused, the root's support foot (x, y, θ).  ``pending``:
    a popped node still to expand first (-1: none); ``pops``: nodes it may pop before it stops
    with ``CLOCK``.  ``GOAL_SHOT`` and ``GROW`` return the node to pass back as ``pending``."""
    while True:
        if pending >= 0:
            if link[pending, 0] == 0:  # a left foot landed last: the right flies next
                rels, costs = rels_r, costs_r
            else:
                rels, costs = rels_l, costs_l
            done = _expand(
                st, pose, link, hf, hg, hm, cell_key, cell_g, sp, rels, costs,
                circles, feet, hp, dist, direction, turn_from, pending,
            )  # fmt: skip
            if not done:
                return GROW, pending
            pending = -1
        if st[1] == 0:
            return EMPTY, -1
        if st[2] >= st[4]:
            return BUDGET, -1
        if pops == 0:
            return CLOCK, -1
        pops -= 1
        n = _pop(hf, hg, hm, st[1])
        st[1] -= 1
        key = lattice_key(pose[n, 0], pose[n, 1], pose[n, 2], link[n, 0], sp[2], sp[3], st[5])
        i = _slot(cell_key, key)
        if cell_key[i] == key and cell_g[i] == _CLOSED:
            continue
        cell_key[i], cell_g[i] = key, _CLOSED
        st[2] += 1
        if st[2] > st[6]:
            return MAX_EXPANSIONS, -1
        if link[n, 0] == 0 and goal_step(pose[n, 0], pose[n, 1], pose[n, 2], goal)[0]:
            return GOAL_SHOT, n  # a double-step boundary within one double step of the goal
        pending = n


class SearchState:
    """One weighted-A* search's nodes, open list and lattice cells (best g, ``-inf`` once closed, in
    an open-addressing hash table), grown on demand."""

    def __init__(self, capacity: int):
        self.st = np.zeros(7, dtype=np.int64)
        self.sp = np.zeros(10, dtype=np.float64)
        self.pose = np.empty((capacity, 4), dtype=np.float64)
        self.link = np.empty((capacity, 3), dtype=np.int64)
        self.hf = np.empty(capacity, dtype=np.float64)
        self.hg = np.empty(capacity, dtype=np.float64)
        self.hm = np.empty(capacity, dtype=np.int64)
        self.cell_key, self.cell_g = self._table(capacity)

    @staticmethod
    def _table(capacity: int) -> tuple[np.ndarray, np.ndarray]:
        """Room for a cell per node (every cell comes with a node) at most half full."""
        size = 1 << (2 * capacity - 1).bit_length()
        return np.full(size, _NO_CELL, dtype=np.int64), np.empty(size, dtype=np.float64)

    def grow(self) -> None:
        n = 2 * self.pose.shape[0]
        for name in ("pose", "link", "hf", "hg", "hm"):
            old = getattr(self, name)
            new = np.empty((n,) + old.shape[1:], dtype=old.dtype)
            new[: old.shape[0]] = old
            setattr(self, name, new)
        cell_key, cell_g = self._table(n)
        rehash(self.cell_key, self.cell_g, cell_key, cell_g)
        self.cell_key, self.cell_g = cell_key, cell_g
