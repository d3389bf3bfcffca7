"""PyBullet backend: the physics verbs of the shared 3D driver on a DIRECT-mode Bullet client.

Model.  The URDF comes from the robot spec (``footsim.robots.urdf.urdf_xml``, the upper body welded
with ``rigid_upper_body``), written once per
backend to a temporary file (removed on ``close``) and loaded with ``URDF_USE_INERTIA_FROM_FILE``
(Bullet would otherwise recompute inertias from the collision shapes) and
``URDF_USE_SELF_COLLISION``.  Self-collision is then restricted with collision groups to what the
spec marks ``self_collision`` (lower legs, ankles, feet) and only *between* the two legs —
the same pairs the MJCF model collides.  Joints are mapped by name once, at build.

Several backends coexist in one process: each owns its own ``p.connect(p.DIRECT)`` client and
passes ``physicsClientId`` on every call.  No GUI, no OpenGL; ``render`` uses TinyRenderer.

Motors.  Every joint is a ``POSITION_CONTROL`` motor with ``force`` = the joint's effort limit.
Bullet's position motor is not a spring: it is a velocity constraint solved each tick,
``v_target = positionGain · (q* − q) / dt + velocityGain · (q̇* − q̇) + q̇`` (velocityGain 1:
``v_target = positionGain / dt · (q* − q)``), force-limited.  A servo with gain ``kp`` and
damping ``kd`` whose inertia is small against ``kd`` (the overdamped limit) settles as
``q̇ = kp / kd · (q* − q)``: the same first-order law.  So we map the spec's servo parameters
(``kp`` [Nm/rad], and its ``damping`` [Nm s/rad] as ``kd``) to

    positionGain = position_gain_scale · kp · dt / damping

(Wolfgang's leg servos: kp 45, damping 1.7 → time constant kd/kp = 38 ms; dt 1/240 s → 0.110 ·
scale; Bullet caps it at 1), unless ``position_rate`` [1/s] sets every joint's motor to
``q̇ = position_rate · (q* − q)``, i.e. positionGain = position_rate · dt: the FootstepNav-v1 preset
sets 24 /s, Bullet's default positionGain 0.1 at the Bit-Bots' 1/240 s, which their PyBullet
simulation runs (it passes no gain).  A rate, not a gain, so that a timestep change keeps the same
servo (docs/BACKENDS.md has the measurements).  Bullet's own joint damping is off
(``_build_world``); the joint's default velocity motor (the URDF friction) is replaced by the
position motor.

Armature.  URDF cannot express the servos' reflected rotor inertia, and without it the leg links
are tiny (2e-5 to 6e-4 kg m²) under a 3.5 kg torso, and Bullet's sequential-impulse solver needs
many iterations a tick before motor and friction impulses agree (fewer: the stance foot slips).
``armature_scale`` folds the spec's armature, scaled, into the leg links as rotor disks
(``_add_armature``; 1.0 in FootstepNav-v1).  How many iterations the walk needs to converge is
measured in docs/BACKENDS.md (PyBullet, "Solver iterations").  ``motor=servo`` instead drives the
joints in torque mode with MuJoCo's servo law.

Contacts.  Lateral / spinning / rolling friction of the floor and the feet as the Bit-Bots'
PyBullet setup (FACTS: 1.0 / 0.1 / 0.1).  Obstacles are static cylinders, the ball a static
sphere: a small pool of unit-size bodies scaled to each episode's radii (``set_obstacles``).

Determinism and memory.  The world is built once.  Each episode resets the robot's base and
joint states and re-adds its links to the broadphase, which drops their contact manifolds, so
no warm-start impulses carry over from an earlier episode.  (``resetSimulation`` + ``loadURDF``
per episode would be simpler but Bullet leaks ~46 kB per load; obstacle bodies are pooled for
the same reason.)
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import weakref

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from footsim.backends.base import RenderOverlay, TrackingCamera
from footsim.backends.bullet import world_pool
from footsim.backends.control import ServoFeedForward
from footsim.backends.physics3d import PHYSICS_TERMS, Physics3DBackend, PhysicsSim, SimState, levelling_rotation
from footsim.geometry import Pose2D
from footsim.robots.spec import RobotSpec
from footsim.robots.urdf import urdf_xml
from footsim.scene import Scene
from footsim.walk.ik import LEG_JOINT_NAMES

# Collision groups / masks (collide when group_a & mask_b and group_b & mask_a).
_ROBOT, _STATIC, _LEFT_LEG, _RIGHT_LEG = 1, 2, 4, 8


@contextlib.contextmanager
def _quiet():
    """Silence Bullet's C-level stdout chatter (URDF merge log, importer warnings)."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):  # no real stdout (e.g. captured): nothing to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _quat_xyzw(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """Bullet's (x, y, z, w) quaternion of a rotation matrix (scipy's convention is the same)."""
    x, y, z, w = (float(v) for v in Rotation.from_matrix(rotation).as_quat())
    return x, y, z, w


class PybulletSim(PhysicsSim):
    """One DIRECT-mode Bullet world holding the robot, the floor and the scene's obstacles."""

    capabilities = PHYSICS_TERMS  # all of them (see apply_physics_randomization)

    def __init__(
        self,
        lateral_friction: float = 1.0,
        spinning_friction: float = 0.1,
        rolling_friction: float = 0.1,
        position_gain_scale: float = 1.0,
        position_rate: float | None = None,
        velocity_gain: float = 1.0,
        motor_max_velocity: bool = False,
        solver_iterations: int = 50,
        motor: str = "position",
        servo_kp_scale: float = 1.0,
        servo_damping_scale: float = 1.0,
        servo_kv: float = 0.0,
        armature_scale: float = 0.0,
        control_dt: float | None = None,
        obstacle_height: float = 1.0,
        self_collision: bool = True,
        rigid_upper_body: bool = True,
        max_base_speed: float = 10.0,
    ):
        for key, value in {
            "lateral_friction": lateral_friction,
            "spinning_friction": spinning_friction,
            "rolling_friction": rolling_friction,
            "velocity_gain": velocity_gain,
        }.items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"backend.{key} must be a non-negative number, got {value!r}")
        if not (math.isfinite(position_gain_scale) and position_gain_scale > 0):
            raise ValueError(f"backend.position_gain_scale must be positive, got {position_gain_scale!r}")
        if position_rate is not None and not (math.isfinite(position_rate) and position_rate > 0):
            raise ValueError(f"backend.position_rate must be a positive rate [1/s] or null, got {position_rate!r}")
        if int(solver_iterations) < 1:
            raise ValueError(f"backend.solver_iterations must be >= 1, got {solver_iterations!r}")
        if motor not in ("position", "servo"):
            raise ValueError(f"backend.motor must be 'position' or 'servo', got {motor!r}")
        for key, value in {
            "servo_damping_scale": servo_damping_scale,
            "servo_kv": servo_kv,
            "armature_scale": armature_scale,
        }.items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"backend.{key} must be a non-negative number, got {value!r}")
        if not (math.isfinite(servo_kp_scale) and servo_kp_scale > 0):
            raise ValueError(f"backend.servo_kp_scale must be positive, got {servo_kp_scale!r}")
        if motor == "servo" and armature_scale == 0:
            raise ValueError(
                "backend.motor=servo needs backend.armature_scale > 0: explicit servo torques on the "
                "bare link inertias (down to 2e-5 kg m^2) diverge at any usable timestep"
            )
        self.motor = motor
        self.servo_kp_scale, self.servo_damping_scale = float(servo_kp_scale), float(servo_damping_scale)
        self.servo_kv, self.armature_scale = float(servo_kv), float(armature_scale)
        self.control_dt = None if control_dt is None else float(control_dt)
        self.lateral_friction = float(lateral_friction)
        self.spinning_friction = float(spinning_friction)
        self.rolling_friction = float(rolling_friction)
        self.position_gain_scale = float(position_gain_scale)
        self.position_rate = None if position_rate is None else float(position_rate)
        self.velocity_gain = float(velocity_gain)
        if not isinstance(motor_max_velocity, (bool, np.bool_)):
            raise ValueError(f"backend.motor_max_velocity must be true or false, got {motor_max_velocity!r}")
        # true: every leg motor's target velocity is capped at the joint's URDF velocity limit, as the
        # Bit-Bots' PyBullet setup passes it (setJointMotorControl2 maxVelocity); false: no cap.
        self.motor_max_velocity = bool(motor_max_velocity)
        self.solver_iterations = int(solver_iterations)
        self.obstacle_height = float(obstacle_height)
        self.self_collision = bool(self_collision)
        self.rigid_upper_body = bool(rigid_upper_body)
        self.max_base_speed = float(max_base_speed)
        self.client = -1
        self._urdf_path: str | None = None
        self._finalizer: weakref.finalize | None = None
        self.robot_id = -1
        self.obstacle_ids: list[int] = []
        self._placed: list[tuple[str, float, list[float]]] = []  # this episode's (kind, radius, position)
        self._stand_ins: list[int] = []  # render-only visual bodies of this episode's obstacles
        self._goal_marker = -1
        self._footstep_markers: list[int] = []  # render-only boxes: right, left commanded footstep
        self._scene: Scene | None = None
        # Randomization (apply_physics_randomization): scales in force, per-tick external wrench.
        self._scales = {"kp": 1.0, "damping": 1.0, "torque": 1.0}
        self._randomized = False
        self._base_force = np.zeros(3)
        self._com_offset = np.zeros(3)
        self._wrench = False  # a push or a COM offset to apply every tick

    # -- world ----------------------------------------------------------------------------
    def build(self, robot: RobotSpec, physics_dt: float) -> None:
        self.spec, self.physics_dt = robot, float(physics_dt)
        text = urdf_xml(robot, self.rigid_upper_body, sole_frames=False)
        self._key = (text, self.self_collision, self.armature_scale)
        # Motor gains per joint (see the module docstring for the mapping).
        self._gain = {j.name: min(1.0, self._nominal_gain(j)) for j in robot.joints}
        self._self_collide = {link.name: any(s.self_collision for s in link.shapes) for link in robot.links}
        fd, self._urdf_path = tempfile.mkstemp(prefix=f"footsim_{robot.name}_", suffix=".urdf")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        world = world_pool.take(self._key)
        if world is not None:  # reuse a parked world of the same model
            self.__dict__.update(world)
        else:
            self.client = p.connect(p.DIRECT)
            if self.client < 0:  # pragma: no cover
                raise RuntimeError("pybullet: could not connect a DIRECT client")
        self._finalizer = weakref.finalize(self, world_pool.release, self.client, self._urdf_path, None, None)
        if world is None:
            self._build_world()
        self._configure()

    def _build_world(self) -> None:
        """(Re)create floor and robot in an empty world; joint indices are mapped by name."""
        c = self.client
        p.resetSimulation(physicsClientId=c)
        floor_shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=c)
        floor_visual = p.createVisualShape(
            p.GEOM_BOX,
            halfExtents=[25, 25, 0.001],
            visualFramePosition=[0, 0, -0.001],
            rgbaColor=[0.35, 0.55, 0.35, 1],
            physicsClientId=c,
        )
        self.floor_id = p.createMultiBody(0, floor_shape, floor_visual, physicsClientId=c)
        p.setCollisionFilterGroupMask(self.floor_id, -1, _STATIC, _ROBOT, physicsClientId=c)
        flags = (
            p.URDF_USE_INERTIA_FROM_FILE
            | p.URDF_USE_SELF_COLLISION
            | p.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
            | p.URDF_MERGE_FIXED_LINKS
        )
        with _quiet():
            self.robot_id = p.loadURDF(self._urdf_path, [0, 0, 1], flags=flags, physicsClientId=c)
        self.joint_index: dict[str, int] = {}
        self.link_index: dict[str, int] = {self.spec.base_link: -1}
        self._filters: list[tuple[int, int, int]] = []
        for i in range(p.getNumJoints(self.robot_id, physicsClientId=c)):
            info = p.getJointInfo(self.robot_id, i, physicsClientId=c)
            self.link_index[info[12].decode()] = i
            if info[2] == p.JOINT_REVOLUTE:
                self.joint_index[info[1].decode()] = i
        self.joint_names = [n for n in self.spec.joint_names if n in LEG_JOINT_NAMES or not self.rigid_upper_body]
        missing = sorted(set(self.joint_names) - set(self.joint_index))
        if missing:
            raise RuntimeError(f"pybullet: the loaded URDF lacks joints {missing}")
        # Self-collision only between the legs' self-colliding links (as in the MJCF model).
        for name, link in self.link_index.items():
            group, mask = _ROBOT, _STATIC
            if self.self_collision and self._self_collide.get(name):
                left = name.startswith("l_")
                group |= _LEFT_LEG if left else _RIGHT_LEG
                mask |= _RIGHT_LEG if left else _LEFT_LEG
            p.setCollisionFilterGroupMask(self.robot_id, link, group, mask, physicsClientId=c)
            self._filters.append((link, group, mask))
        # No explicit joint damping: Bullet applies it as an explicit torque, which diverges on the
        # bare foot links (D·dt/I ≫ 2 at 1/240 s); the servo's damping is in the motor mapping.
        for index in self.joint_index.values():
            p.changeDynamics(self.robot_id, index, jointDamping=0.0, physicsClientId=c)
        if self.armature_scale > 0:
            self._add_armature()
        # Base pose: Bullet reports the base's inertial frame; keep the link-frame offset.
        dyn = p.getDynamicsInfo(self.robot_id, -1, physicsClientId=c)
        self._com_pos = np.array(dyn[3])
        self._com_orn = tuple(dyn[4])
        self._com_rot = np.array(p.getMatrixFromQuaternion(self._com_orn)).reshape(3, 3)
        self.obstacle_ids = []
        self._free: dict[str, list[int]] = {}  # parked obstacle bodies per kind ("cylinder", "ball")
        self._pool_kind: dict[int, str] = {}
        self._placed = []
        self._stand_ins = []
        self._goal_marker = -1
        self._footstep_markers = []
        # Nominal masses and inertia diagonals of every robot link (-1: the torso), for randomization.
        self.nominal_dynamics = {
            link: (info[0], tuple(info[2]))
            for link in [-1, *range(p.getNumJoints(self.robot_id, physicsClientId=c))]
            for info in [p.getDynamicsInfo(self.robot_id, link, physicsClientId=c)]
        }

    def _add_armature(self) -> None:
        """Fold each joint's armature (the servo's reflected rotor inertia, spec × ``armature_scale``)
        into its child link as a thin rotor disk on the joint axis: inertia ``a`` about the axis,
        ``a/2`` about the two others (a valid inertia: Bullet's inverse dynamics rejects one that
        breaks the triangle inequality).  Bullet's multibody has no armature; this adds ``a`` to the
        joint's own diagonal of the mass matrix, as MuJoCo's armature does, but also couples it
        into the upstream joints (the rotor rides on the link)."""
        c, body = self.client, self.robot_id
        for name, link in self.joint_index.items():
            armature = self.armature_scale * self.spec.joint(name).servo.armature
            info = p.getJointInfo(body, link, physicsClientId=c)
            dynamics = p.getDynamicsInfo(body, link, physicsClientId=c)
            inertial = np.array(p.getMatrixFromQuaternion(dynamics[4])).reshape(3, 3)
            axis = inertial.T @ np.asarray(info[13], dtype=float)  # joint axis in the principal frame
            inertia = np.asarray(dynamics[2], dtype=float) + 0.5 * armature * (1.0 + axis * axis)
            p.changeDynamics(body, link, localInertiaDiagonal=inertia.tolist(), physicsClientId=c)

    def _configure(self) -> None:
        """Settings of this backend's config on a (new or reused) world."""
        c = self.client
        p.setGravity(0, 0, -9.81, physicsClientId=c)
        p.setPhysicsEngineParameter(
            fixedTimeStep=self.physics_dt,
            numSolverIterations=self.solver_iterations,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            physicsClientId=c,
        )
        p.changeDynamics(
            self.floor_id,
            -1,
            lateralFriction=self.lateral_friction,
            spinningFriction=self.spinning_friction,
            rollingFriction=self.rolling_friction,
            physicsClientId=c,
        )
        for foot in ("l_foot", "r_foot"):
            if foot in self.link_index:
                p.changeDynamics(
                    self.robot_id, self.link_index[foot], lateralFriction=self.lateral_friction, physicsClientId=c
                )
        # Motor arrays, in a fixed order: legs (LEG_JOINT_NAMES), then the rest.
        self.leg_indices = [self.joint_index[n] for n in LEG_JOINT_NAMES]
        self.leg_forces = [self.spec.joint(n).effort for n in LEG_JOINT_NAMES]
        self.leg_gains = [self._gain[n] for n in LEG_JOINT_NAMES]
        self._scales = {"kp": 1.0, "damping": 1.0, "torque": 1.0}
        self.leg_vgains = [self.velocity_gain] * len(LEG_JOINT_NAMES)
        self.leg_max_velocities = [self.spec.joint(n).velocity for n in LEG_JOINT_NAMES]
        self.other_names = [n for n in self.joint_names if n not in LEG_JOINT_NAMES]
        # The state contract: Bullet's base state (position, quaternion x y z w, linear and angular
        # velocity of the inertial frame) read into one array; the leg commands sent from another.
        self._base = np.zeros(13)
        self._command = np.zeros(len(LEG_JOINT_NAMES))
        self._feed_forward: ServoFeedForward | None = None
        if self.motor == "servo":
            dt = self.control_dt if self.control_dt is not None else self.physics_dt
            self._feed_forward = ServoFeedForward(self.servo_kv, np.ones(len(LEG_JOINT_NAMES)), dt)
        self.state = SimState(
            quat=self._base[3:7],
            position=self._base[0:3],
            command=self._command,
            leg_ids=np.arange(len(LEG_JOINT_NAMES), dtype=np.intp),
            finite=(self._base,),
            live=False,
            w_last=True,
            frame=self._com_rot,
            offset=self._com_pos,
            matrix_normalizes=True,
            velocity=self._base[7:13],
            max_speed=self.max_base_speed,
            feed_forward=None if self._feed_forward is None else self._feed_forward.state,
        )
        if self.motor == "servo":
            # Torque mode: Bullet's leg motors become the joints' dry friction (a velocity motor to
            # 0 with the servo's frictionloss as its force, as MuJoCo's frictionloss); the servo law
            # is applied as a torque every tick (servo_torques).
            frictionloss = [self.spec.joint(n).servo.frictionloss for n in LEG_JOINT_NAMES]
            p.setJointMotorControlArray(
                self.robot_id,
                self.leg_indices,
                p.VELOCITY_CONTROL,
                targetVelocities=[0.0] * len(frictionloss),
                forces=frictionloss,
                physicsClientId=c,
            )
            self._servo_gains()

    def _servo_gains(self) -> None:
        """Per leg joint (kp, kv, damping, effort) of the servo law, with the randomization scales."""
        kp_scale = self.servo_kp_scale * self._scales["kp"]
        self._servo = [
            (
                kp_scale * j.servo.kp,
                self.servo_kv,
                self.servo_damping_scale * self._scales["damping"] * j.servo.damping,
                j.effort * self._scales["torque"],
            )
            for j in map(self.spec.joint, LEG_JOINT_NAMES)
        ]
        dt = self.control_dt if self.control_dt is not None else self.physics_dt
        assert self._feed_forward is not None, "servo motors only"
        self._feed_forward.gain[:] = [kv / kp / dt for kp, kv, _, _ in self._servo]  # the servo's kv / kp

    def set_obstacles(self, scene: Scene) -> None:
        """Place the scene's cylinders and ball.

        Bullet frees nothing of a removed body (a few kB leak per created body or shape), and
        every body in the world costs time each tick, even parked far away with collisions off:
        with the earlier pool of one body per radius, a PyBullet tick was 2.4× slower after 100
        obstacle episodes and 6× after 400.  So a few bodies with *unit-size* shapes serve every
        radius: ``unsupportedChangeScaling`` scales a body's shape to the obstacle.  Contact
        distances then equal those of a shape created at that radius (tested).  The pooled
        bodies are invisible (the unit shape would be drawn unscaled); ``render`` draws visual
        stand-ins.  Unused bodies are parked far below the floor with collisions off."""
        self._scene = scene
        c = self.client
        if not self._healthy():  # after a blow-up, start from a freshly built world
            self._build_world()
            self._configure()
        for body in self.obstacle_ids:  # park last episode's bodies
            p.resetBasePositionAndOrientation(body, [0.0, 0.0, -100.0], [0, 0, 0, 1], physicsClientId=c)
            p.setCollisionFilterGroupMask(body, -1, 0, 0, physicsClientId=c)
            self._free[self._pool_kind[body]].append(body)
        self.obstacle_ids = []
        self._remove_stand_ins()
        self._placed = []
        items = [(o, False) for o in scene.obstacles] + ([(scene.ball, True)] if scene.ball is not None else [])
        for obstacle, is_ball in items:
            kind = "ball" if is_ball else "cylinder"
            free = self._free.setdefault(kind, [])
            body = free.pop() if free else self._new_obstacle(kind)
            radius = float(obstacle.r)
            p.unsupportedChangeScaling(body, [radius, radius, radius if is_ball else 1.0], physicsClientId=c)
            position = [float(obstacle.x), float(obstacle.y), radius if is_ball else self.obstacle_height / 2]
            p.resetBasePositionAndOrientation(body, position, [0, 0, 0, 1], physicsClientId=c)
            p.setCollisionFilterGroupMask(body, -1, _STATIC, _ROBOT, physicsClientId=c)
            self.obstacle_ids.append(body)
            self._placed.append((kind, radius, position))

    def _new_obstacle(self, kind: str) -> int:
        """A pooled obstacle body: unit radius (the cylinder ``obstacle_height`` tall), invisible."""
        c = self.client
        if kind == "ball":
            shape = p.createCollisionShape(p.GEOM_SPHERE, radius=1.0, physicsClientId=c)
            visual = p.createVisualShape(p.GEOM_SPHERE, radius=1.0, rgbaColor=[0, 0, 0, 0], physicsClientId=c)
        else:
            shape = p.createCollisionShape(p.GEOM_CYLINDER, radius=1.0, height=self.obstacle_height, physicsClientId=c)
            visual = p.createVisualShape(
                p.GEOM_CYLINDER, radius=1.0, length=self.obstacle_height, rgbaColor=[0, 0, 0, 0], physicsClientId=c
            )
        body = p.createMultiBody(0, shape, visual, [0.0, 0.0, -100.0], physicsClientId=c)
        self._pool_kind[body] = kind
        return body

    def _draw_stand_ins(self) -> None:
        """Visual-only bodies at this episode's obstacles, for ``render`` (made on the first
        frame of an episode, removed at the next ``set_obstacles``)."""
        if self._stand_ins or not self._placed:
            return
        c = self.client
        for kind, radius, position in self._placed:
            if kind == "ball":
                visual = p.createVisualShape(p.GEOM_SPHERE, radius=radius, rgbaColor=[1, 1, 1, 1], physicsClientId=c)
            else:
                visual = p.createVisualShape(
                    p.GEOM_CYLINDER,
                    radius=radius,
                    length=self.obstacle_height,
                    rgbaColor=[0.55, 0.35, 0.2, 1],  # the MuJoCo backends' obstacle colour
                    physicsClientId=c,
                )
            self._stand_ins.append(p.createMultiBody(0, -1, visual, position, physicsClientId=c))

    def _remove_stand_ins(self) -> None:
        for body in self._stand_ins:
            p.removeBody(body, physicsClientId=self.client)
        self._stand_ins = []

    # -- robot ----------------------------------------------------------------------------
    def reset_robot(self, base_position: np.ndarray, joint_positions: dict[str, float]) -> None:
        c, body = self.client, self.robot_id
        position, rotation = self._levelled_base(np.asarray(base_position, dtype=float), joint_positions)
        com = position + rotation @ self._com_pos
        orientation = _quat_xyzw(rotation @ self._com_rot)  # Bullet's base frame is the inertial frame
        p.resetBasePositionAndOrientation(body, com.tolist(), orientation, physicsClientId=c)
        p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=c)
        # Re-adding the links to the broadphase drops their contact manifolds, so no warm-start
        # impulses from the previous episode leak into this one (determinism).
        for link, group, mask in self._filters:
            p.setCollisionFilterGroupMask(body, link, group, mask, physicsClientId=c)
        for name in self.joint_names:
            p.resetJointState(
                body, self.joint_index[name], float(joint_positions.get(name, 0.0)), 0.0, physicsClientId=c
            )
        if self.motor == "servo":  # target velocities restart from rest at these angles
            assert self._feed_forward is not None
            self._feed_forward.reset([float(joint_positions.get(n, 0.0)) for n in LEG_JOINT_NAMES])
            self._command[:] = self._feed_forward.previous
        others = [self.joint_index[n] for n in self.other_names]
        if others:
            p.setJointMotorControlArray(
                body,
                others,
                p.POSITION_CONTROL,
                targetPositions=[float(joint_positions.get(n, 0.0)) for n in self.other_names],
                forces=[self.spec.joint(n).effort * self._scales["torque"] for n in self.other_names],
                positionGains=[self._motor_gain(n) for n in self.other_names],
                velocityGains=[self.velocity_gain] * len(others),
                physicsClientId=c,
            )

    def _levelled_base(
        self, base_position: np.ndarray, joint_positions: dict[str, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Base position and rotation with the soles flat on the floor, as MuJoCo and dm-control
        start: the walk's standing pose pitches the trunk (``trunk_pitch``), so an upright base
        would put the robot on its heels, where Bullet's rolling friction holds it (measured: one
        contact point per foot, feet 0.077 rad toe-up, trunk upright instead of leaning).  The
        left sole's roll and pitch in the base frame (the spec's kinematics) are undone, its yaw
        kept, and the robot lowered so the lower foot's lowest point touches the floor."""
        soles = [self.spec.sole_transform(side, joint_positions) for side in ("left", "right")]
        rotation = levelling_rotation(soles[0][:3, :3])
        lowest = min(float((rotation @ t[:3, 3])[2]) for t in soles)
        clearance = self.spec.sole_clearance("left")
        return np.array([base_position[0], base_position[1], -lowest - clearance]), rotation

    def read_state(self, velocity: bool = False) -> None:
        base, c, body = self._base, self.client, self.robot_id
        base[0:3], base[3:7] = p.getBasePositionAndOrientation(body, c)  # positional: keywords cost µs
        if velocity:
            base[7:10], base[10:13] = p.getBaseVelocity(body, c)

    def write_command(self) -> None:
        """Position motors: the command as their targets.  Servo mode: nothing to send (the servo
        law turns the command into torques every physics step, ``servo_torques``)."""
        if self.motor == "servo":
            return
        if self.motor_max_velocity:  # the array call has no maxVelocity: one call per joint
            for index, target, force, gain, vgain, cap in zip(
                self.leg_indices,
                self._command.tolist(),
                self.leg_forces,
                self.leg_gains,
                self.leg_vgains,
                self.leg_max_velocities,
            ):
                p.setJointMotorControl2(
                    self.robot_id,
                    index,
                    p.POSITION_CONTROL,
                    targetPosition=target,
                    force=force,
                    positionGain=gain,
                    velocityGain=vgain,
                    maxVelocity=cap,
                    physicsClientId=self.client,
                )
            return
        p.setJointMotorControlArray(
            self.robot_id,
            self.leg_indices,
            p.POSITION_CONTROL,
            targetPositions=self._command.tolist(),
            forces=self.leg_forces,
            positionGains=self.leg_gains,
            velocityGains=self.leg_vgains,
            physicsClientId=self.client,
        )

    @property
    def urdf_path(self) -> str | None:
        """The temporary URDF file this sim's world loaded (removed when the world is released)."""
        return self._urdf_path

    def servo_torques(self) -> list[float]:
        """MuJoCo's actuator law: clip(kp (ctrl − q) − kv q̇, ±effort) − damping q̇ per leg joint."""
        states = p.getJointStates(self.robot_id, self.leg_indices, physicsClientId=self.client)
        torques = []
        for (q, qd, _, _), ctrl, (kp, kv, damping, effort) in zip(states, self._command.tolist(), self._servo):
            force = kp * (ctrl - q) - kv * qd
            torques.append(min(effort, max(-effort, force)) - damping * qd)
        return torques

    def advance(self, n_steps: int) -> None:
        c = self.client
        if self.motor == "servo":
            body, legs = self.robot_id, self.leg_indices
            for _ in range(n_steps):
                if self._wrench:
                    self._apply_wrench()
                p.setJointMotorControlArray(
                    body, legs, p.TORQUE_CONTROL, forces=self.servo_torques(), physicsClientId=c
                )
                p.stepSimulation(physicsClientId=c)
            return
        if self._wrench:
            for _ in range(n_steps):
                self._apply_wrench()
                p.stepSimulation(physicsClientId=c)
            return
        step = p.stepSimulation
        for _ in range(n_steps):
            step(c)  # positional: Bullet parses keywords µs slower

    # -- randomization --------------------------------------------------------------------
    def _nominal_gain(self, joint) -> float:
        """A joint's Bullet positionGain before randomization and the cap: ``position_rate`` · dt
        when the rate is set, else the module docstring's mapping of its servo, scale · kp · dt / kd."""
        if self.position_rate is not None:
            return self.position_rate * self.physics_dt
        return self.position_gain_scale * joint.servo.kp * self.physics_dt / max(joint.servo.damping, 1e-6)

    def _motor_gain(self, name: str) -> float:
        """Bullet position gain of a joint with the randomized kp and damping (kd) scales
        (× kp / kd, as the servo mapping would give), capped at 1."""
        if self._scales["kp"] == 1.0 and self._scales["damping"] == 1.0:
            return self._gain[name]
        raw = self._nominal_gain(self.spec.joint(name))
        return min(1.0, raw * self._scales["kp"] / self._scales["damping"])

    def apply_physics_randomization(self, values: dict[str, float]) -> None:
        """Nominal × ``values`` (absent terms: nominal).

        * friction: Bullet multiplies the two bodies' lateral friction, so the floor's and the
          feet's coefficients are scaled separately (contact: nominal · floor · foot).
        * ``rolling_friction_scale``: the floor's rolling friction (the feet carry none; Bullet
          combines it as floor rolling · foot lateral, so the contact's torque arm is nominal ·
          this · foot_friction).
        * ``link_mass_scale``: mass and inertia diagonal of every link, one factor (the inertia
          includes the armature folded into the leg links, so it scales with them).
        * ``actuator_kp_scale`` / ``joint_damping_scale``: the servo's kp and kd in the motor
          mapping (positionGain ∝ kp / kd, capped at 1) — Bullet's joint damping is off (see
          ``_build_world``), the servo's damping lives in that mapping.
        * ``torque_limit_scale``: the motors' max force.
        * ``torso_com_offset_x/_y``: Bullet cannot move a loaded link's inertial frame, so the
          offset is emulated by its gravity moment, the torque (R d) × m g on the torso every
          tick — exact for the moment about any support point, but the torso's inertial frame
          (and so its dynamics in flight) stays nominal.
        * ``terrain_slope``: the floor plane is tilted about the origin toward
          ``terrain_slope_direction``.
        """
        unknown = sorted(set(values) - self.capabilities - {"terrain_slope_direction"})
        if unknown:
            raise ValueError(f"PybulletSim cannot apply randomization terms {unknown}")
        c, body = self.client, self.robot_id

        def scale(name):
            value = float(values.get(name, 1.0))
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"randomization {name} must be > 0, got {value}")
            return value

        mass = scale("link_mass_scale")
        for link, (m, inertia) in self.nominal_dynamics.items():
            p.changeDynamics(
                body, link, mass=m * mass, localInertiaDiagonal=[v * mass for v in inertia], physicsClientId=c
            )
        p.changeDynamics(
            self.floor_id,
            -1,
            lateralFriction=self.lateral_friction * scale("floor_friction"),
            rollingFriction=self.rolling_friction * scale("rolling_friction_scale"),
            physicsClientId=c,
        )
        for foot in ("l_foot", "r_foot"):
            if foot in self.link_index:
                p.changeDynamics(
                    body,
                    self.link_index[foot],
                    lateralFriction=self.lateral_friction * scale("foot_friction"),
                    physicsClientId=c,
                )
        self._scales = {
            "kp": scale("actuator_kp_scale"),
            "damping": scale("joint_damping_scale"),
            "torque": scale("torque_limit_scale"),
        }
        self.leg_gains = [self._motor_gain(n) for n in LEG_JOINT_NAMES]
        self.leg_forces = [self.spec.joint(n).effort * self._scales["torque"] for n in LEG_JOINT_NAMES]
        if self.motor == "servo":
            self._servo_gains()
        self._com_offset = np.array([values.get("torso_com_offset_x", 0.0), values.get("torso_com_offset_y", 0.0), 0.0])
        slope = float(values.get("terrain_slope", 0.0))
        if not (math.isfinite(slope) and abs(slope) < math.pi / 4):
            raise ValueError(f"randomization terrain_slope must be within ±pi/4 rad, got {slope}")
        direction = float(values.get("terrain_slope_direction", 0.0))
        axis = (-math.sin(direction), math.cos(direction), 0.0)  # the plane descends toward the direction
        half = 0.5 * slope
        p.resetBasePositionAndOrientation(
            self.floor_id, [0, 0, 0], [*(math.sin(half) * a for a in axis), math.cos(half)], physicsClientId=c
        )
        self._randomized = bool(values)
        self._wrench = bool(self._base_force.any() or self._com_offset.any())

    def apply_base_force(self, force_xyz: np.ndarray) -> None:
        self._base_force = np.asarray(force_xyz, dtype=float).copy()
        self._wrench = bool(self._base_force.any() or self._com_offset.any())

    def _apply_wrench(self) -> None:
        """Bullet clears external forces after every step: push and COM-offset torque, per tick."""
        c, body = self.client, self.robot_id
        com, orn = p.getBasePositionAndOrientation(body, physicsClientId=c)
        if self._base_force.any():
            p.applyExternalForce(body, -1, self._base_force.tolist(), com, p.WORLD_FRAME, physicsClientId=c)
        if self._com_offset.any():
            rot = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3) @ self._com_rot.T  # link frame
            mass = p.getDynamicsInfo(body, -1, physicsClientId=c)[0]
            torque = np.cross(rot @ self._com_offset, [0.0, 0.0, -9.81 * mass])
            p.applyExternalTorque(body, -1, torque.tolist(), p.WORLD_FRAME, physicsClientId=c)

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pos, orn = p.getBasePositionAndOrientation(self.robot_id, physicsClientId=self.client)
        rot = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3) @ self._com_rot.T  # link frame
        return np.asarray(pos) - rot @ self._com_pos, rot

    def joint_positions(self) -> dict[str, float]:
        states = p.getJointStates(
            self.robot_id, [self.joint_index[n] for n in self.joint_names], physicsClientId=self.client
        )
        return {n: s[0] for n, s in zip(self.joint_names, states)}

    # -- events ---------------------------------------------------------------------------
    def obstacle_contact(self) -> bool:
        # Bullet also lists points a few mm apart (positive contactDistance, index 8); count only
        # touching or penetrating ones, as MuJoCo's contacts (geom margin 0) do.
        c, body = self.client, self.robot_id
        return any(
            point[8] <= 0.0 for ob in self.obstacle_ids for point in p.getContactPoints(body, ob, physicsClientId=c)
        )

    def sole_forces(self) -> tuple[float, float]:
        # Touching or penetrating points only, as in obstacle_contact; index 9 = normal force.
        c, body = self.client, self.robot_id
        forces = []
        for side in ("left", "right"):
            link = self.link_index[self.spec.foot_link(side)]
            points = p.getContactPoints(bodyA=body, linkIndexA=link, physicsClientId=c)
            forces.append(sum(point[9] for point in points if point[8] <= 0.0))
        return float(forces[0]), float(forces[1])

    def sim_error(self) -> str | None:
        pos, orn = p.getBasePositionAndOrientation(self.robot_id, physicsClientId=self.client)
        lin, ang = p.getBaseVelocity(self.robot_id, physicsClientId=self.client)
        values = (*pos, *orn, *lin, *ang)
        if not all(math.isfinite(v) for v in values):
            return "non-finite base state"
        if math.hypot(*lin) > self.max_base_speed or math.hypot(*ang) > 6 * self.max_base_speed:
            return "exploding base velocity"
        return None

    def _healthy(self) -> bool:
        """No sim error and the base within 50 m of the origin (else the world is rebuilt)."""
        if self.sim_error() is not None:
            return False
        pos, _ = p.getBasePositionAndOrientation(self.robot_id, physicsClientId=self.client)
        return max(abs(v) for v in pos) < 50.0

    # -- rendering ------------------------------------------------------------------------
    def render(
        self,
        overlay: RenderOverlay | None,
        width: int,
        height: int,
        camera: TrackingCamera | None = None,
        base: Pose2D | None = None,
    ) -> np.ndarray | None:
        c = self.client
        self._draw_stand_ins()
        camera, base = self.camera_view(camera, base)
        if overlay is not None:
            self._draw_overlay(overlay)
        eye, target = camera.eye(base)
        view = p.computeViewMatrix(eye.tolist(), target.tolist(), [0.0, 0.0, 1.0], physicsClientId=c)
        proj = p.computeProjectionMatrixFOV(camera.fov, width / height, 0.05, 50.0, physicsClientId=c)
        _, _, rgba, _, _ = p.getCameraImage(
            width,
            height,
            view,
            proj,
            shadow=int(camera.shadows),
            renderer=p.ER_TINY_RENDERER,
            flags=p.ER_NO_SEGMENTATION_MASK,
            physicsClientId=c,
        )
        frame = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()
        if overlay is not None and overlay.ray_endpoints is not None and overlay.believed is not None:
            frame = _draw_rays(frame, overlay, camera, base)
        return frame

    def _draw_overlay(self, overlay: RenderOverlay) -> None:
        """The goal disc and heading arrow and the commanded footsteps as visual-only bodies (no
        collision shape), made at the first frame and moved each frame; the MuJoCo backends' colours."""
        c = self.client
        if self._goal_marker < 0:
            disc = p.createVisualShape(p.GEOM_CYLINDER, radius=0.12, length=0.01, physicsClientId=c)
            self._goal_marker = p.createMultiBody(0, -1, disc, [0, 0, 0.005], physicsClientId=c)
            arrow = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.15, 0.02, 0.006], physicsClientId=c)
            self._goal_arrow = p.createMultiBody(0, -1, arrow, [0, 0, 0.012], physicsClientId=c)
        g = overlay.goal
        rgba = [0.1, 0.8, 0.1, 1.0] if overlay.reached else [0.9, 0.1, 0.1, 1.0]
        orn = p.getQuaternionFromEuler([0, 0, g.theta])
        for body, position in (
            (self._goal_marker, [g.x, g.y, 0.005]),
            (self._goal_arrow, [g.x + 0.15 * math.cos(g.theta), g.y + 0.15 * math.sin(g.theta), 0.012]),
        ):
            p.resetBasePositionAndOrientation(body, position, orn, physicsClientId=c)
            p.changeVisualShape(body, -1, rgbaColor=rgba, physicsClientId=c)
        if overlay.foot_size is None or not overlay.footsteps:
            for body in self._footstep_markers:
                p.resetBasePositionAndOrientation(body, [0, 0, -100.0], [0, 0, 0, 1], physicsClientId=c)
            return
        if not self._footstep_markers:
            half = [0.5 * overlay.foot_size[0], 0.5 * overlay.foot_size[1], 0.004]
            for colour in ([0.85, 0.2, 0.2, 0.6], [0.15, 0.65, 0.25, 0.6]):  # right, left
                box = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=colour, physicsClientId=c)
                self._footstep_markers.append(p.createMultiBody(0, -1, box, [0, 0, -100.0], physicsClientId=c))
        for body, foot in zip(self._footstep_markers, overlay.footsteps):
            p.resetBasePositionAndOrientation(
                body, [foot.x, foot.y, 0.006], p.getQuaternionFromEuler([0, 0, foot.theta]), physicsClientId=c
            )

    _WORLD_ATTRS = (
        "client",
        "floor_id",
        "robot_id",
        "joint_index",
        "link_index",
        "joint_names",
        "_filters",
        "_com_pos",
        "_com_orn",
        "_com_rot",
        "obstacle_ids",
        "_free",
        "_pool_kind",
        "_goal_marker",
        "_goal_arrow",
        "_footstep_markers",
        "nominal_dynamics",
    )

    def close(self) -> None:
        """Park the world for reuse (``world_pool``) or disconnect; remove the URDF file."""
        if self._finalizer is None or not self._finalizer.alive:
            return
        self._finalizer.detach()
        world = None
        try:
            # A world that blew up is not reused (NaN may linger in Bullet's caches).
            if self.robot_id >= 0 and p.isConnected(self.client) and self._healthy():
                if self._randomized:  # a parked world is nominal for its next owner
                    self.apply_physics_randomization({})
                if self._scene is not None:
                    self.set_obstacles(type(self._scene)(goal=self._scene.goal))  # park the obstacles
                world = {k: getattr(self, k) for k in self._WORLD_ATTRS if hasattr(self, k)}
        except Exception:  # pragma: no cover - a broken world is not reused
            world = None
        world_pool.release(self.client, self._urdf_path, self._key if world is not None else None, world)
        self.client = -1


