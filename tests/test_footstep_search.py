"""The footstep planner's compiled search (``footsim.planners.search_kernels``) against the numpy
code it replaced.

The ``_reference_*`` code below is ``FootstepPlanner``'s search as it was before numba (commit
9bf3437), kept as the reference implementation: the compiled search must expand the same nodes
in the same order and return the same plans, float for float (``==``, not approximately).
"""

import heapq
import math

import numpy as np
import pytest

from footsim.geometry import Pose2D, mean_pose, wrap_angle
from footsim.planners import search_kernels as kernels
from footsim.planners.footstep import FootstepParams, FootstepPlan, FootstepPlanner, feet_from_nav
from footsim.scene import Obstacle, Scene
from footsim.tasks.scenes import SceneSampler, sample_scenes
from footsim.walk.footsteps import FeetState, Footstep, FootstepGeometry, Side, StepLimits

LIMITS = StepLimits(0.156, 0.103, 0.764)
GEOMETRY = FootstepGeometry(LIMITS, 0.154, 0.106, 0.1799)
TRUNK = (0.15, 0.15)


# -- the numpy reference ---------------------------------------------------------------------
def _reference_wrap(a):
    return np.mod(np.asarray(a) + np.pi, 2.0 * np.pi) - np.pi


def _reference_hits(circles, x, y, theta, half_l, half_w):
    x = np.asarray(x, dtype=float)
    if circles.shape[0] == 0:
        return np.zeros(x.shape, dtype=bool)
    cx, cy, r2 = circles[:, 0], circles[:, 1], circles[:, 2]
    theta = np.asarray(theta, dtype=float)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    dx, dy = cx[None, :] - x[:, None], cy[None, :] - np.asarray(y, dtype=float)[:, None]
    u, v = c * dx + s * dy, -s * dx + c * dy
    hl = np.asarray(half_l, dtype=float).reshape(-1, 1)
    hw = np.asarray(half_w, dtype=float).reshape(-1, 1)
    qu = np.maximum(np.abs(u) - hl, 0.0)
    qv = np.maximum(np.abs(v) - hw, 0.0)
    return (qu * qu + qv * qv < r2[None, :]).any(axis=1)


def _reference_heuristic(planner, x, y, theta):
    cm = planner.costmap
    fi = (np.asarray(x) - cm.origin[0]) * (1.0 / cm.resolution)
    fj = (np.asarray(y) - cm.origin[1]) * (1.0 / cm.resolution)
    i = np.rint(fi).astype(np.intp)
    j = np.rint(fj).astype(np.intp)
    inside = (i >= 0) & (i < cm.shape[0]) & (j >= 0) & (j < cm.shape[1])
    i, j = np.where(inside, i, 0), np.where(inside, j, 0)
    d = np.where(inside, planner.dist[i, j], np.inf)
    theta = np.asarray(theta)
    to_goal = np.abs(_reference_wrap(planner.goal.theta - theta))
    turn_from_direction = np.abs(_reference_wrap(planner.goal.theta - planner.direction))
    via_path = np.abs(_reference_wrap(planner.direction[i, j] - theta)) + turn_from_direction[i, j]
    turn = np.where(d > planner.params.heading_switch_distance, via_path, to_goal)
    return d * (1.0 / planner.limits.x) + (planner.params.turn_heuristic_weight / planner.limits.theta) * turn


