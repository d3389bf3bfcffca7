"""Classical footstep planner: anytime weighted A* over a finite footstep transition set.

* **Transitions**: a few (x, y, θ) footsteps per foot, fractions of the walk engine's step
  limits (``x_fracs`` × ``y_fracs`` × ``theta_fracs``; y and θ are signed *outward*, so each foot
  mirrors them).  Every footstep is passed once through ``FootstepGeometry.landing`` — the
  same clipping and foot–foot interference the backends apply — so the planner knows exactly
  where each foot lands relative to its support foot.
* **State**: the pose of the foot that landed last and its side (the next support foot); nodes
  keep exact continuous poses, duplicates are detected on a lattice (``lattice_xy`` metres ×
  ``lattice_theta_bins`` headings × side), as in hybrid A*.
* **Collision checks**: like the 2D backend — the flying foot's plate at mid-swing and at
  put-down, and the trunk box at the navigation pose after put-down — rectangles against the
  scene's circles (ball included), grown by ``safety_margin``.
* **Heuristic**: a 2D Dijkstra distance map from the goal over the costmap (obstacles inflated by
  ``heuristic_clearance``) divided by the longest footstep (expected steps), plus the turn left
  to the goal's heading divided by the largest turn.
* **Goal**: at a double-step boundary (left foot just landed, right flies next) an analytic
  expansion tries the double step that puts the feet exactly beside the goal pose.
* **Anytime (ARA*-style)**: weighted A* with ε from ``epsilons`` (e.g. 3 → 1); each finished
  search is followed by one with the next ε and the best plan so far as an upper bound (nodes
  with g + h ≥ best cost are pruned), until the budget runs out: ``expansion_budget`` node
  expansions (the default: the clock does not decide, so a plan is the same on any machine and
  under any load), or with it None ``time_budget_s`` of wall-clock time.  Without any plan when
  the budget ends, the plan to the expanded node nearest the goal (by heuristic) is returned as
  ``partial``; an exhausted search space is ``unreachable``; a goal whose feet or trunk overlap
  an obstacle is ``goal_in_collision``.  The planner never runs past its budget by more than
  one node expansion.

The controller replans every double step from the believed pose and executes the plan's next
double step.
"""

from __future__ import annotations

import csv
import heapq
import math
import time
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from footsim.geometry import Pose2D, mean_pose, wrap_angle
from footsim.planners.grid import Costmap, distance_to_goal_map
from footsim.scene import Obstacle, Scene
from footsim.walk.footsteps import DoubleStep, Footstep, FootstepGeometry, Side


