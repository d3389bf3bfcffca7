"""The 2D geometric backend (thesis 5.1.1): :class:`Pymunk2DBackend`.

Feet land exactly where the planar footstep geometry puts them (including foot–foot
interference); the feet and the trunk's footprint are rectangles, obstacles static circles, and
a collision is any overlap of a rectangle with a circle — at both put-downs and at each flying
foot's mid-swing pose.  The overlap test is closed-form (:func:`box_hits_circles`: the distance
from the circle's centre to the rectangle is at most the radius), which is what a pymunk shape
query of the same polygon against the same circles answers (``tests/test_backend_pymunk2d.py``
checks the two against each other); the six tests of a double step run in one compiled call
(:func:`footsim.backends.pymunk2d.collision.double_step_collides`; without execution noise the
placement and the navigation pose join them in
:func:`footsim.backends.pymunk2d.collision.execute_double_step`).
:meth:`Pymunk2DBackend.space` builds that pymunk space on demand.  The navigation pose is the mean
of the two feet.

``collision_model="nav_distance"`` is the thesis's own 2D check instead (5.1.1: "the distance to
the closest obstacle ... below a defined threshold"): the navigation pose at each put-down closer
than ``collision_distance`` to an obstacle's or the ball's edge.  The thesis gives no threshold;
the default 0.1 m is about the trunk's half width.  Neither check contains the other: it ignores the
feet (they reach 0.14 m sideways and 0.08 m forward of the navigation pose) but keeps a 0.1 m circle
clear where the trunk's footprint reaches 0.075-0.106 m.

Calibrated 2D: ``execution_model`` (``footsim-calibrate``) moves the landing to where a 3D backend
puts it; ``fall_model`` (a ``footsim-capability`` map) makes a commanded double step fall with the
rate of the map's nearest cell, drawn from the episode rng.  A fall is reported as the 3D driver
reports one (``max_tilt`` = π/2, the robot lying down); the task's fall term ends the episode.
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pymunk

from footsim.backends.base import Backend, RenderOverlay, StepResult
from footsim.backends.pymunk2d import collision
from footsim.backends.pymunk2d.render import draw_scene
from footsim.calibration.execution_model import CapabilityFallModel, ExecutionModel
from footsim.geometry import Pose2D, mean_pose
from footsim.robots.spec import RobotSpec
from footsim.scene import Scene, circle_array
from footsim.walk.footsteps import DoubleStep, FeetState, FootstepGeometry, Side, placed_double_step
from footsim.walk.params import WalkParams

# pymunk categories of the obstacles, which reach the upper body, and of the ball, which does not
_TALL, _LOW = 0b10, 0b01


def _box(body: pymunk.Body, length: float, width: float, offset: float = 0.0) -> pymunk.Poly:
    """A ``length`` x ``width`` rectangle on ``body``, its centre ``offset`` ahead of the body's origin."""
    hl, hw = 0.5 * length, 0.5 * width
    return pymunk.Poly(body, [(offset - hl, -hw), (offset + hl, -hw), (offset + hl, hw), (offset - hl, hw)])


def box_hits_circles(x: float, y: float, theta: float, half_length: float, half_width: float, circles) -> bool:
    """Does the rectangle ``2·half_length × 2·half_width`` centred at ``(x, y)``, turned by
    ``theta``, overlap (or touch) any circle ``(cx, cy, r)`` of ``circles``?

    Closed form of a pymunk shape query of that polygon against static circles: the closest
    point of the rectangle to the circle's centre lies within ``r`` (centre inside: distance 0).
    The compiled :func:`footsim.backends.pymunk2d.collision.box_hits_circles` on any sequence of ``(x, y, r)``
    (the backend calls the kernels directly, with the episode's circles as an array).
    """
    return collision.box_hits_circles(
        float(x), float(y), float(theta), float(half_length), float(half_width), circle_array(circles)
    )


# ``execute`` builds StepResult positionally (a hot path): make sure the field order is the one used.
# Fields after ``info`` (the 3D tilt) keep their defaults here.
assert [f.name for f in fields(StepResult)][:7] == [
    "pose",
    "duration_s",
    "feet",
    "executed",
    "collided",
    "sim_error",
    "info",
], "StepResult fields changed"