class _ReferencePlanner(FootstepPlanner):
    """The planner with its search, goal double step and heuristic as numpy code."""

    def _goal_shot(self, support, flying_start):
        geo, feet = self.geometry, self.goal_feet
        rel = support.relative(feet.right)
        step = Footstep(rel.x, rel.y + geo.foot_distance, rel.theta)
        lim = self.limits
        tol = 1e-9
        if abs(step.x) > lim.x + tol or abs(step.y) > lim.y + tol or abs(step.theta) > lim.theta + tol:
            return None
        if self.stable is not None and not self.stable.allows(step.x / lim.x, step.y / lim.y, step.theta / lim.theta):
            return None
        landed, done, interfered = geo.landing(Side.RIGHT, step)
        if interfered:
            return None
        right = support.compose(landed)
        left = feet.left
        mid_r, mid_l = mean_pose(flying_start, right), mean_pose(support, left)
        nav_r = mean_pose(support, right)
        xs = [mid_r.x, right.x, nav_r.x, mid_l.x, left.x]
        ys = [mid_r.y, right.y, nav_r.y, mid_l.y, left.y]
        ts = [mid_r.theta, right.theta, nav_r.theta, mid_l.theta, left.theta]
        fh, th = self.foot_half, self.trunk_half
        rects = self.rects_goal if self._active_rects is self.rects else self._active_rects
        if _reference_hits(
            rects.circles, xs, ys, ts, [fh[0]] * 2 + [th[0]] + [fh[0]] * 2, [fh[1]] * 2 + [th[1]] + [fh[1]] * 2
        ).any():
            return None
        p = self.params
        cost = (
            2 * p.step_cost
            + p.turn_cost * abs(done.theta)
            + p.backward_cost * max(-done.x, 0) / lim.x
            + p.lateral_cost * abs(done.y) / lim.y
        )
        return [(Side.RIGHT, done, right), (Side.LEFT, Footstep(), left)], cost

    def _weighted_astar(self, left, right, eps, bound, deadline, expansions_left):
        p = self.params
        inv_res, nbins = 1.0 / p.lattice_xy, int(p.lattice_theta_bins)
        inv_bin = nbins / (2 * math.pi)
        nodes = [(left.x, left.y, left.theta, Side.LEFT, -1, None, right)]
        nav0 = mean_pose(left, right)
        h_start = float(_reference_heuristic(self, [nav0.x], [nav0.y], [nav0.theta])[0])
        open_heap = [(eps * h_start, 0.0, 0)]
        best_g, closed = {}, set()
        plan, partial, expanded, timed_out = None, (h_start, 0), 0, False
        side_bit = {Side.LEFT: 0, Side.RIGHT: 1}
        circles = self._active_rects.circles
        while open_heap:
            if expanded >= expansions_left:
                timed_out = True
                break
            f, g, n = heapq.heappop(open_heap)
            x, y, t, side, _, _, other = nodes[n]
            key = (
                (int(round(x * inv_res)) * 8192 + int(round(y * inv_res))) * nbins + int(round(t * inv_bin)) % nbins
            ) * 2 + side_bit[side]
            if key in closed:
                continue
            closed.add(key)
            expanded += 1
            if expanded > p.max_expansions:
                timed_out = True
                break
            support = Pose2D(x, y, t)
            if side is Side.LEFT:
                shot = self._goal_shot(support, other)
                if shot is not None and g + shot[1] < bound:
                    plan = self._reference_extract(n, nodes, shot[0], g + shot[1])
                    break
            flying = side.other
            steps, rels, costs = self.transitions[flying]
            k = len(steps)
            c, s = math.cos(t), math.sin(t)
            lx = x + c * rels[:, 0] - s * rels[:, 1]
            ly = y + s * rels[:, 0] + c * rels[:, 1]
            lt = t + rels[:, 2]
            nav_x, nav_y = 0.5 * (x + lx), 0.5 * (y + ly)
            nav_t = t + 0.5 * rels[:, 2]
            mid_t = other.theta + 0.5 * _reference_wrap(lt - other.theta)
            hl = np.concatenate([np.full(2 * k, self.foot_half[0]), np.full(k, self.trunk_half[0])])
            hw = np.concatenate([np.full(2 * k, self.foot_half[1]), np.full(k, self.trunk_half[1])])
            hits = (
                _reference_hits(
                    circles,
                    np.concatenate([lx, 0.5 * (other.x + lx), nav_x]),
                    np.concatenate([ly, 0.5 * (other.y + ly), nav_y]),
                    np.concatenate([lt, mid_t, nav_t]),
                    hl,
                    hw,
                )
                .reshape(3, k)
                .any(axis=0)
            )
            h = _reference_heuristic(self, nav_x, nav_y, nav_t)
            gs = g + costs
            ok = np.flatnonzero(~hits & np.isfinite(h) & (gs + h < bound))
            if ok.size == 0:
                continue
            lt = _reference_wrap(lt)
            keys = (
                (
                    (np.rint(lx * inv_res).astype(np.int64) * 8192 + np.rint(ly * inv_res).astype(np.int64)) * nbins
                    + np.rint(lt * inv_bin).astype(np.int64) % nbins
                )
                * 2
                + side_bit[flying]
            )[ok].tolist()
            gl, hl_, fl = gs[ok].tolist(), h[ok].tolist(), (gs + eps * h)[ok].tolist()
            xl, yl, tl = lx[ok].tolist(), ly[ok].tolist(), lt[ok].tolist()
            for q, idx in enumerate(ok.tolist()):
                ckey, gc = keys[q], gl[q]
                if ckey in closed or gc >= best_g.get(ckey, math.inf):
                    continue
                best_g[ckey] = gc
                m = len(nodes)
                nodes.append((xl[q], yl[q], tl[q], flying, n, steps[idx], support))
                if hl_[q] < partial[0]:
                    partial = (hl_[q], m)
                heapq.heappush(open_heap, (fl[q], gc, m))
        result = {"plan": plan, "expanded": expanded, "timed_out": timed_out, "partial": None}
        if plan is None and partial[1] != 0:
            chain = self._reference_chain(partial[1], nodes)
            result["partial"] = (
                partial[0],
                [(nodes[i][3], nodes[i][5]) for i in chain],
                [(nodes[i][3], Pose2D(*nodes[i][:3])) for i in chain],
            )
        return result

    @staticmethod
    def _reference_chain(n, nodes):
        chain = []
        while nodes[n][4] != -1:
            chain.append(n)
            n = nodes[n][4]
        chain.reverse()
        return chain

    def _reference_extract(self, n, nodes, tail, cost):
        chain = self._reference_chain(n, nodes)
        steps = [(nodes[i][3], nodes[i][5]) for i in chain] + [(side, step) for side, step, _ in tail]
        poses = [(nodes[i][3], Pose2D(*nodes[i][:3])) for i in chain] + [(side, pose) for side, _, pose in tail]
        return FootstepPlan("ok", steps, poses, cost=cost)