def _draw_rays(frame: np.ndarray, overlay: RenderOverlay, camera: TrackingCamera, base: Pose2D) -> np.ndarray:
    """The rays drawn over ``frame`` (TinyRenderer draws no lines): each segment from the
    believed pose, 2 cm above the floor, projected with the camera model (the one the frame was
    rendered from; ``tests/test_video_camera.py`` checks that the two agree), cut where it would
    pass behind the camera."""
    from PIL import Image, ImageDraw

    eye, target = camera.eye(base)
    forward = (target - eye) / np.linalg.norm(target - eye)
    assert overlay.believed is not None and overlay.ray_endpoints is not None
    start = np.array([overlay.believed.x, overlay.believed.y, 0.02])
    ends = np.column_stack([np.asarray(overlay.ray_endpoints, dtype=float), np.full(len(overlay.ray_endpoints), 0.02)])
    near = 0.1  # [m] in front of the camera
    d0 = float((start - eye) @ forward)
    if d0 <= near:
        return frame
    d1 = (ends - eye) @ forward
    cut = np.where(d1 < near, (d0 - near) / np.maximum(d0 - d1, 1e-12), 1.0)[:, None]
    ends = start + cut * (ends - start)
    height, width = frame.shape[:2]
    pixels = camera.project(np.vstack([start, ends]), base, width, height)
    image = Image.fromarray(frame)
    draw = ImageDraw.Draw(image)
    origin = tuple(pixels[0])
    for end in pixels[1:]:
        draw.line([origin, tuple(end)], fill=(255, 204, 0), width=1)
    return np.asarray(image).copy()


class PybulletBackend(Physics3DBackend):
    """The shared 3D driver on PyBullet.  Options: see ``conf/backend/pybullet.yaml``."""

    name = "pybullet"

    sim_class = PybulletSim
    default_control_dt = 0.01
    default_physics_dt = 0.01