class Pymunk2DBackend(Backend):
    name = "pymunk"
    kind = "2d"
    capabilities = frozenset({"footstep_noise_x", "footstep_noise_y", "footstep_noise_theta", "walk_freq_scale"})
    #: ``reset`` may be given an rng that is only created when first drawn from (the env's
    #: ``DeferredGenerator``): this backend draws only with execution noise, an execution model or
    #: a fall model.
    deferred_rng = True

    COLLISION_MODELS = ("footprint", "upper_body", "nav_distance")

    def __init__(
        self,
        robot: RobotSpec,
        walk: WalkParams,
        execution_model: str | None = None,
        execution_noise: bool = True,
        execution_falls: bool = False,
        fall_model: str | None = None,
        collision_model: str = "footprint",
        collision_distance: float = 0.1,
        **unused,
    ):
        if unused:
            raise ValueError(f"backend pymunk: unknown option(s) {sorted(unused)}")
        if collision_model not in self.COLLISION_MODELS:
            raise ValueError(
                f"backend.collision_model must be one of {list(self.COLLISION_MODELS)}, got {collision_model!r}"
            )
        collision_distance = float(collision_distance)
        if not collision_distance >= 0.0:
            raise ValueError(f"backend.collision_distance must be >= 0, got {collision_distance!r}")
        self.collision_model = collision_model
        self.collision_distance = collision_distance
        self.execution_model = None
        if execution_model:  # commanded -> executed displacement fitted on a 3D backend (footsim-calibrate)
            self.execution_model = ExecutionModel.load(execution_model, noise=bool(execution_noise))
        self.execution_falls = bool(execution_falls)
        self.fall_model = None
        if fall_model:  # the capability map of a 3D backend (footsim-capability): falls per commanded double step
            if self.execution_falls:
                raise ValueError(
                    "backend pymunk: backend.fall_model and backend.execution_falls=true are two fall models; "
                    "choose one (execution_falls: the execution model's logistic fit; fall_model: a capability map)"
                )
            self.fall_model = CapabilityFallModel.load(fall_model)
        self.robot = robot
        self.walk = walk
        self.geometry = FootstepGeometry(robot.step_limits, robot.foot_length, robot.foot_width, walk.foot_distance)
        foot_half = (0.5 * robot.foot_length, 0.5 * robot.foot_width)
        trunk_half = tuple(0.5 * v for v in robot.torso_footprint)
        self.upper_body_box = self._upper_body_box(robot, collision_model)  # the check adds it against obstacles
        upper = (0.0, 0.0, 0.0)
        if self.upper_body_box is not None:
            length, width, offset = self.upper_body_box
            upper = (0.5 * length, 0.5 * width, offset)
        # Broad phase: a shape whose reference pose is farther from an obstacle than the shape's
        # farthest corner from that pose (+ a rounding margin) can't touch it.
        reach = max(math.hypot(*foot_half), math.hypot(*trunk_half), math.hypot(abs(upper[2]) + upper[0], upper[1]))
        reach = reach * (1.0 + 1e-9) + 1e-9
        self._dims = np.array([reach, *foot_half, *trunk_half, *upper], dtype=np.float64)  # collision kernels
        self._n_tall = 0  # the scene's obstacles: the first rows of its circles, the ball last
        self._space: pymunk.Space | None = None
        self._circles = circle_array(())  # the scene's (x, y, r), obstacles and ball
        self.feet: FeetState | None = None
        self.history: list[tuple[Side, Pose2D]] = []
        self.nav_history: list[Pose2D] = []
        self.scene: Scene | None = None
        self._noise_sigma = (0.0, 0.0, 0.0)
        self._duration = walk.double_step_duration
        self._rng = np.random.default_rng(0)

    @staticmethod
    def _upper_body_box(robot: RobotSpec, collision_model: str) -> tuple[float, float, float] | None:
        """With ``upper_body``, the robot's box bounding torso, head and arms at walk-ready (length,
        width, its centre's offset ahead of the feet's mean pose); else None."""
        if collision_model != "upper_body":
            return None
        if robot.upper_body_footprint is None:
            raise ValueError(f"backend.collision_model=upper_body: robot {robot.name!r} has no upper_body_footprint")
        return robot.upper_body_footprint

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
        self._space = None
        self._circles = scene.circle_array
        self._n_tall = len(scene.obstacles)
        self.feet = self.geometry.initial_feet()
        nav = self.feet.nav_pose
        self.history = [(Side.LEFT, self.feet.left), (Side.RIGHT, self.feet.right)]
        self.nav_history = [nav]
        return nav

    @property
    def space(self) -> pymunk.Space | None:
        """The episode's scene as a pymunk space (obstacles and ball as static circles, the foot, trunk
        and, with ``upper_body``, upper-body footprints as kinematic polygons, the last filtered to
        see the obstacles only), built on first use: collisions are tested in closed form
        (:func:`box_hits_circles`), this is for inspection and tests."""
        if self._space is None and self.scene is not None:
            space = pymunk.Space()
            for obstacle in self.scene.obstacles:
                circle = pymunk.Circle(space.static_body, obstacle.r, (obstacle.x, obstacle.y))
                circle.filter = pymunk.ShapeFilter(categories=_TALL)
                space.add(circle)
            if self.scene.ball is not None:
                ball = self.scene.ball
                circle = pymunk.Circle(space.static_body, ball.r, (ball.x, ball.y))
                circle.filter = pymunk.ShapeFilter(categories=_LOW)
                space.add(circle)
            # the robot's shapes share a group (never collide with each other); the upper body's sees the obstacles only
            for length, width, offset, mask in (
                (self.robot.foot_length, self.robot.foot_width, 0.0, pymunk.ShapeFilter.ALL_MASKS()),
                (*self.robot.torso_footprint, 0.0, pymunk.ShapeFilter.ALL_MASKS()),
                *([(*self.upper_body_box, _TALL)] if self.upper_body_box is not None else []),
            ):
                body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
                shape = _box(body, length, width, offset)
                shape.filter = pymunk.ShapeFilter(group=1, mask=mask)
                space.add(body, shape)
            self._space = space
        return self._space

    def execute(self, double_step: DoubleStep) -> StepResult:
        before = self.feet
        if before is None:
            raise RuntimeError("backend pymunk: execute() before reset()")
        sigma = self._noise_sigma
        perturbed = sigma[0] or sigma[1] or sigma[2]
        if not perturbed and self.execution_model is None and self.collision_model != "nav_distance":
            # the common case in one compiled call: placement, collision test and navigation pose
            (first, second), (left, right) = double_step, before
            values = collision.execute_double_step(
                right[0],
                right[1],
                right[2],
                left[0],
                left[1],
                left[2],
                first[0],
                first[1],
                first[2],
                second[0],
                second[1],
                second[2],
                self.geometry.kernel_params,
                self._circles,
                self._dims,
                self._n_tall,
            )
            after_first, after_second, executed, n_interfered = placed_double_step(left, values)
            fell = self.fall_model is not None and self._map_falls(double_step)
            return self._result(
                after_first, after_second, executed, n_interfered, fell, values[14], _new(Pose2D, values[15:])
            )
        after_first, after_second, executed, n_interfered = self.geometry.execute(
            before, double_step, self._perturb if perturbed else None
        )
        assert self.scene is not None  # reset() set it with the feet
        if not self.scene.circles:
            collided = False
        elif self.collision_model != "nav_distance":
            collided = self._double_step_collides(before, after_first, after_second)
        else:
            collided = self._nav_too_close(after_first.nav_pose) or self._nav_too_close(after_second.nav_pose)
        fell = False
        if self.execution_model is not None:
            after_first, after_second, fell = self._apply_execution_model(
                before, after_first, after_second, double_step
            )
        if self.fall_model is not None:  # drawn after the execution model's noise
            fell = self._map_falls(double_step)
        return self._result(
            after_first,
            after_second,
            executed,
            n_interfered,
            fell,
            collided,
            mean_pose(after_second[0], after_second[1]),
        )

    def _result(
        self,
        after_first: FeetState,
        after_second: FeetState,
        executed: DoubleStep,
        n_interfered: int,
        fell: bool,
        collided: bool,
        nav: Pose2D,
    ) -> StepResult:
        self.feet = after_second
        self.history += [(Side.RIGHT, after_first[1]), (Side.LEFT, after_second[0])]
        self.nav_history.append(nav)
        # positional (checked against StepResult's fields at import): keywords cost a µs here
        result = StepResult(
            nav, self._duration, after_second, executed, collided, None, {"foot_interference": n_interfered}
        )
        if fell:  # a fall model's fall: the tilt of a robot lying on the ground, as the 3D driver reports it
            result.max_tilt = math.pi / 2
        return result

    def _apply_execution_model(
        self, before: FeetState, after_first: FeetState, after_second: FeetState, double_step: DoubleStep
    ) -> tuple[FeetState, FeetState, bool]:
        """Move the feet so the navigation frame makes the model's displacement instead of the
        geometry's: both feet shift rigidly with the navigation frame (half the correction at the
        half step); the residual noise and the fall draw come from the episode rng."""
        model = self.execution_model
        assert model is not None, "called only with an execution model"
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

    def _map_falls(self, double_step: DoubleStep) -> bool:
        """Does the commanded double step fall?  One draw from the episode rng against the fall
        rate of the capability map's nearest cell (:class:`CapabilityFallModel`): a rate 0 never
        falls (``random() < 0`` is never true), a rate 1 always does."""
        model = self.fall_model
        assert model is not None, "called only with a fall model"
        action = double_step.as_array() / np.tile(self.robot.step_limits.as_array(), 2)
        return bool(self._rng.random() < model.probability(action))

    # -- collisions -----------------------------------------------------------------------
    def _double_step_collides(self, before: FeetState, after_first: FeetState, after_second: FeetState) -> bool:
        """Each flying foot at mid-swing and at put-down, and the trunk at each put-down, in one
        compiled call (:func:`footsim.backends.pymunk2d.collision.double_step_collides`, broad phase included)."""
        (sx, sy, st), ((mx, my, mt), (rx, ry, rt)), (ex, ey, et) = before[1], after_first, after_second[0]
        return collision.double_step_collides(
            self._circles, self._dims, self._n_tall, sx, sy, st, rx, ry, rt, mx, my, mt, ex, ey, et
        )

    def _nav_too_close(self, nav: Pose2D) -> bool:
        """Thesis check: the navigation pose within ``collision_distance`` of a circle's edge."""
        x, y, margin = nav[0], nav[1], self.collision_distance
        assert self.scene is not None
        return any(math.hypot(x - cx, y - cy) - r < margin for cx, cy, r in self.scene.circles)

    # -- rendering ------------------------------------------------------------------------
    def render(self, overlay: RenderOverlay | None = None) -> np.ndarray:
        return draw_scene(self.scene, self.history, self.nav_history, self.robot, overlay)

    def close(self) -> None:
        self._space = None


_new = tuple.__new__  # NamedTuple construction without the Python-level __new__