def _same(a: FootstepPlan, b: FootstepPlan) -> bool:
    return (a.status, a.steps, a.poses, a.cost, a.expanded) == (b.status, b.steps, b.poses, b.cost, b.expanded) and (
        a.epsilon == b.epsilon or (math.isnan(a.epsilon) and math.isnan(b.epsilon))
    )


# -- the tests -------------------------------------------------------------------------------
def test_wrap_is_the_numpy_wrap():
    rng = np.random.default_rng(0)
    a = np.concatenate(
        [rng.uniform(-20, 20, 5000), np.arange(-8, 9) * math.pi, [0.0, -0.0, 2 * math.pi, math.pi / 2, 1e-300]]
    )
    for v, ref in zip(a, _reference_wrap(a)):
        assert kernels.wrap(v) == ref


def test_rect_and_heuristic_kernels_equal_the_numpy_code():
    rng = np.random.default_rng(1)
    scene = sample_scenes(SceneSampler(obstacles=True), 1, seed=3)[0]
    planner = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams())
    circles = planner.rects.circles
    x, y = rng.uniform(-1.5, 3.5, 4000), rng.uniform(-2.5, 2.5, 4000)
    theta = rng.uniform(-4, 4, 4000)
    hl, hw = rng.uniform(0.01, 0.2, 4000), rng.uniform(0.01, 0.2, 4000)
    hits = kernels.rects_hit(circles, x, y, theta, hl, hw)
    assert 0 < hits.sum() < len(hits)
    assert np.array_equal(hits, _reference_hits(circles, x, y, theta, hl, hw))
    assert np.array_equal(planner.turn_from_direction, np.abs(_reference_wrap(scene.goal.theta - planner.direction)))
    h = np.array([planner._heuristic(*v) for v in zip(x, y, theta)])
    ref = _reference_heuristic(planner, x, y, theta)
    assert np.isfinite(h).any() and not np.isfinite(h).all()
    assert np.array_equal(h, ref)


def test_goal_step_is_the_relative_pose_of_the_goal_stance():
    scene = Scene(Pose2D(0.3, 0.1, 0.4), ())
    planner = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams())
    rng = np.random.default_rng(2)
    within = 0
    for _ in range(2000):
        support = Pose2D(*rng.uniform(-0.2, 0.5, 2), rng.uniform(-3.2, 3.2))
        ok, x, y, theta = kernels.goal_step(*support, planner._goal_step)
        rel = support.relative(planner.goal_feet.right)
        assert (x, y, theta) == (rel.x, rel.y + GEOMETRY.foot_distance, rel.theta)
        tol = 1e-9
        assert ok == (abs(x) <= LIMITS.x + tol and abs(y) <= LIMITS.y + tol and abs(theta) <= LIMITS.theta + tol)
        within += ok
    assert within > 0


