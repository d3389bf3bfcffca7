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
  scene's circles (ball included), grown by ``safety_margin``; optionally the upper body's box
  against the obstacles (``upper_body``, the 2D backend's ``collision_model=upper_body``).
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

The search loop, the footprint checks and the heuristic are compiled
(:mod:`footsim.planners.search_kernels`, bit-identical to the numpy code they replaced); the goal
double step, the replay of the previous plan and the anytime schedule stay here.
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from footsim.geometry import Pose2D, mean_pose, wrap_angle
from footsim.planners import search_kernels as kernels
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
    """Rectangle–circle overlap against a fixed set of circles, grown by a margin
    (:func:`footsim.planners.search_kernels.rect_hits`)."""

    def __init__(self, obstacles: tuple[Obstacle, ...], margin: float):
        self.n = len(obstacles)
        r2 = (np.array([o.r for o in obstacles], dtype=float) + margin) ** 2
        self.circles = np.ascontiguousarray(
            np.column_stack([[o.x for o in obstacles], [o.y for o in obstacles], r2]).reshape(-1, 3), dtype=float
        )

    def hits(self, x, y, theta, half_l, half_w) -> np.ndarray:
        """For equally long arrays of rectangle poses and half extents: overlaps any circle."""
        x, y, theta, half_l, half_w = (np.asarray(a, dtype=float) for a in (x, y, theta, half_l, half_w))
        return kernels.rects_hit(self.circles, x, y, theta, half_l, half_w)


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
        upper_body: tuple[float, float, float] | None = None,
    ):
        """``upper_body``: the box over torso, head and arms (length, width, its centre's offset
        ahead of the navigation pose) checked against the obstacles (not the ball, which stays below
        the arms) besides the trunk box, as the 2D backend's ``collision_model=upper_body`` does."""
        self.geometry = geometry
        self.params = p = params
        self.scene = scene
        self.goal = scene.goal
        self.limits = geometry.limits
        self.foot_half = (0.5 * geometry.foot_length, 0.5 * geometry.foot_width)
        self.trunk_half = (0.5 * trunk_footprint[0], 0.5 * trunk_footprint[1])
        self.upper_body = upper_body
        # half length, half width and offset of the upper body's box (0, 0, 0: none)
        self._upper = (
            (0.0, 0.0, 0.0) if upper_body is None else (0.5 * upper_body[0], 0.5 * upper_body[1], upper_body[2])
        )
        self._n_tall = len(scene.obstacles)  # scene.all_obstacles lists them first, the ball last
        obstacles = scene.all_obstacles
        self.rects = _Rects(obstacles, p.safety_margin)
        self.rects_exact = _Rects(obstacles, 0.0)
        self._active_rects = self.rects
        # Transition set per flying side, deduplicated: executed footsteps, landing poses relative to
        # the support foot, costs.
        self.transitions: dict[Side, tuple[list[Footstep], np.ndarray, np.ndarray]] = {}
        # half extents of the rectangles checked per expansion: the foot (landing, mid-swing), the trunk
        self._extents = np.array([*self.foot_half, *self.trunk_half, *self._upper, self._n_tall], dtype=float)
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
            self.transitions[side] = (steps, np.array(rels, dtype=float), np.array(costs, dtype=float))
        # Heuristic map.
        g = self.goal
        self.costmap = Costmap.from_obstacles(
            obstacles, [start_xy, (g.x, g.y)], p.resolution, p.heuristic_clearance, margin=1.0
        )
        self.dist = distance_to_goal_map(self.costmap, (g.x, g.y))
        self.direction = _downhill_direction(self.dist, self.costmap.resolution)
        self.turn_from_direction = kernels.turn_table(g.theta, self.direction)
        cm = self.costmap
        self._heuristic_params = np.array(
            [
                cm.origin[0],
                cm.origin[1],
                1.0 / cm.resolution,
                g.theta,
                p.heading_switch_distance,
                1.0 / self.limits.x,
                p.turn_heuristic_weight / self.limits.theta,
            ]
        )
        # The feet standing at the goal.
        self.goal_feet = geometry.initial_feet(g)
        tol = 1e-9
        self._goal_step = np.array(
            [
                *self.goal_feet.right,
                geometry.foot_distance,
                self.limits.x + tol,
                self.limits.y + tol,
                self.limits.theta + tol,
            ]
        )  # kernels.goal_step: the goal's right foot, the foot distance, the limits
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
        # The compiled search's first call compiles it (or loads it from numba's cache): here, not
        # within a plan's wall-clock budget.  Bound 0 prunes every child; nothing else is kept.
        self._weighted_astar(self.goal_feet.left, self.goal_feet.right, 1.0, 0.0, math.inf, 1)

    # -- geometry helpers -----------------------------------------------------------------------
    def _upper_body_hits(self, rects: _Rects, navs: list[Pose2D]) -> bool:
        """Does the upper body's box (if any) at one of the navigation poses ``navs`` touch an obstacle?"""
        hl, hw, offset = self._upper
        if hl == 0.0:
            return False
        centres = [nav.compose(Pose2D(offset, 0.0, 0.0)) for nav in navs]
        tall = rects.circles[: self._n_tall]
        xs, ys, ts = (np.array([centre[k] for centre in centres]) for k in range(3))
        return bool(kernels.rects_hit(tall, xs, ys, ts, np.full(len(navs), hl), np.full(len(navs), hw)).any())

    def _stance_collides(self, left: Pose2D, right: Pose2D, exact: bool = False) -> bool:
        rects = self.rects_exact if exact else self.rects
        nav = mean_pose(left, right)
        if self._upper_body_hits(rects, [nav]):
            return True
        xs = np.array([left.x, right.x, nav.x])
        ys = np.array([left.y, right.y, nav.y])
        ts = np.array([left.theta, right.theta, nav.theta])
        hl = np.array([self.foot_half[0]] * 2 + [self.trunk_half[0]])
        hw = np.array([self.foot_half[1]] * 2 + [self.trunk_half[1]])
        return bool(rects.hits(xs, ys, ts, hl, hw).any())

    def _heuristic(self, x: float, y: float, theta: float) -> float:
        """Expected footsteps to the goal from a navigation pose; inf outside the map/unreachable.

        Distance along the Dijkstra map over the longest footstep, plus the turning left: beyond
        ``heading_switch_distance`` first to the map's downhill direction and later to the goal
        heading, within it straight to the goal heading (weighted by ``turn_heuristic_weight``).
        """
        return float(
            kernels.heuristic(self._heuristic_params, self.dist, self.direction, self.turn_from_direction, x, y, theta)
        )

    def _goal_shot(self, support: Pose2D, flying_start: Pose2D) -> tuple[list, float] | None:
        """The double step (right then left) from left support ``support`` that ends at the goal."""
        geo, feet = self.geometry, self.goal_feet
        within, x, y, theta = kernels.goal_step(support.x, support.y, support.theta, self._goal_step)
        if not within:
            return None
        step = Footstep(x, y, theta)
        lim = self.limits
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
        if rects.hits(xs, ys, ts, hl, hw).any() or self._upper_body_hits(rects, [nav_r]):
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
        h0 = self._heuristic(nav.x, nav.y, nav.theta)
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
            ).any() or self._upper_body_hits(self.rects, [nav]):
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
        """One weighted-A* search with heuristic weight ``eps``, pruning at ``bound``; the loop runs in
        :func:`footsim.planners.search_kernels.search`, which comes back here for the goal double step
        at each double-step boundary and, with a wall-clock deadline, before each pop."""
        p = self.params
        k = max(len(t[0]) for t in self.transitions.values())
        state = kernels.SearchState(1 + k * int(min(expansions_left, p.max_expansions, 64)))
        st, sp = state.st, state.sp
        # the root: the left foot landed last, the right (its support pose) flies next
        state.pose[0] = (left.x, left.y, left.theta, 0.0)
        state.link[0] = (0, -1, -1)
        nav0 = mean_pose(left, right)
        h_start = self._heuristic(nav0.x, nav0.y, nav0.theta)
        state.hf[0], state.hg[0], state.hm[0] = eps * h_start, 0.0, 0
        nbins = int(p.lattice_theta_bins)
        big = np.iinfo(np.int64).max
        st[:] = (1, 1, 0, 0, big if math.isinf(expansions_left) else int(expansions_left), nbins, p.max_expansions)
        sp[:] = (eps, bound, 1.0 / p.lattice_xy, nbins / (2 * math.pi), h_start, 0.0, 0.0, *right)
        steps_l, rels_l, costs_l = self.transitions[Side.LEFT]
        steps_r, rels_r, costs_r = self.transitions[Side.RIGHT]
        circles = self._active_rects.circles
        timed = math.isfinite(deadline)
        plan = None
        timed_out = False
        pending, pops = -1, 0 if timed else big
        while True:
            reason, n = kernels.search(
                st, state.pose, state.link, state.hf, state.hg, state.hm, state.cell_key, state.cell_g, sp,
                rels_l, costs_l, rels_r, costs_r, circles, self._extents, self._heuristic_params,
                self.dist, self.direction, self.turn_from_direction, self._goal_step, pending, pops,
            )  # fmt: skip
            pending, pops = -1, 0 if timed else big
            if reason == kernels.GROW:
                state.grow()
                pending = n
            elif reason == kernels.GOAL_SHOT:  # double-step boundary: try to finish
                x, y, t, g = state.pose[n].tolist()
                parent = int(state.link[n, 1])
                other = right if parent < 0 else Pose2D(*state.pose[parent, :3].tolist())
                shot = self._goal_shot(Pose2D(x, y, t), other)
                if shot is not None and g + shot[1] < bound:
                    plan = self._extract(n, state, shot[0], g + shot[1])
                    break
                pending = n
            elif reason == kernels.CLOCK:
                if time.perf_counter() >= deadline:
                    timed_out = True
                    break
                pops = 1
            else:
                timed_out = reason != kernels.EMPTY
                break
        result: dict[str, Any] = {"plan": plan, "expanded": int(st[2]), "timed_out": timed_out, "partial": None}
        if plan is None and st[3] != 0:
            chain = self._chain(int(st[3]), state)
            result["partial"] = (float(sp[4]), [step for step, _ in chain], [pose for _, pose in chain])
        return result

    def _chain(self, n: int, state: kernels.SearchState) -> list[tuple[tuple[Side, Footstep], tuple[Side, Pose2D]]]:
        """The footsteps and landing poses from the root to node ``n``."""
        chain = []
        link, pose = state.link, state.pose
        while link[n, 1] != -1:
            side_bit, parent, j = link[n].tolist()
            side = Side.RIGHT if side_bit else Side.LEFT
            chain.append(((side, self.transitions[side][0][j]), (side, Pose2D(*pose[n, :3].tolist()))))
            n = parent
        chain.reverse()
        return chain

    def _extract(self, n: int, state: kernels.SearchState, tail, cost: float) -> FootstepPlan:
        chain = self._chain(n, state)
        out_steps = [step for step, _ in chain] + [(side, step) for side, step, _ in tail]
        poses = [pose for _, pose in chain] + [(side, pose) for side, _, pose in tail]
        return FootstepPlan("ok", out_steps, poses, cost=cost)


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
        upper_body: tuple[float, float, float] | None = None,
    ):
        self.geometry = geometry
        length, width = trunk_footprint
        self.trunk_footprint = (length, width)
        self.upper_body = upper_body  # FootstepPlanner's upper_body
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
        # plan against what the env's collision check tests
        return cls(geometry, env.robot.torso_footprint, params, env.backend.upper_body_box)

    def _reset_state(self) -> None:
        self.last_left_step: Footstep | None = None
        self.status = "idle"
        self.failure_reason = ""
        self.plan_times: list[float] = []
        self.plans: list[FootstepPlan] = []
        self.statuses: dict[str, int] = {}

    def reset(self, scene: Scene, info: dict, seed: int) -> None:  # deterministic: the seed is unused
        self._reset_state()
        pose = Pose2D(*info["pose_estimate"])
        self.planner = FootstepPlanner(
            self.geometry, self.trunk_footprint, scene, self.params, (pose.x, pose.y), self.upper_body
        )

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