@dataclass(frozen=True)
class FootstepParams:
    """Planner parameters (conf/controller/footstep.yaml documents them)."""

    time_budget_s: float = 0.045  # per plan, with expansion_budget None (anytime: the whole budget is used)
    # Node expansions per plan over all anytime iterations; when set it replaces time_budget_s, so
    # plans do not depend on the machine or its load (docs/BENCHMARKS.md: the time it takes).
    # None: the wall-clock budget.
    expansion_budget: int | None = 300
    epsilons: tuple = (3.0, 2.0, 1.5, 1.2, 1.0)  # heuristic weights of the anytime iterations
    x_fracs: tuple = (-0.5, 0.0, 0.5, 1.0)  # forward step / limits.x
    y_fracs: tuple = (0.0, 0.5, 1.0)  # outward lateral step / limits.y (negative = inward)
    theta_fracs: tuple = (0.0, 0.5, 1.0)  # outward turn / limits.theta
    lattice_xy: float = 0.03  # [m] duplicate detection
    lattice_theta_bins: int = 32
    safety_margin: float = 0.02  # [m] added to obstacle radii in the footprint checks
    resolution: float = 0.05  # heuristic grid [m]
    heuristic_clearance: float = 0.08  # [m] obstacle inflation of the heuristic's distance map
    turn_heuristic_weight: float = 0.5
    heading_switch_distance: float = 0.6  # [m] beyond it the heuristic expects walking along the path
    step_cost: float = 1.0  # per footstep (time)
    turn_cost: float = 0.3  # per radian turned
    backward_cost: float = 1.0  # per limits.x stepped backwards
    lateral_cost: float = 0.3  # per limits.y stepped sideways
    max_expansions: int = 20000
    reuse_plan: bool = True  # seed each replan with the rest of the previous plan (when still valid)
    # A capability map (footsim-capability's capability.csv): only footsteps whose nearest same-step
    # cell fell in at most stable_max_fall_rate of its trials are planned (None: every footstep).
    stable_region: str | None = None
    stable_max_fall_rate: float = 0.0

    def __post_init__(self) -> None:
        if not self.time_budget_s > 0:
            raise ValueError(f"controller.time_budget_s must be > 0, got {self.time_budget_s!r}")
        if self.expansion_budget is not None and not int(self.expansion_budget) >= 1:
            raise ValueError(f"controller.expansion_budget must be >= 1 or null, got {self.expansion_budget!r}")
        if not self.epsilons or any(e < 1.0 for e in self.epsilons):
            raise ValueError(f"controller.epsilons must be a non-empty list of weights >= 1, got {self.epsilons!r}")
        for key in ("x_fracs", "y_fracs", "theta_fracs"):
            values = getattr(self, key)
            if not values or any(abs(v) > 1.0 for v in values):
                raise ValueError(f"controller.{key} must be fractions of the step limits in [-1, 1], got {values!r}")
        if not (self.lattice_xy > 0 and int(self.lattice_theta_bins) >= 4 and self.resolution > 0):
            raise ValueError("controller.lattice_xy and resolution must be > 0, lattice_theta_bins >= 4")
        if not 0.0 <= self.stable_max_fall_rate <= 1.0:
            raise ValueError(f"controller.stable_max_fall_rate must be in [0, 1], got {self.stable_max_fall_rate!r}")

    @classmethod
    def from_mapping(cls, mapping) -> FootstepParams:
        data = {k: v for k, v in dict(mapping).items() if k != "name"}
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"controller (footstep): unknown key(s) {unknown}; valid: {sorted(known)}")
        for key in ("epsilons", "x_fracs", "y_fracs", "theta_fracs"):
            if key in data:
                data[key] = tuple(float(v) for v in data[key])
        return cls(**data)


@dataclass
class FootstepPlan:
    """Footsteps from the start (right foot first), with the feet poses they reach."""

    status: str  # ok | partial | unreachable | goal_in_collision | at_goal
    steps: list[tuple[Side, Footstep]] = field(default_factory=list)
    poses: list[tuple[Side, Pose2D]] = field(default_factory=list)  # where each foot lands
    cost: float = math.inf
    epsilon: float = math.nan  # ε of the search that found it
    expanded: int = 0
    time_s: float = 0.0
    first_solution_s: float = math.nan  # time until the first complete plan (replayed or searched)

    @property
    def ok(self) -> bool:
        return self.status in ("ok", "partial", "at_goal")

    def next_double_step(self) -> DoubleStep:
        """The plan's first double step (right, left); missing steps are rest (0, 0, 0)."""
        right = self.steps[0][1] if len(self.steps) > 0 else Footstep()
        left = self.steps[1][1] if len(self.steps) > 1 else Footstep()
        return DoubleStep(right, left)


class _Rects:
    """Vectorised rectangle–circle overlap against a fixed set of circles."""

    def __init__(self, obstacles: tuple[Obstacle, ...], margin: float):
        self.n = len(obstacles)
        self.cx = np.array([o.x for o in obstacles], dtype=float)
        self.cy = np.array([o.y for o in obstacles], dtype=float)
        self.r2 = (np.array([o.r for o in obstacles], dtype=float) + margin) ** 2

    def hits(self, x, y, theta, half_l, half_w) -> np.ndarray:
        """For arrays of rectangle poses (and half extents, scalar or per pose): overlaps any circle."""
        x = np.asarray(x, dtype=float)
        if self.n == 0:
            return np.zeros(x.shape, dtype=bool)
        theta = np.asarray(theta, dtype=float)
        c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
        dx, dy = self.cx[None, :] - x[:, None], self.cy[None, :] - np.asarray(y, dtype=float)[:, None]
        u, v = c * dx + s * dy, -s * dx + c * dy
        hl = np.asarray(half_l, dtype=float).reshape(-1, 1)
        hw = np.asarray(half_w, dtype=float).reshape(-1, 1)
        qu = np.maximum(np.abs(u) - hl, 0.0)
        qv = np.maximum(np.abs(v) - hw, 0.0)
        return (qu * qu + qv * qv < self.r2[None, :]).any(axis=1)