def _problems():
    """Planning problems over every branch of the search: rest starts and replans on obstacle
    scenes, random believed poses (partial plans, starts inside the safety margin), small budgets,
    the wall-clock budget's loop (a huge budget, so the clock never decides)."""
    rng = np.random.default_rng(5)
    for k, scene in enumerate(sample_scenes(SceneSampler(obstacles=True), 8, seed=11)):
        params = FootstepParams(expansion_budget=(300, 60, 1000)[k % 3])
        feet = GEOMETRY.initial_feet()
        yield scene, params, feet.left, feet.right
        g = scene.goal
        nav = Pose2D(g.x * rng.uniform(0, 1), g.y * rng.uniform(0, 1) + rng.normal(0, 0.2), rng.uniform(-3, 3))
        last = Footstep(*(rng.uniform(-1, 1, 3) * LIMITS.as_array()))
        yield scene, params, *feet_from_nav(nav, GEOMETRY, last)
    scene = Scene(Pose2D(1.0, 0.3, 1.0), (Obstacle(0.5, 0.1, 0.15),))
    feet = GEOMETRY.initial_feet()
    yield scene, FootstepParams(expansion_budget=None, time_budget_s=1e6, max_expansions=400), feet.left, feet.right
    # heading across ±π among obstacles (the mid-swing heading's wrap)
    for k, scene in enumerate(sample_scenes(SceneSampler(obstacles=True), 3, seed=12)):
        yield scene, FootstepParams(), *feet_from_nav(Pose2D(0.0, 0.0, math.pi - 0.05 * k), GEOMETRY, None)
    # standing closer to an obstacle than the safety margin: the search without the margin
    yield Scene(Pose2D(1.0, 0.0, 0.0), (Obstacle(0.0, 0.235, 0.08),)), FootstepParams(), feet.left, feet.right


@pytest.mark.parametrize("problem", list(_problems()), ids=lambda _: "")
def test_compiled_search_plans_exactly_as_the_numpy_search(problem):
    scene, params, left, right = problem
    compiled = FootstepPlanner(GEOMETRY, TRUNK, scene, params)
    reference = _ReferencePlanner(GEOMETRY, TRUNK, scene, params)
    a, b = compiled.plan(left, right), reference.plan(left, right)
    assert _same(a, b), (a.status, b.status, a.cost, b.cost, a.expanded, b.expanded)
    if a.status == "ok" and len(a.steps) >= 4:  # a replan seeded with the rest of the plan (replay)
        _, after, _, _ = GEOMETRY.execute(FeetState(left, right), a.next_double_step())
        again = compiled.plan(after.left, after.right, previous=a)
        assert _same(again, reference.plan(after.left, after.right, previous=b))


def test_recorded_plan():
    """A plan recorded at commit 9bf3437 (numpy search, ``scripts/footstep_plans.py``'s first
    problem): 300 expansions, the ε = 1.2 search's plan of 14 footsteps and cost 16.4693…; the
    footsteps are the transition set's (multiples of half the limits) up to the goal double step."""
    scene = sample_scenes(SceneSampler(obstacles=True), 1, seed=20220101)[0]
    feet = GEOMETRY.initial_feet()
    plan = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams()).plan(feet.left, feet.right)
    assert (plan.status, plan.expanded, plan.epsilon) == ("ok", 300, 1.2)
    assert plan.cost == 16.469320818613465
    assert len(plan.steps) == 14 and plan.steps[0] == (Side.RIGHT, Footstep(0.078, -0.103, -0.764))
    body = [step for _, step in plan.steps[:-2]]
    for step in body:
        for value, limit in zip(step, LIMITS.as_array()):
            assert abs(value / (0.5 * limit) - round(value / (0.5 * limit))) < 1e-9
    final = plan.poses[-1][1], plan.poses[-2][1]
    assert mean_pose(*final).distance_to(scene.goal) < 1e-9
    assert abs(wrap_angle(mean_pose(*final).theta - scene.goal.theta)) < 1e-9
