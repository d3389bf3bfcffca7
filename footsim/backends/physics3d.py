"""The shared 3D driver: walk engine → leg IK → joint targets → physics ticks → truth.

A 3D backend subclasses ``Physics3DBackend`` and implements only the physics verbs of
``PhysicsSim`` (build the world, set joint targets, advance, read the base pose, contacts, …).
Everything else — the walk-engine loop, fall detection by fused angles, obstacle-contact
bookkeeping, timing and the planar pose — lives here, once.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from footsim.backends.base import Backend, RenderOverlay, StepResult
from footsim.geometry import Pose2D
from footsim.robots.spec import RobotSpec
from footsim.tasks.scenes import Scene
from footsim.walk.engine import QuinticWalk
from footsim.walk.footsteps import DoubleStep, FootstepGeometry, Side
from footsim.walk.ik import LEG_JOINT_NAMES
from footsim.walk.params import WalkParams

#: Fused roll or pitch beyond this counts as a fall [rad].  Walking tilts stay below ~0.25 rad;
#: past 0.7 rad (40°) the open-loop walk engine cannot recover.
DEFAULT_FALL_THRESHOLD = 0.7


def fused_roll_pitch(rotation: np.ndarray) -> tuple[float, float]:
    """Fused roll and pitch (Allgeuer & Behnke) from a body-to-world rotation matrix.

    Unlike Euler angles they do not depend on yaw or on the order of rotations: they are the
    angles between the world's vertical and the body's y–z plane (pitch) and x–z plane (roll).
    Valid for the upper hemisphere; an upside-down body (R[2,2] < 0) is fallen anyway.
    """
    pitch = math.asin(max(-1.0, min(1.0, -float(rotation[2, 0]))))
    roll = math.asin(max(-1.0, min(1.0, float(rotation[2, 1]))))
    return roll, pitch


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


class PhysicsSim(ABC):
    """The physics verbs a 3D backend provides.  Joints are addressed by name at ``build``."""

    @abstractmethod
    def build(self, robot: RobotSpec, physics_dt: float) -> None:
        """Create the world: floor, robot, and room for the scene's obstacles."""

    @abstractmethod
    def set_obstacles(self, scene: Scene) -> None:
        """Place the scene's obstacles (cylinders) and ball for a new episode."""

    @abstractmethod
    def reset_robot(self, base_position: np.ndarray, joint_positions: dict[str, float]) -> None:
        """Put the robot at ``base_position`` (upright, facing +x) with these joint angles, at rest."""

    @abstractmethod
    def set_leg_targets(self, targets: np.ndarray) -> None:
        """Position targets for the 12 leg joints, in ``LEG_JOINT_NAMES`` order."""

    @abstractmethod
    def advance(self, n_steps: int) -> None:
        """Advance the physics by ``n_steps`` timesteps."""

    @abstractmethod
    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Base (trunk) position (3,) and body-to-world rotation matrix (3, 3)."""

    @abstractmethod
    def obstacle_contact(self) -> bool:
        """Is any part of the robot touching an obstacle or the ball?"""

    def sim_error(self) -> str | None:
        """A reason if the simulation became invalid (NaN state, instability), else None."""
        return None

    def render(self, overlay: RenderOverlay | None, width: int, height: int) -> np.ndarray | None:
        return None

    def close(self) -> None:
        pass


class Physics3DBackend(Backend):
    """A ``Backend`` that walks the robot with the quintic engine on a ``PhysicsSim``."""

    kind = "3d"
    collision_ends_episode = False  # thesis: 3D contacts destabilise the robot, they do not end the episode

    def __init__(
        self,
        robot: RobotSpec,
        walk: WalkParams,
        sim: PhysicsSim,
        control_dt: float = 0.005,
        physics_dt: float = 0.005,
        fall_threshold: float = DEFAULT_FALL_THRESHOLD,
        collision_ends_episode: bool = False,
        contact_check_every: int = 5,
        settle_time: float = 0.1,
        out_of_bounds: float = 50.0,
        render_size: tuple[int, int] = (480, 480),
    ):
        substeps = control_dt / physics_dt
        if not (physics_dt > 0 and control_dt > 0 and abs(substeps - round(substeps)) < 1e-6):
            raise ValueError(f"backend.control_dt ({control_dt}) must be a positive multiple of backend.physics_dt ({physics_dt})")
        if not 0 < fall_threshold < math.pi / 2:
            raise ValueError(f"backend.fall_threshold must be in (0, pi/2) rad, got {fall_threshold!r}")
        if int(contact_check_every) < 1:
            raise ValueError(f"backend.contact_check_every must be >= 1, got {contact_check_every!r}")
        self.robot, self.walk, self.sim = robot, walk, sim
        self.control_dt, self.physics_dt = float(control_dt), float(physics_dt)
        self.substeps = int(round(substeps))
        self.fall_threshold = float(fall_threshold)
        self.collision_ends_episode = bool(collision_ends_episode)
        self.contact_check_every = int(contact_check_every)
        self.settle_ticks = int(round(settle_time / self.control_dt))
        self.out_of_bounds = float(out_of_bounds)
        self.render_size = tuple(render_size)
        self.geometry = FootstepGeometry(robot.step_limits, robot.foot_length, robot.foot_width, walk.foot_distance)
        limits = np.vstack([robot.leg_limits(Side.LEFT), robot.leg_limits(Side.RIGHT)])
        self.engine = QuinticWalk(walk, self.geometry, robot.leg_geometry, self.control_dt, joint_limits=limits)
        self.sim.build(robot, self.physics_dt)
        self.scene: Scene | None = None

    # -- episode --------------------------------------------------------------------------
    def reset(self, scene: Scene, rng: np.random.Generator) -> Pose2D:
        self.scene = scene
        self.sim.set_obstacles(scene)
        self.engine.reset()
        standing = self.engine.standing_joint_targets()
        joints = dict(self.robot.walk_ready)
        joints.update(zip(LEG_JOINT_NAMES, standing.tolist()))
        self.sim.reset_robot(np.array([0.0, 0.0, self.walk.trunk_height]), joints)
        self.sim.set_leg_targets(standing)
        self.sim.advance(self.settle_ticks * self.substeps)  # let the contacts settle
        return self.planar_pose()

    def execute(self, double_step: DoubleStep) -> StepResult:
        trajectory = self.engine.double_step(double_step)
        targets = trajectory.joint_targets
        fell = collided = False
        error = None
        ticks = 0
        check, substeps = self.contact_check_every, self.substeps
        set_targets, advance = self.sim.set_leg_targets, self.sim.advance
        watch_contacts = bool(self.scene.all_obstacles)
        for ticks in range(1, len(targets) + 1):
            set_targets(targets[ticks - 1])
            advance(substeps)
            if ticks % check == 0:
                error, fell = self._status()
                if error is not None or fell:
                    break
                if watch_contacts and not collided and self.sim.obstacle_contact():
                    collided = True
                    if self.collision_ends_episode:
                        break
        if error is None and not fell:
            error, fell = self._status()
        pose = self.planar_pose() if error is None else Pose2D(math.nan, math.nan, math.nan)
        return StepResult(
            pose=pose, duration_s=ticks * self.control_dt, feet=trajectory.feet, executed=trajectory.executed,
            fell=fell, collided=collided, sim_error=error,
            info={"foot_interference": trajectory.interfered, "ik_unreachable_ticks": int((~trajectory.reachable).sum())},
        )

    # -- truth ----------------------------------------------------------------------------
    def planar_pose(self) -> Pose2D:
        """The base projected on the ground: (x, y, yaw of the trunk's x axis)."""
        position, rotation = self.sim.base_pose()
        return Pose2D(float(position[0]), float(position[1]), math.atan2(rotation[1, 0], rotation[0, 0]))

    def _fallen(self) -> bool:
        return self._status()[1]

    def _status(self) -> tuple[str | None, bool]:
        """``(sim error or None, fallen)`` from one read of the base: the simulator's own
        verdict, NaN and out-of-bounds checks, then fused roll/pitch against the threshold."""
        error = self.sim.sim_error()
        if error is not None:
            return error, False
        position, rotation = self.sim.base_pose()
        if not (np.isfinite(position).all() and np.isfinite(rotation).all()):
            return "non-finite base pose", False
        if abs(position).max() > self.out_of_bounds:
            return f"base left the ±{self.out_of_bounds} m bounds", False
        if rotation[2, 2] < 0.0:
            return None, True
        roll, pitch = fused_roll_pitch(rotation)
        return None, abs(roll) > self.fall_threshold or abs(pitch) > self.fall_threshold

    def stop_walking(self) -> float:
        """Run the engine's stop sequence (back to standing); returns its duration [s]."""
        trajectory = self.engine.stop()
        for target in trajectory.joint_targets:
            self.sim.set_leg_targets(target)
            self.sim.advance(self.substeps)
        return len(trajectory) * self.control_dt

    def hold(self, seconds: float) -> None:
        """Keep the current joint targets for a while (used by the walk checks)."""
        self.sim.advance(int(round(seconds / self.control_dt)) * self.substeps)

    def render(self, overlay: RenderOverlay | None = None) -> np.ndarray | None:
        return self.sim.render(overlay, *self.render_size)

    def close(self) -> None:
        self.sim.close()
