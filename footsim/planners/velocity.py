"""The velocity baseline (thesis chapter 4): global grid planner + carrot local planner.

Every ``replan_period`` double steps an any-angle path (Lazy Theta* by default; Theta* or A*)
is planned on the inflated costmap of the scene's obstacles from the pose the robot *believes*
it has.  Every double step the carrot local planner (FACTS.md "Velocity baseline") turns the
path into a velocity order (vx, vy, ω) in the robot frame, smoothed with an exponential filter,
and the walk engine's velocity-order rule (``QuinticWalk.footsteps_from_velocity``) turns the
order into the double step the env executes.

Option ``behind_ball`` (thesis 4.4): first navigate to a pose ``behind_distance`` behind the goal
with the goal's heading, then to the goal, so the last approach is a forward walk onto the ball.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.planners.grid import Costmap, densify, plan_path
from footsim.scene import Scene
from footsim.walk.engine import QuinticWalk
from footsim.walk.footsteps import FootstepGeometry, StepLimits


@dataclass(frozen=True)
class VelocityParams:
    """Costmap, global planner and carrot parameters (conf/controller/velocity.yaml documents them)."""

    global_planner: str = "lazy_theta_star"  # lazy_theta_star | theta_star | astar
    resolution: float = 0.05  # costmap cell [m]; also the spacing of the path points
    footprint_radius: float = 0.15  # robot footprint as a circle [m]
    inflation: float = 0.08  # extra clearance kept from obstacles [m]
    replan_period: int = 5  # double steps between global plans
    carrot_distance: int = 5  # path points ahead of the closest one
    max_vel_x: float = 0.45  # [m/s]
    min_vel_x: float = -0.1  # [m/s]
    max_vel_y: float = 0.2  # [m/s]
    max_rotation_vel: float = 1.0  # [rad/s]
    orient_to_goal_distance: float = 1.0  # [m] beyond: face the goal position; within: its heading
    translation_slow_down_factor: float = 1.0  # walk_vel = min(distance · this, max_vel_x)
    rotation_slow_down_factor: float = 1.0  # ω = clamp(this · heading error)
    smoothing: float = 1.0  # exponential filter: cmd = smoothing · new + (1 - smoothing) · previous
    heading_target: str = "goal"  # far from the goal, face the goal position (FACTS) or the carrot
    behind_ball: bool = False  # thesis 4.4: approach via a pose behind the goal
    behind_distance: float = 0.3  # [m] behind the goal pose
    behind_tolerance: float = 0.08  # [m] switch to the goal once this close to the pre-goal pose
    behind_angle_tolerance: float = 0.35  # [rad] … and this well aligned

    def __post_init__(self) -> None:
        if self.global_planner not in ("lazy_theta_star", "theta_star", "astar"):
            raise ValueError(
                f"controller.global_planner must be lazy_theta_star, theta_star or astar, got {self.global_planner!r}"
            )
        if self.heading_target not in ("goal", "carrot"):
            raise ValueError(f"controller.heading_target must be goal or carrot, got {self.heading_target!r}")
        if int(self.replan_period) < 1 or int(self.carrot_distance) < 1:
            raise ValueError("controller.replan_period and controller.carrot_distance must be >= 1")
        if not 0.0 < self.smoothing <= 1.0:
            raise ValueError(f"controller.smoothing must be in (0, 1], got {self.smoothing!r}")
        for key in ("resolution", "max_vel_x", "max_vel_y", "max_rotation_vel"):
            if not getattr(self, key) > 0:
                raise ValueError(f"controller.{key} must be > 0, got {getattr(self, key)!r}")
        if self.min_vel_x > 0:
            raise ValueError(f"controller.min_vel_x must be <= 0, got {self.min_vel_x!r}")

    @classmethod
    def from_mapping(cls, mapping) -> VelocityParams:
        data = {k: v for k, v in dict(mapping).items() if k != "name"}
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"controller (velocity): unknown key(s) {unknown}; valid: {sorted(known)}")
        return cls(**data)


def carrot_command(
    pose: Pose2D, carrot: tuple[float, float], goal: Pose2D, p: VelocityParams
) -> tuple[float, float, float]:
    """The carrot local planner's raw order (vx, vy, ω) in the robot frame (before smoothing).

    walk_vel = min(distance · translation_slow_down_factor, max_vel_x) with distance to the
    goal; vx, vy point at the carrot (holonomic), scaled together so that vx ∈ [min_vel_x,
    max_vel_x] and |vy| ≤ max_vel_y (the direction is kept); ω = clamp(rotation_slow_down_factor
    · heading error, ±max_rotation_vel) with the error to the goal position's bearing (or the
    carrot's) beyond ``orient_to_goal_distance``, to the goal's heading within it.
    """
    distance = math.hypot(goal.x - pose.x, goal.y - pose.y)
    walk_vel = min(distance * p.translation_slow_down_factor, p.max_vel_x)
    bearing = math.atan2(carrot[1] - pose.y, carrot[0] - pose.x)
    rel = wrap_angle(bearing - pose.theta)
    vx, vy = math.cos(rel) * walk_vel, math.sin(rel) * walk_vel
    scale = 1.0
    if vx > p.max_vel_x:
        scale = min(scale, p.max_vel_x / vx)
    if vx < p.min_vel_x:
        scale = min(scale, p.min_vel_x / vx)
    if abs(vy) > p.max_vel_y:
        scale = min(scale, p.max_vel_y / abs(vy))
    vx, vy = vx * scale, vy * scale
    if distance > p.orient_to_goal_distance:
        target = carrot if p.heading_target == "carrot" else (goal.x, goal.y)
        error = wrap_angle(math.atan2(target[1] - pose.y, target[0] - pose.x) - pose.theta)
    else:
        error = wrap_angle(goal.theta - pose.theta)
    omega = min(max(p.rotation_slow_down_factor * error, -p.max_rotation_vel), p.max_rotation_vel)
    return vx, vy, omega


def smooth(
    previous: tuple[float, float, float], new: tuple[float, float, float], alpha: float
) -> tuple[float, float, float]:
    """Exponential filter: ``alpha · new + (1 − alpha) · previous`` per component."""
    return (
        alpha * new[0] + (1.0 - alpha) * previous[0],
        alpha * new[1] + (1.0 - alpha) * previous[1],
        alpha * new[2] + (1.0 - alpha) * previous[2],
    )


class VelocityController:
    """The velocity baseline as a ``footsim.rl.evaluate.Controller``.

    It observes only ``info["pose_estimate"]`` (the believed pose), the scene's obstacles and goal.
    ``status`` names the last global plan's outcome (``ok``, ``ok_footprint_only``,
    ``no_path``); with no path (goal unreachable or inside an obstacle) it steps in place until
    the next replan, so a persistent failure ends the episode as a timeout.
    """

    kind = "velocity"

    def __init__(self, limits: StepLimits, walk, geometry: FootstepGeometry, params: VelocityParams = VelocityParams()):
        self.params = params
        self.limits = limits
        self.engine = QuinticWalk(walk, geometry)  # only its velocity-order rule is used
        self.plan_times: list[float] = []
        self.reset_state()

    @classmethod
    def from_env(cls, env, params: VelocityParams | dict | None = None) -> VelocityController:
        if params is None:
            params = VelocityParams()
        elif not isinstance(params, VelocityParams):
            params = VelocityParams.from_mapping(params)
        geometry = FootstepGeometry(env.limits, env.robot.foot_length, env.robot.foot_width, env.walk.foot_distance)
        return cls(env.limits, env.walk, geometry, params)

    def reset_state(self) -> None:
        self.scene: Scene | None = None
        self.costmap: Costmap | None = None
        self.path: np.ndarray | None = None
        self.path_index = 0
        self.command = (0.0, 0.0, 0.0)
        self.steps = 0
        self.status = "idle"
        self.targets: list[Pose2D] = []
        self.plan_times = []
        self.paths: list[np.ndarray] = []

    # -- Controller protocol ----------------------------------------------------------------
    def reset(self, scene: Scene, info: dict, seed: int) -> None:  # deterministic: the seed is unused
        self.reset_state()
        self.scene = scene
        p = self.params
        goal = scene.goal
        self.targets = [goal]
        if p.behind_ball:
            self.targets.insert(0, goal.compose(Pose2D(-p.behind_distance, 0.0, 0.0)))
        pose = Pose2D(*info["pose_estimate"])
        pts = [(pose.x, pose.y)] + [(t.x, t.y) for t in self.targets]
        self.costmap = Costmap.from_obstacles(scene.all_obstacles, pts, p.resolution, p.footprint_radius + p.inflation)
        self.costmap_tight = Costmap(self.costmap.origin, p.resolution, self.costmap.clearance, p.footprint_radius)
        self._replan(pose)

    def __call__(self, obs, info: dict) -> np.ndarray:
        pose = Pose2D(*info["pose_estimate"])
        p = self.params
        if len(self.targets) > 1:  # behind-the-ball: switch to the goal at the pre-goal pose
            pre = self.targets[0]
            if (
                pose.distance_to(pre) < p.behind_tolerance
                and abs(wrap_angle(pre.theta - pose.theta)) < p.behind_angle_tolerance
            ):
                self.targets.pop(0)
                self._replan(pose)
        if self.steps > 0 and self.steps % int(p.replan_period) == 0:
            self._replan(pose)
        self.steps += 1
        if self.status == "no_path":  # navigation failed (as nav2 aborts the goal): step in place
            self.command = (0.0, 0.0, 0.0)
            return np.zeros(6)
        raw = carrot_command(pose, self._carrot(pose), self.targets[0], p)
        self.command = smooth(self.command, raw, p.smoothing)
        double_step = self.engine.footsteps_from_velocity(*self.command)
        return double_step.as_array() / np.tile(self.limits.as_array(), 2)

    def episode_info(self) -> dict:
        times = np.array(self.plan_times) * 1e3
        return {
            "planner_status": self.status,
            "plans": len(times),
            "plan_ms_median": float(np.median(times)) if len(times) else math.nan,
        }

    # -- internals ----------------------------------------------------------------------------
    def _replan(self, pose: Pose2D) -> None:
        assert self.costmap is not None, "reset() builds the costmap before the first plan"
        target = self.targets[0]
        start = time.perf_counter()
        path = plan_path(self.costmap, (pose.x, pose.y), (target.x, target.y), self.params.global_planner)
        status = "ok"
        if path is None:  # too tight for the inflated footprint: try the bare footprint
            path = plan_path(self.costmap_tight, (pose.x, pose.y), (target.x, target.y), self.params.global_planner)
            status = "ok_footprint_only"
        self.plan_times.append(time.perf_counter() - start)
        if path is None:
            self.status = "no_path"
            self.path = np.array([[pose.x, pose.y]])
        else:
            self.status = status
            self.path = densify(path.points, self.params.resolution)
        self.paths.append(self.path)
        self.path_index = 0

    def _carrot(self, pose: Pose2D) -> tuple[float, float]:
        """The path point ``carrot_distance`` points past the closest one (never moving backwards)."""
        pts = self.path
        assert pts is not None, "reset() plans a path before the first command"
        d = np.hypot(pts[self.path_index :, 0] - pose.x, pts[self.path_index :, 1] - pose.y)
        self.path_index += int(np.argmin(d))
        k = min(self.path_index + int(self.params.carrot_distance), len(pts) - 1)
        return float(pts[k, 0]), float(pts[k, 1])
