"""Baselines: grid planners, carrot local planner, footstep planner, and both in the 2D env."""

import math

import numpy as np
import pytest

from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.planners.controllers import make_controller
from footsim.planners.footstep import FootstepParams, FootstepPlanner, feet_from_nav
from footsim.planners.grid import Costmap, cell_path_length, distance_to_goal_map, grid_search, plan_path
from footsim.planners.velocity import VelocityController, VelocityParams, carrot_command, smooth
from footsim.rl.evaluate import evaluate
from footsim.scene import Obstacle, Scene
from footsim.tasks.scenes import SceneSampler, sample_scenes
from footsim.walk.footsteps import DoubleStep, Footstep, FootstepGeometry, Side, StepLimits

LIMITS = StepLimits(0.156, 0.103, 0.764)
GEOMETRY = FootstepGeometry(LIMITS, 0.154, 0.106, 0.1799)
TRUNK = (0.15, 0.15)


def _segment_clear(costmap: Costmap, a, b) -> bool:
    """Independent check: points every 1/20 cell along a→b lie in unblocked cells."""
    n = int(20 * math.hypot(b[0] - a[0], b[1] - a[1]) / costmap.resolution) + 2
    for t in np.linspace(0, 1, n):
        i, j = costmap.cell(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
        if costmap.blocked[i, j]:
            return False
    return True


@pytest.mark.parametrize("algorithm", ["theta_star", "lazy_theta_star"])
def test_theta_star_collision_free_and_no_longer_than_astar(algorithm):
    scenes = sample_scenes(SceneSampler(obstacles=True), 12, seed=11)
    compared = 0
    for scene in scenes:
        cm = Costmap.from_obstacles(scene.all_obstacles, [(0, 0), (scene.goal.x, scene.goal.y)], 0.05, 0.17)
        start, goal = cm.nearest_free(cm.cell(0, 0)), cm.nearest_free(cm.cell(scene.goal.x, scene.goal.y))
        astar, _ = grid_search(cm, start, goal, "astar")
        theta, _ = grid_search(cm, start, goal, algorithm)
        assert (astar is None) == (theta is None)
        if astar is None:
            continue
        compared += 1
        assert theta[0] == start and theta[-1] == goal
        for a, b in zip(theta[:-1], theta[1:]):
            assert _segment_clear(cm, cm.world(*a), cm.world(*b)), f"segment {a}->{b} crosses a blocked cell"
        assert cell_path_length(cm, theta) <= cell_path_length(cm, astar) + 1e-9
    assert compared >= 8


def test_costmap_inflation_and_distance_map():
    cm = Costmap.from_obstacles((Obstacle(1.0, 0.0, 0.2),), [(0, 0), (2, 0)], 0.05, 0.15)
    assert cm.blocked[cm.cell(1.0, 0.3)] and not cm.blocked[cm.cell(1.0, 0.45)]
    assert abs(cm.clearance[cm.cell(1.0, 0.5)] - 0.3) <= 0.05
    dist = distance_to_goal_map(cm, (2.0, 0.0))
    d0 = dist[cm.cell(0, 0)]
    assert 2.0 < d0 < 2.0 + 0.5  # around the inflated disc
    path = plan_path(cm, (0, 0), (2, 0), "lazy_theta_star")
    assert path is not None and 2.0 < path.length <= d0 + 1e-9  # any-angle beats 8-connected


def test_carrot_controller_hand_computed():
    p = VelocityParams(
        max_vel_x=0.3,
        min_vel_x=-0.1,
        max_vel_y=0.1,
        max_rotation_vel=0.6,
        translation_slow_down_factor=0.5,
        rotation_slow_down_factor=0.3,
        orient_to_goal_distance=1.0,
    )
    # Far (d = 2 > 1): walk_vel = min(2 · 0.5, 0.3) = 0.3 towards the carrot at 45°:
    # (0.212, 0.212) scaled by 0.1 / 0.212 so |vy| = 0.1 → (0.1, 0.1); face the goal position (bearing 0).
    vx, vy, om = carrot_command(Pose2D(0, 0, 0), (1.0, 1.0), Pose2D(2.0, 0.0, 0.5), p)
    assert (vx, vy, om) == pytest.approx((0.1, 0.1, 0.0))
    # Near (d = 0.5): walk_vel = 0.25 straight ahead; ω = 0.3 · (1.0 − 0) = 0.3.
    assert carrot_command(Pose2D(0, 0, 0), (0.5, 0.0), Pose2D(0.5, 0.0, 1.0), p) == pytest.approx((0.25, 0.0, 0.3))
    # Backwards: walk_vel 0.2 → vx −0.2 clamped to min_vel_x −0.1; ω clamped to 0.6 (0.3 · 3.0 = 0.9).
    vx, vy, om = carrot_command(Pose2D(0, 0, 0), (-1.0, 0.0), Pose2D(-0.4, 0.0, 3.0), p)
    assert (vx, vy, om) == pytest.approx((-0.1, 0.0, 0.6), abs=1e-12)
    # Rotated robot: heading π/2 (facing world +y), carrot at world +x = straight to its right.
    vx, vy, om = carrot_command(Pose2D(0, 0, math.pi / 2), (1.0, 0.0), Pose2D(0.0, -0.1, math.pi / 2), p)
    assert (vx, vy, om) == pytest.approx((0.0, -0.05, 0.0), abs=1e-12)  # walk_vel = 0.1 · 0.5
    assert smooth((0.0, 0.0, 0.0), (0.2, 0.1, 0.4), 0.5) == pytest.approx((0.1, 0.05, 0.2))


def test_velocity_controller_uses_the_walk_engine_rule():
    env = FootstepEnv()
    ctrl = VelocityController.from_env(env, {"smoothing": 1.0})
    obs, info = env.reset(seed=0, options={"scene": Scene(Pose2D(2.0, 0.0, 0.0))})
    ctrl.reset(env.scene, info, seed=0)
    action = ctrl(obs, info)
    vx = min(2.0 * ctrl.params.translation_slow_down_factor, ctrl.params.max_vel_x)
    expected = ctrl.engine.footsteps_from_velocity(vx, 0.0, 0.0).as_array() / np.tile(LIMITS.as_array(), 2)
    assert action == pytest.approx(expected)
    assert expected[0] == pytest.approx(vx / (2 * env.walk.freq) / LIMITS.x, rel=1e-2)


def _rect_hits_circle_sampled(pose: Pose2D, half_l, half_w, o: Obstacle) -> bool:
    for u in np.linspace(-half_l, half_l, 15):
        for v in np.linspace(-half_w, half_w, 11):
            x, y = pose.transform_point(u, v)
            if (x - o.x) ** 2 + (y - o.y) ** 2 < o.r**2:
                return True
    return False


UPPER_BODY = (0.238, 0.283, 0.045)  # Wolfgang's box over torso, head and arms (the 2D collision_model=upper_body)


@pytest.mark.parametrize("upper_body", [None, UPPER_BODY], ids=["torso", "upper_body"])
@pytest.mark.parametrize("seed", [3, 8])
def test_footstep_plan_within_limits_and_clear_of_obstacles(seed, upper_body):
    scene = sample_scenes(SceneSampler(obstacles=True), 1, seed=seed)[0]
    planner = FootstepPlanner(
        GEOMETRY,
        TRUNK,
        scene,
        FootstepParams(expansion_budget=None, time_budget_s=2.0, epsilons=(2.0,)),
        upper_body=upper_body,
    )
    feet = GEOMETRY.initial_feet()
    plan = planner.plan(feet.left, feet.right)
    assert plan.status == "ok", plan.status
    assert [s for s, _ in plan.steps] == [Side.RIGHT, Side.LEFT] * (len(plan.steps) // 2)
    state = feet
    for (side, step), (side2, pose) in zip(plan.steps, plan.poses):
        assert side == side2
        assert (
            abs(step.x) <= LIMITS.x + 1e-9 and abs(step.y) <= LIMITS.y + 1e-9 and abs(step.theta) <= LIMITS.theta + 1e-9
        )
        rel, done, interfered = GEOMETRY.landing(side, step)
        assert not interfered and done == step
        start = state.foot(side)
        state = state.with_foot(side, state.foot(side.other).compose(rel))
        landed = state.foot(side)
        assert landed == pytest.approx(pose)
        mid = Pose2D(0.5 * (start.x + landed.x), 0.5 * (start.y + landed.y), landed.theta)
        for o in scene.all_obstacles:
            assert not _rect_hits_circle_sampled(landed, 0.077, 0.053, o)
            assert not _rect_hits_circle_sampled(state.nav_pose, 0.075, 0.075, o)
            assert not _rect_hits_circle_sampled(mid, 0.077, 0.053, o)
        if upper_body is not None:  # the upper body's box, against the obstacles (the ball stays below the arms)
            length, width, offset = upper_body
            centre = state.nav_pose.compose(Pose2D(offset, 0.0, 0.0))
            assert not any(_rect_hits_circle_sampled(centre, 0.5 * length, 0.5 * width, o) for o in scene.obstacles)
    final = state.nav_pose
    assert final.distance_to(scene.goal) < 1e-6 and abs(final.theta - scene.goal.theta) < 1e-6


def _capability_csv(path, unstable):
    """A same-step capability map over {-1, -0.5, 0, 0.5, 1}^3; cells where ``unstable(x, y, θ)`` fell."""
    lines = ["right_x,right_y,right_theta,left_x,left_y,left_theta,fall_rate,n,falls"]
    grid = (-1.0, -0.5, 0.0, 0.5, 1.0)
    for x in grid:
        for y in grid:
            for t in grid:
                rate = 1.0 if unstable(x, y, t) else 0.0
                lines.append(f"{x},{y},{t},{x},{y},{t},{rate},2,{int(2 * rate)}")
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_footstep_planner_keeps_to_the_stable_region(tmp_path):
    """With a map where every full forward step (x = 1) falls, the transition set has no footstep
    of x = limits.x on either side; with the threshold at 1 every footstep is back; bad files are named."""
    scene = Scene(goal=Pose2D(1.0, 0.0, 0.0))
    csv = _capability_csv(tmp_path / "map.csv", lambda x, y, t: x == 1.0)
    full = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams())
    stable = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams(stable_region=csv))
    loose = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams(stable_region=csv, stable_max_fall_rate=1.0))
    for side in (Side.LEFT, Side.RIGHT):
        xs = [step.x for step in stable.transitions[side][0]]
        assert xs and max(xs) == pytest.approx(0.5 * LIMITS.x)  # x_fracs (-0.5, 0, 0.5, 1): the 1 is gone
        assert len(stable.transitions[side][0]) == len(full.transitions[side][0]) - 9  # 3 y × 3 θ at x = 1
        assert len(loose.transitions[side][0]) == len(full.transitions[side][0])
    feet = GEOMETRY.initial_feet()
    plan = stable.plan(feet.left, feet.right)
    # every planned footstep (the goal shot too) lies nearer to a stable cell than to an x = 1 cell
    assert plan.status == "ok" and all(step.x / LIMITS.x < 0.75 for _, step in plan.steps)
    everything = _capability_csv(tmp_path / "all.csv", lambda x, y, t: True)
    with pytest.raises(ValueError, match="no footstep of the transition set is stable"):
        FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams(stable_region=everything))
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="not a footsim-capability CSV"):
        FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams(stable_region=str(tmp_path / "bad.csv")))
    with pytest.raises(ValueError, match="stable_max_fall_rate"):
        FootstepParams(stable_max_fall_rate=2.0)