class StableRegion:
    """The stable part of the action box from a capability map (``footsim-capability``'s CSV): a
    footstep (as unit action x, y, θ of the robot's step limits) is allowed when the nearest
    same-step cell (both feet taking that step) fell in at most ``max_fall_rate`` of its trials."""

    _cache: dict[tuple[str, float], StableRegion] = {}

    def __init__(self, cells: np.ndarray, fall_rates: np.ndarray, max_fall_rate: float):
        self.cells, self.fall_rates, self.max_fall_rate = cells, fall_rates, float(max_fall_rate)

    @classmethod
    def load(cls, path: str, max_fall_rate: float) -> StableRegion:
        key = (str(path), float(max_fall_rate))
        if key not in cls._cache:
            try:
                with open(path, newline="") as f:
                    rows = list(csv.DictReader(f))
            except OSError as err:
                raise ValueError(f"controller.stable_region: cannot read {path}: {err}") from None
            needed = ("right_x", "right_y", "right_theta", "left_x", "left_y", "left_theta", "fall_rate")
            if not rows or any(k not in rows[0] for k in needed):
                raise ValueError(f"controller.stable_region: {path} is not a footsim-capability CSV (columns {needed})")
            same = [r for r in rows if all(r[f"right_{a}"] == r[f"left_{a}"] for a in ("x", "y", "theta"))]
            if not same:
                raise ValueError(f"controller.stable_region: {path} has no same-step cells (make it with grid=same:N)")
            cells = np.array([[float(r["right_x"]), float(r["right_y"]), float(r["right_theta"])] for r in same])
            cls._cache[key] = cls(cells, np.array([float(r["fall_rate"]) for r in same]), max_fall_rate)
        return cls._cache[key]

    def allows(self, x: float, y: float, theta: float) -> bool:
        nearest = int(np.argmin(np.sum((self.cells - (x, y, theta)) ** 2, axis=1)))
        return bool(self.fall_rates[nearest] <= self.max_fall_rate)


