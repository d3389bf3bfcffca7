"""The 2D geometric backend (thesis 5.1.1), with pymunk for collisions.

Feet land exactly where the planar footstep geometry puts them (including foot–foot
interference); the feet and the trunk's footprint are pymunk polygons, obstacles static circles,
and a collision is any overlap found by pymunk shape queries — at both put-downs and at each
flying foot's mid-swing pose.  The navigation pose is the mean of the two feet.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from footsim.backends.base import Backend, RenderOverlay, StepResult
from footsim.geometry import Pose2D, mean_pose
from footsim.robots.spec import RobotSpec
from footsim.tasks.scenes import Scene
from footsim.walk.footsteps import DoubleStep, FeetState, FootstepGeometry, Side
from footsim.walk.params import WalkParams


def _box(body: pymunk.Body, length: float, width: float) -> pymunk.Poly:
    hl, hw = 0.5 * length, 0.5 * width
    return pymunk.Poly(body, [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)])


class Pymunk2DBackend(Backend):
    name = "pymunk"
    kind = "2d"
    capabilities = frozenset({"footstep_noise_x", "footstep_noise_y", "footstep_noise_theta", "walk_freq_scale"})
    collision_ends_episode = True

    def __init__(self, robot: RobotSpec, walk: WalkParams, collision_ends_episode: bool = True,
                 execution_model: str | None = None, execution_noise: bool = True, execution_falls: bool = False,
                 **unused):
        if unused:
            raise ValueError(f"backend pymunk: unknown option(s) {sorted(unused)}")
        self.execution_model = None
        if execution_model:  # commanded -> executed displacement fitted on a 3D backend (footsim-calibrate)
            from footsim.calibrate import ExecutionModel

            self.execution_model = ExecutionModel.load(execution_model, noise=bool(execution_noise))
        self.execution_falls = bool(execution_falls)
        self.robot = robot
        self.walk = walk
        self.collision_ends_episode = bool(collision_ends_episode)
        self.geometry = FootstepGeometry(
            robot.step_limits, robot.foot_length, robot.foot_width, walk.foot_distance
        )
        # Circumradii for the broad phase: a shape farther than this from every obstacle can't touch one.
        self._foot_radius = math.hypot(0.5 * robot.foot_length, 0.5 * robot.foot_width)
        self._trunk_radius = math.hypot(*(0.5 * v for v in robot.torso_footprint))
        self.space: pymunk.Space | None = None
        self.feet: FeetState | None = None
        self.history: list[tuple[Side, Pose2D]] = []
        self.nav_history: list[Pose2D] = []
        self.scene: Scene | None = None
        self._noise_sigma = (0.0, 0.0, 0.0)
        self._duration = walk.double_step_duration
        self._rng = np.random.default_rng(0)

    def apply_randomization(self, values: dict[str, float]) -> None:
        sx, sy, st = self._noise_sigma
        sx = abs(values.get("footstep_noise_x", sx))
        sy = abs(values.get("footstep_noise_y", sy))
        st = abs(values.get("footstep_noise_theta", st))
        self._noise_sigma = (sx, sy, st)
        if "walk_freq_scale" in values:
            scale = values["walk_freq_scale"]
            if scale <= 0:
                raise ValueError(f"walk_freq_scale must be > 0, got {scale}")
            self._duration = self.walk.double_step_duration / scale

    def _perturb(self, pose: Pose2D) -> Pose2D:
        """A landed foot displaced by execution noise, in its own frame."""
        ex, ey, et = self._rng.normal(0.0, 1.0, 3) * self._noise_sigma
        return pose.compose(Pose2D(float(ex), float(ey), float(et)))

    # -- episode --------------------------------------------------------------------------
    def reset(self, scene: Scene, rng: np.random.Generator) -> Pose2D:
        self.scene = scene
        self._rng = rng
        self.space = pymunk.Space()
        for obstacle in scene.all_obstacles:
            self.space.add(pymunk.Circle(self.space.static_body, obstacle.r, (obstacle.x, obstacle.y)))
        self._probe_body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self._foot_shape = _box(self._probe_body, self.robot.foot_length, self.robot.foot_width)
        self._trunk_body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self._trunk_shape = _box(self._trunk_body, *self.robot.torso_footprint)
        robot_only = pymunk.ShapeFilter(group=1)  # the robot's own shapes never collide with each other
        self._foot_shape.filter = robot_only
        self._trunk_shape.filter = robot_only
        self.space.add(self._probe_body, self._foot_shape, self._trunk_body, self._trunk_shape)
        self._obstacles = [(o.x, o.y, o.r) for o in scene.all_obstacles]
        self.feet = self.geometry.initial_feet()
        self.history = [(Side.LEFT, self.feet.left), (Side.RIGHT, self.feet.right)]
        self.nav_history = [self.feet.nav_pose]
        return self.feet.nav_pose

    def execute(self, double_step: DoubleStep) -> StepResult:
        if self.feet is None:
            raise RuntimeError("backend pymunk: execute() before reset()")
        before = self.feet
        noisy = any(self._noise_sigma)
        after_first, after_second, executed, n_interfered = self.geometry.execute(
            before, double_step, self._perturb if noisy else None)
        collided = False
        if self.scene.all_obstacles:
            collided = (
                self._swing_collides(before, after_first, Side.RIGHT)
                or self._swing_collides(after_first, after_second, Side.LEFT)
            )
        fell = False
        if self.execution_model is not None:
            after_first, after_second, fell = self._apply_execution_model(before, after_first, after_second, double_step)
        self.feet = after_second
        self.history += [(Side.RIGHT, after_first.right), (Side.LEFT, after_second.left)]
        self.nav_history.append(after_second.nav_pose)
        return StepResult(
            pose=after_second.nav_pose,
            duration_s=self._duration,
            feet=after_second,
            executed=executed,
            fell=fell,
            collided=collided,
            info={"foot_interference": n_interfered},
        )

    def _apply_execution_model(self, before: FeetState, after_first: FeetState, after_second: FeetState,
                               double_step: DoubleStep) -> tuple[FeetState, FeetState, bool]:
        """Move the feet so the navigation frame makes the model's displacement instead of the
        geometry's: both feet shift rigidly with the navigation frame (half the correction at the
        half step); the residual noise and the fall draw come from the episode rng."""
        model = self.execution_model
        start, predicted = before.nav_pose, after_second.nav_pose
        dx, dy, dtheta = model.predict(start.relative(predicted), self._rng)
        correction = predicted.relative(start.compose(Pose2D(float(dx), float(dy), float(dtheta))))

        def moved(feet: FeetState, fraction: float) -> FeetState:
            nav = feet.nav_pose
            target = nav.compose(Pose2D(fraction * correction.x, fraction * correction.y, fraction * correction.theta))
            return FeetState(target.compose(nav.relative(feet.left)), target.compose(nav.relative(feet.right)))

        fell = False
        if self.execution_falls and model.fall is not None:
            action = double_step.as_array() / np.tile(self.robot.step_limits.as_array(), 2)
            fell = bool(self._rng.random() < model.fall_probability(action))
        return moved(after_first, 0.5), moved(after_second, 1.0), fell

    # -- collisions -----------------------------------------------------------------------
    def _swing_collides(self, start: FeetState, end: FeetState, flying: Side) -> bool:
        """Flying foot at mid-swing and at put-down, and the trunk at put-down."""
        mid = mean_pose(start.foot(flying), end.foot(flying))
        return (
            self._hits(self._probe_body, self._foot_shape, self._foot_radius, mid)
            or self._hits(self._probe_body, self._foot_shape, self._foot_radius, end.foot(flying))
            or self._hits(self._trunk_body, self._trunk_shape, self._trunk_radius, end.nav_pose)
        )

    def _hits(self, body: pymunk.Body, shape: pymunk.Shape, radius: float, pose: Pose2D) -> bool:
        px, py = pose.x, pose.y
        if all((ox - px) ** 2 + (oy - py) ** 2 > (r + radius) ** 2 for ox, oy, r in self._obstacles):
            return False  # broad phase: no obstacle within the shape's circumradius
        body.position = (px, py)
        body.angle = pose.theta
        self.space.reindex_shapes_for_body(body)
        return any(hit.shape.body is self.space.static_body for hit in self.space.shape_query(shape))

    # -- rendering ------------------------------------------------------------------------
    def render(self, overlay: RenderOverlay | None = None) -> np.ndarray:
        from footsim.render2d import draw_scene

        return draw_scene(self.scene, self.history, self.nav_history, self.robot, overlay)

    def close(self) -> None:
        self.space = None