def test_feet_from_nav_inverts_the_double_step():
    feet = GEOMETRY.initial_feet(Pose2D(0.3, -0.2, 0.4))
    step = DoubleStep(Footstep(0.1, -0.05, -0.3), Footstep(0.12, 0.02, 0.1))
    _, after, executed, _ = GEOMETRY.execute(feet, step)
    left, right = feet_from_nav(after.nav_pose, GEOMETRY, executed.second)
    assert left == pytest.approx(after.left) and right == pytest.approx(after.right)


SIMPLE_SCENES = [
    Scene(Pose2D(0.6, 0.2, 0.3)),
    Scene(Pose2D(-0.4, 0.5, 2.0)),
    Scene(Pose2D(1.2, 0.0, 0.0), (Obstacle(0.6, 0.3, 0.12),)),
]


@pytest.mark.parametrize("name", ["velocity", "footstep"])
def test_baselines_reach_simple_goals(name):
    env = FootstepEnv(task="nav_obstacles")
    controller = make_controller(env, {"name": name})
    records = evaluate(env, controller, SIMPLE_SCENES, progress=False)
    assert [r["outcome"] for r in records] == ["success"] * len(SIMPLE_SCENES), records


def test_footstep_baseline_plans_against_the_envs_trunk_box():
    """With the 2D collision_model=upper_body the baseline plans against the upper body's box too:
    on scenes where the plans against the torso box touch an obstacle with it, its own do not."""
    env = FootstepEnv(backend={"name": "pymunk", "collision_model": "upper_body"}, task="nav_obstacles")
    own = make_controller(env, {"name": "footstep"})
    assert own.upper_body == pytest.approx(UPPER_BODY)
    torso_only = make_controller(FootstepEnv(task="nav_obstacles"), {"name": "footstep"})
    scenes = sample_scenes(SceneSampler(obstacles=True), 40, seed=5)
    torso_planned = [r["outcome"] for r in evaluate(env, torso_only, scenes, progress=False)]
    touched = [k for k, outcome in enumerate(torso_planned) if outcome == "collision"]
    assert len(touched) >= 5, "too few scenes tell the two boxes apart"
    for k in touched:
        obs, info = env.reset(seed=k, options={"scene": scenes[k]})
        own.reset(scenes[k], info, seed=k)
        while True:  # a step the planner chose (not its stand-still fallback once it gave up) is clear
            obs, _, terminated, truncated, info = env.step(own(obs, info))
            assert info["outcome"] != "collision" or own.status not in ("ok", "partial"), (k, own.status)
            if terminated or truncated:
                break