class FootstepPlanner:
    """Plans footsteps on one scene (the map and goal are fixed; starts change per replan)."""

    def __init__(
        self,
        geometry: FootstepGeometry,
        trunk_footprint: tuple[float, float],
        scene: Scene,
        params: FootstepParams = FootstepParams(),
        start_xy: tuple[float, float] = (0.0, 0.0),
    ):
        self.geometry = geometry
        self.params = p = params
        self.scene = scene
        self.goal = scene.goal
        self.limits = geometry.limits
        self.foot_half = (0.5 * geometry.foot_length, 0.5 * geometry.foot_width)
        self.trunk_half = (0.5 * trunk_footprint[0], 0.5 * trunk_footprint[1])
        obstacles = scene.all_obstacles
        self.rects = _Rects(obstacles, p.safety_margin)
        self.rects_exact = _Rects(obstacles, 0.0)
        self._active_rects = self.rects
        # Transition set per flying side, deduplicated: executed footsteps, landing poses relative to
        # the support foot, costs, and the half extents of the 3k rectangles checked per expansion
        # (landing foot, mid-swing foot, trunk).
        # per flying side: steps, their relative poses, costs, and the half lengths/widths of the
        # checked rectangles (both feet and the trunk)
        self.transitions: dict[Side, tuple[list[Footstep], np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        lim = self.limits
        self.stable = stable = (
            None if p.stable_region is None else StableRegion.load(p.stable_region, p.stable_max_fall_rate)
        )
        for side in (Side.LEFT, Side.RIGHT):
            seen, steps, rels, costs = set(), [], [], []
            for fx in p.x_fracs:
                for fy in p.y_fracs:
                    for ft in p.theta_fracs:
                        if stable is not None and not stable.allows(fx, side.sign * fy, side.sign * ft):
                            continue
                        step = Footstep(fx * lim.x, side.sign * fy * lim.y, side.sign * ft * lim.theta)
                        rel, done, _ = geometry.landing(side, step)
                        key = (round(rel.x, 6), round(rel.y, 6), round(rel.theta, 6))
                        if key in seen:
                            continue
                        seen.add(key)
                        steps.append(done)
                        rels.append(rel)
                        costs.append(
                            p.step_cost
                            + p.turn_cost * abs(done.theta)
                            + p.backward_cost * max(-done.x, 0.0) / lim.x
                            + p.lateral_cost * abs(done.y) / lim.y
                        )
            k = len(steps)
            if k == 0:
                raise ValueError(
                    f"controller.stable_region {p.stable_region}: no footstep of the transition set is stable "
                    f"(stable_max_fall_rate {p.stable_max_fall_rate})"
                )
            half_l = np.concatenate([np.full(2 * k, self.foot_half[0]), np.full(k, self.trunk_half[0])])
            half_w = np.concatenate([np.full(2 * k, self.foot_half[1]), np.full(k, self.trunk_half[1])])
            self.transitions[side] = (steps, np.array(rels, dtype=float), np.array(costs, dtype=float), half_l, half_w)
        # Heuristic map.
        g = self.goal
        self.costmap = Costmap.from_obstacles(
            obstacles, [start_xy, (g.x, g.y)], p.resolution, p.heuristic_clearance, margin=1.0
        )
        self.dist = distance_to_goal_map(self.costmap, (g.x, g.y))
        self.direction = _downhill_direction(self.dist, self.costmap.resolution)
        self.turn_from_direction = np.abs(_wrap(g.theta - self.direction))
        # The feet standing at the goal.
        self.goal_feet = geometry.initial_feet(g)
        self.goal_status = (
            "ok"
            if not self._stance_collides(self.goal_feet.left, self.goal_feet.right, exact=True)
            else "goal_in_collision"
        )
        # The last double step may come as close to obstacles as the goal stance itself does
        # (the ball lies 0.125 m ahead of the goal): its margin is capped by the stance's clearance.
        lo, hi = 0.0, p.safety_margin
        if self.goal_status == "ok" and self._stance_collides(self.goal_feet.left, self.goal_feet.right):
            for _ in range(12):
                self.rects = _Rects(obstacles, 0.5 * (lo + hi))
                lo, hi = (
                    (lo, 0.5 * (lo + hi))
                    if self._stance_collides(self.goal_feet.left, self.goal_feet.right)
                    else (0.5 * (lo + hi), hi)
                )
            self.rects = _Rects(obstacles, p.safety_margin)
        self.rects_goal = _Rects(obstacles, lo if lo < p.safety_margin else p.safety_margin)

    # -- geometry helpers -----------------------------------------------------------------------
    def _stance_collides(self, left: Pose2D, right: Pose2D, exact: bool = False) -> bool:
        rects = self.rects_exact if exact else self.rects
        nav = mean_pose(left, right)
        xs = np.array([left.x, right.x, nav.x])
        ys = np.array([left.y, right.y, nav.y])
        ts = np.array([left.theta, right.theta, nav.theta])
        hl = np.array([self.foot_half[0]] * 2 + [self.trunk_half[0]])
        hw = np.array([self.foot_half[1]] * 2 + [self.trunk_half[1]])
        return bool(rects.hits(xs, ys, ts, hl, hw).any())

    def _heuristic(self, x, y, theta) -> np.ndarray:
        """Expected footsteps to the goal from navigation poses (arrays); inf outside/unreachable.

        Distance along the Dijkstra map over the longest footstep, plus the turning left: beyond
        ``heading_switch_distance`` first to the map's downhill direction and later to the goal
        heading, within it straight to the goal heading (weighted by ``turn_heuristic_weight``).
        """
        cm = self.costmap
        fi = (np.asarray(x) - cm.origin[0]) * (1.0 / cm.resolution)
        fj = (np.asarray(y) - cm.origin[1]) * (1.0 / cm.resolution)
        i = np.rint(fi).astype(np.intp)
        j = np.rint(fj).astype(np.intp)
        inside = (i >= 0) & (i < cm.shape[0]) & (j >= 0) & (j < cm.shape[1])
        i, j = np.where(inside, i, 0), np.where(inside, j, 0)
        d = np.where(inside, self.dist[i, j], np.inf)
        theta = np.asarray(theta)
        to_goal = np.abs(_wrap(self.goal.theta - theta))
        direction = self.direction[i, j]
        via_path = np.abs(_wrap(direction - theta)) + self.turn_from_direction[i, j]
        turn = np.where(d > self.params.heading_switch_distance, via_path, to_goal)
        return d * (1.0 / self.limits.x) + (self.params.turn_heuristic_weight / self.limits.theta) * turn

    def _goal_shot(self, support: Pose2D, flying_start: Pose2D) -> tuple[list, float] | None:
        """The double step (right then left) from left support ``support`` that ends at the goal."""
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
        left = feet.left  # from the right foot at the goal: the resting pose, step (0, 0, 0)
        mid_r, mid_l = mean_pose(flying_start, right), mean_pose(support, left)
        nav_r = mean_pose(support, right)
        xs = np.array([mid_r.x, right.x, nav_r.x, mid_l.x, left.x])
        ys = np.array([mid_r.y, right.y, nav_r.y, mid_l.y, left.y])
        ts = np.array([mid_r.theta, right.theta, nav_r.theta, mid_l.theta, left.theta])
        fh, th = self.foot_half, self.trunk_half
        hl = np.array([fh[0], fh[0], th[0], fh[0], fh[0]])
        hw = np.array([fh[1], fh[1], th[1], fh[1], fh[1]])
        rects = self.rects_goal if self._active_rects is self.rects else self._active_rects
        if rects.hits(xs, ys, ts, hl, hw).any():
            return None
        p = self.params
        cost = (
            2 * p.step_cost
            + p.turn_cost * abs(done.theta)
            + p.backward_cost * max(-done.x, 0) / lim.x
            + p.lateral_cost * abs(done.y) / lim.y
        )
        return [(Side.RIGHT, done, right), (Side.LEFT, Footstep(), left)], cost

    # -- search --------------------------------------------------------------------------------
    def plan(
        self, left: Pose2D, right: Pose2D, budget_s: float | None = None, previous: FootstepPlan | None = None
    ) -> FootstepPlan:
        """Plan from the feet (left foot supporting, right foot flies first).

        ``previous``: the plan being executed; its remaining footsteps (after the double step
        just taken) are replayed from the new feet and, when still collision-free and ending in
        a feasible goal double step, seed the anytime search as its first solution.
        """
        t0 = time.perf_counter()
        budget = self.params.time_budget_s if budget_s is None else budget_s
        expansion_budget = self.params.expansion_budget
        deadline = math.inf if expansion_budget is not None else t0 + budget
        expansions_left: float = math.inf if expansion_budget is None else int(expansion_budget)
        if self.goal_status != "ok":
            return FootstepPlan(self.goal_status, time_s=time.perf_counter() - t0)
        nav = mean_pose(left, right)
        if nav.distance_to(self.goal) < 1e-3 and abs(wrap_angle(self.goal.theta - nav.theta)) < 1e-3:
            return FootstepPlan("at_goal", cost=0.0, time_s=time.perf_counter() - t0)
        h0 = float(self._heuristic([nav.x], [nav.y], [nav.theta])[0])
        if not math.isfinite(h0):
            return FootstepPlan("unreachable", time_s=time.perf_counter() - t0)
        best: FootstepPlan | None = self.replay(left, right, previous) if previous is not None else None
        first_solution = time.perf_counter() - t0 if best is not None else math.nan
        best_partial = None
        expanded_total = 0
        exhausted = False
        rect_sets = [self.rects, self.rects_exact] if self.params.safety_margin > 0 else [self.rects]
        for rects in rect_sets:  # when the margin leaves no way out (e.g. the robot already stands
            exhausted = False  # closer than the margin), search again without it
            self._active_rects = rects
            for eps in self.params.epsilons:
                result = self._weighted_astar(
                    left, right, eps, best.cost if best else math.inf, deadline, expansions_left - expanded_total
                )
                expanded_total += result["expanded"]
                if result["partial"] is not None and (best_partial is None or result["partial"][0] < best_partial[0]):
                    best_partial = result["partial"]
                if result["plan"] is not None:
                    best = result["plan"]
                    best.epsilon = eps
                    if math.isnan(first_solution):
                        first_solution = time.perf_counter() - t0
                if result["timed_out"]:
                    break
                if result["plan"] is None and best is None:
                    exhausted = True
                    break
                if time.perf_counter() >= deadline or expanded_total >= expansions_left:
                    break
            if not exhausted or time.perf_counter() >= deadline or expanded_total >= expansions_left:
                break
        self._active_rects = self.rects
        elapsed = time.perf_counter() - t0
        if best is not None:
            best.expanded, best.time_s, best.first_solution_s = expanded_total, elapsed, first_solution
            return best
        if exhausted:
            return FootstepPlan("unreachable", expanded=expanded_total, time_s=elapsed)
        if best_partial is not None:
            _, steps, poses = best_partial
            return FootstepPlan("partial", steps, poses, expanded=expanded_total, time_s=elapsed)
        return FootstepPlan("unreachable", expanded=expanded_total, time_s=elapsed)

    def replay(self, left: Pose2D, right: Pose2D, previous: FootstepPlan) -> FootstepPlan | None:
        """``previous`` minus its first double step, replayed from these feet, if still valid."""
        if previous.status != "ok" or len(previous.steps) < 4:
            return None
        feet = {Side.LEFT: left, Side.RIGHT: right}
        steps, poses, cost = [], [], 0.0
        body = previous.steps[2:-2]  # the last double step is re-aimed at the goal
        for side, step in body:
            support = feet[side.other]
            rel, done, _ = self.geometry.landing(side, step)
            landed = support.compose(rel)
            mid, nav = mean_pose(feet[side], landed), mean_pose(support, landed)
            xs, ys, ts = [landed.x, mid.x, nav.x], [landed.y, mid.y, nav.y], [landed.theta, mid.theta, nav.theta]
            if self.rects.hits(
                xs,
                ys,
                ts,
                [self.foot_half[0]] * 2 + [self.trunk_half[0]],
                [self.foot_half[1]] * 2 + [self.trunk_half[1]],
            ).any():
                return None
            feet[side] = landed
            steps.append((side, done))
            poses.append((side, landed))
            p = self.params
            cost += (
                p.step_cost
                + p.turn_cost * abs(done.theta)
                + p.backward_cost * max(-done.x, 0.0) / self.limits.x
                + p.lateral_cost * abs(done.y) / self.limits.y
            )
        shot = self._goal_shot(feet[Side.LEFT], feet[Side.RIGHT])
        if shot is None:
            return None
        steps += [(side, step) for side, step, _ in shot[0]]
        poses += [(side, pose) for side, _, pose in shot[0]]
        return FootstepPlan("ok", steps, poses, cost=cost + shot[1], epsilon=previous.epsilon)

    def _weighted_astar(
        self, left: Pose2D, right: Pose2D, eps: float, bound: float, deadline: float, expansions_left: float
    ) -> dict:
        p = self.params
        inv_res, nbins = 1.0 / p.lattice_xy, int(p.lattice_theta_bins)
        inv_bin = nbins / (2 * math.pi)
        # node: (x, y, theta, side, parent, step, support pose = the flying foot's next start)
        nodes: list[tuple[float, float, float, Side, int, Footstep | None, Pose2D]] = [
            (left.x, left.y, left.theta, Side.LEFT, -1, None, right)
        ]
        nav0 = mean_pose(left, right)
        h_start = float(self._heuristic([nav0.x], [nav0.y], [nav0.theta])[0])
        open_heap = [(eps * h_start, 0.0, 0)]
        best_g: dict[int, float] = {}
        closed: set = set()
        plan = None
        partial = (h_start, 0)
        expanded = 0
        timed_out = False
        side_bit = {Side.LEFT: 0, Side.RIGHT: 1}
        while open_heap:
            if expanded >= expansions_left or time.perf_counter() >= deadline:
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
            if side is Side.LEFT:  # double-step boundary: try to finish
                shot = self._goal_shot(support, other)
                if shot is not None and g + shot[1] < bound:
                    plan = self._extract(n, nodes, shot[0], g + shot[1])
                    break
            flying = side.other
            steps, rels, costs, hl, hw = self.transitions[flying]
            c, s = math.cos(t), math.sin(t)
            lx = x + c * rels[:, 0] - s * rels[:, 1]
            ly = y + s * rels[:, 0] + c * rels[:, 1]
            lt = t + rels[:, 2]
            # navigation pose after landing and the flying foot at mid-swing (circular means)
            nav_x, nav_y = 0.5 * (x + lx), 0.5 * (y + ly)
            nav_t = t + 0.5 * rels[:, 2]
            mid_t = other.theta + 0.5 * _wrap(lt - other.theta)
            k = len(lx)
            hits = (
                self._active_rects.hits(
                    np.concatenate([lx, 0.5 * (other.x + lx), nav_x]),
                    np.concatenate([ly, 0.5 * (other.y + ly), nav_y]),
                    np.concatenate([lt, mid_t, nav_t]),
                    hl,
                    hw,
                )
                .reshape(3, k)
                .any(axis=0)
            )
            h = self._heuristic(nav_x, nav_y, nav_t)
            gs = g + costs
            ok = np.flatnonzero(~hits & np.isfinite(h) & (gs + h < bound))
            if ok.size == 0:
                continue
            lt = _wrap(lt)
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
        result: dict[str, Any] = {"plan": plan, "expanded": expanded, "timed_out": timed_out, "partial": None}
        if plan is None and partial[1] != 0:
            chain = self._chain(partial[1], nodes)
            result["partial"] = (
                partial[0],
                [(nodes[i][3], nodes[i][5]) for i in chain],
                [(nodes[i][3], Pose2D(*nodes[i][:3])) for i in chain],
            )
        return result

    @staticmethod
    def _chain(n: int, nodes: list) -> list[int]:
        chain = []
        while nodes[n][4] != -1:
            chain.append(n)
            n = nodes[n][4]
        chain.reverse()
        return chain

    def _extract(self, n: int, nodes: list, tail, cost: float) -> FootstepPlan:
        chain = self._chain(n, nodes)
        out_steps = [(nodes[i][3], nodes[i][5]) for i in chain] + [(side, step) for side, step, _ in tail]
        poses = [(nodes[i][3], Pose2D(*nodes[i][:3])) for i in chain] + [(side, pose) for side, _, pose in tail]
        return FootstepPlan("ok", out_steps, poses, cost=cost)


def _wrap(a):
    return np.mod(np.asarray(a) + np.pi, 2.0 * np.pi) - np.pi


def _downhill_direction(dist: np.ndarray, resolution: float) -> np.ndarray:
    """Per cell, the heading [rad] towards the neighbour that lies on the shortest way to the goal."""
    nx, ny = dist.shape
    padded = np.pad(dist, 1, constant_values=np.inf)
    best = np.full(dist.shape, np.inf)
    direction = np.zeros(dist.shape)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            neighbour = padded[1 + di : 1 + di + nx, 1 + dj : 1 + dj + ny] + resolution * math.hypot(di, dj)
            better = neighbour < best
            best = np.where(better, neighbour, best)
            direction = np.where(better, math.atan2(dj, di), direction)
    return direction


def feet_from_nav(nav: Pose2D, geometry: FootstepGeometry, last_left_step: Footstep | None) -> tuple[Pose2D, Pose2D]:
    """The feet (left, right) that put the navigation pose at ``nav``.

    After a double step the left foot landed last, at ``landing(LEFT, step)`` relative to the
    right foot; the navigation pose is the mean of the two.  Without a previous step the feet
    stand at rest.
    """
    if last_left_step is None:
        feet = geometry.initial_feet(nav)
        return feet.left, feet.right
    rel, _, _ = geometry.landing(Side.LEFT, last_left_step)  # left in the right foot's frame
    right_in_left = rel.inverse()
    half = Pose2D(0.5 * right_in_left.x, 0.5 * right_in_left.y, 0.5 * right_in_left.theta)  # nav in left frame
    left = nav.compose(half.inverse())
    return left, left.compose(right_in_left)


class FootstepController:
    """The footstep planner as a ``footsim.rl.evaluate.Controller``: replan every double step.

    Observes ``info["pose_estimate"]`` (believed navigation pose), the scene's obstacles and goal;
    the feet are reconstructed from the believed pose and its own last commanded step.  When the
    planner reports failure (``goal_in_collision``, ``unreachable``) it steps in place, so the
    episode ends as a timeout, and ``status``/``failure_reason`` say why.
    """

    kind = "footstep"

    def __init__(
        self,
        geometry: FootstepGeometry,
        trunk_footprint: tuple[float, float],
        params: FootstepParams = FootstepParams(),
    ):
        self.geometry = geometry
        length, width = trunk_footprint
        self.trunk_footprint = (length, width)
        self.params = params
        self.limits = geometry.limits
        self.planner: FootstepPlanner | None = None
        self._reset_state()

    @classmethod
    def from_env(cls, env, params: FootstepParams | dict | None = None) -> FootstepController:
        if params is None:
            params = FootstepParams()
        elif not isinstance(params, FootstepParams):
            params = FootstepParams.from_mapping(params)
        geometry = FootstepGeometry(env.limits, env.robot.foot_length, env.robot.foot_width, env.walk.foot_distance)
        return cls(geometry, env.robot.torso_footprint, params)

    def _reset_state(self) -> None:
        self.last_left_step: Footstep | None = None
        self.status = "idle"
        self.failure_reason = ""
        self.plan_times: list[float] = []
        self.plans: list[FootstepPlan] = []
        self.statuses: dict[str, int] = {}

    def reset(self, scene: Scene, info: dict) -> None:
        self._reset_state()
        pose = Pose2D(*info["pose_estimate"])
        self.planner = FootstepPlanner(self.geometry, self.trunk_footprint, scene, self.params, (pose.x, pose.y))

    def __call__(self, obs, info: dict) -> np.ndarray:
        nav = Pose2D(*info["pose_estimate"])
        if self.failure_reason == "goal_in_collision":
            plan = FootstepPlan(self.failure_reason)  # the map and goal are static: don't search again
        else:
            left, right = feet_from_nav(nav, self.geometry, self.last_left_step)
            previous = self.plans[-1] if self.plans and self.params.reuse_plan else None
            assert self.planner is not None, "reset() builds the planner"
            plan = self.planner.plan(left, right, previous=previous)
            self.plan_times.append(plan.time_s)
            self.plans.append(plan)
        self.status = plan.status
        self.statuses[plan.status] = self.statuses.get(plan.status, 0) + 1
        self.failure_reason = "" if plan.ok else plan.status
        double_step = plan.next_double_step() if plan.ok else DoubleStep(Footstep(), Footstep())
        self.last_left_step = double_step.second
        return np.clip(double_step.as_array() / np.tile(self.limits.as_array(), 2), -1.0, 1.0)

    def episode_info(self) -> dict:
        times = np.array(self.plan_times) * 1e3
        failed = sum(n for k, n in self.statuses.items() if k in ("unreachable", "goal_in_collision"))
        return {
            "planner_status": self.failure_reason or self.status,
            "failed_plans": failed,
            "plans": len(times),
            "plan_ms_median": float(np.median(times)) if len(times) else math.nan,
        }