def _ring_scene() -> Scene:
    goal = Pose2D(1.5, 0.0, 0.0)
    ring = tuple(
        Obstacle(goal.x + 0.5 * math.cos(a), goal.y + 0.5 * math.sin(a), 0.14)
        for a in np.linspace(0, 2 * math.pi, 14, endpoint=False)
    )
    return Scene(goal, ring)


class _TickingClock:
    """Stands in for ``time`` in the planner: each reading advances 1 ms, so the deadline logic
    is tested by its own clock, not by how busy the machine is."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self) -> float:
        self.now += 1e-3
        return self.now


def test_search_stops_at_its_time_budget(monkeypatch):
    import footsim.planners.footstep as footstep

    budget = 0.02
    planner = FootstepPlanner(
        GEOMETRY, TRUNK, Scene(Pose2D(3.0, 1.0, 2.0), ()), FootstepParams(expansion_budget=None, time_budget_s=budget)
    )
    feet = GEOMETRY.initial_feet()
    planner.plan(feet.left, feet.right)  # warm-up on the real clock
    monkeypatch.setattr(footstep, "time", _TickingClock())
    plan = planner.plan(feet.left, feet.right)
    assert budget - 1e-9 <= plan.time_s <= budget + 3e-3  # stops within a few clock readings of it
    assert 0 < plan.expanded < budget / 1e-3  # at most one expansion per reading


class _SlowClock:
    """A clock on which every reading is a second later: any wall-clock budget is over at once."""

    def __init__(self):
        self.now = 0.0

    def perf_counter(self):
        self.now += 1.0
        return self.now


def test_expansion_budget_makes_plans_independent_of_the_clock(monkeypatch):
    """With expansion_budget the search ends after exactly that many expansions whatever the clock
    says (the same plan under a normal and an absurdly slow clock), and a larger budget, which
    continues the same deterministic search, never returns a costlier plan."""
    import footsim.planners.footstep as footstep

    scene = sample_scenes(SceneSampler(obstacles=True), 1, seed=8)[0]
    feet = GEOMETRY.initial_feet()

    def plan(budget):
        return FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams(expansion_budget=budget)).plan(
            feet.left, feet.right
        )

    small, large = plan(150), plan(1500)
    assert small.expanded == 150 and large.expanded <= 1500
    assert small.status == large.status == "ok"
    assert large.cost <= small.cost + 1e-12
    monkeypatch.setattr(footstep, "time", _SlowClock())
    again = plan(150)
    assert again.expanded == 150 and again.steps == small.steps and again.cost == small.cost
    with pytest.raises(ValueError, match="expansion_budget"):
        FootstepParams(expansion_budget=0)


def test_unreachable_and_blocked_goals_fail_without_searching(monkeypatch):
    import footsim.planners.footstep as footstep

    monkeypatch.setattr(footstep, "time", _TickingClock())
    params = FootstepParams(expansion_budget=None, time_budget_s=0.05)
    feet = GEOMETRY.initial_feet()
    inside = Scene(Pose2D(1.0, 0.0, 0.0), (Obstacle(1.05, 0.0, 0.2),))
    for scene, status in ((_ring_scene(), "unreachable"), (inside, "goal_in_collision")):
        planner = FootstepPlanner(GEOMETRY, TRUNK, scene, params)
        plan = planner.plan(feet.left, feet.right)
        assert plan.status == status and not plan.ok
        assert plan.expanded == 0 and plan.time_s <= 2e-3  # decided before any search
    # In the env: the controller steps in place, the episode times out, the reason is recorded.
    env = FootstepEnv(task={"name": "nav_obstacles", "max_steps": 5})
    for name in ("footstep", "velocity"):
        ctrl = make_controller(env, {"name": name})
        record = evaluate(env, ctrl, [_ring_scene()], progress=False)[0]
        assert record["outcome"] == "timeout"
        assert record["planner_status"] == ("unreachable" if name == "footstep" else "no_path")


def test_footstep_planner_respects_budget_on_hard_scenes(monkeypatch):
    import footsim.planners.footstep as footstep

    budget = 0.02
    scenes = sample_scenes(SceneSampler(obstacles=True), 6, seed=21)
    feet = GEOMETRY.initial_feet()
    monkeypatch.setattr(footstep, "time", _TickingClock())  # the deadline on its own clock, not the machine's load
    for scene in scenes:
        planner = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams(expansion_budget=None, time_budget_s=budget))
        plan = planner.plan(feet.left, feet.right)
        assert plan.time_s <= budget + 3e-3  # within a few clock readings of the budget
        assert plan.status in ("ok", "partial", "unreachable", "goal_in_collision")


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="unknown key"):
        make_controller(FootstepEnv(), {"name": "footstep", "budget": 1})
    with pytest.raises(ValueError, match="global_planner"):
        VelocityParams(global_planner="dijkstra")
    with pytest.raises(ValueError, match="unknown baseline"):
        make_controller(FootstepEnv(), {"name": "rrt"})
