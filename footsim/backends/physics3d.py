"""The shared 3D driver: walk engine → leg IK → joint targets → physics ticks → truth.

A 3D backend subclasses ``Physics3DBackend`` and implements only the physics verbs of
``PhysicsSim`` (build the world, set joint targets, advance, read the base pose, contacts, …).
Everything else — the walk-engine loop, fall detection by fused angles, obstacle-contact
bookkeeping, timing and the planar pose — lives here, once.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable
from functools import partial

import numpy as np

from footsim.backends.base import Backend, RenderOverlay, StepResult
from footsim.geometry import Pose2D
from footsim.kernels3d import all_finite, control_tick, quick_status, stabilized_targets
from footsim.robots.spec import RobotSpec
from footsim.scene import Scene
from footsim.walk.engine import QuinticWalk
from footsim.walk.footsteps import DoubleStep, FootstepGeometry, Side
from footsim.walk.ik import LEG_JOINT_NAMES
from footsim.walk.params import WalkParams

#: Randomization terms the driver applies itself, on every 3D backend (the sim's own terms are
#: in ``PhysicsSim.capabilities``).
DRIVER_TERMS = frozenset(
    {"control_latency", "push_force", "push_duration", "push_interval", "walk_freq_scale", "walk_trunk_height_scale"}
)
#: Push timing when a preset sets ``push_force`` but not these [s].
DEFAULT_PUSH_DURATION, DEFAULT_PUSH_INTERVAL = 0.1, 2.0

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


def levelling_rotation(sole_rotation: np.ndarray) -> np.ndarray:
    """Base rotation that makes a sole level, keeping its yaw.  ``sole_rotation`` is the sole's
    rotation with the base at identity orientation (the walk's standing pose pitches the trunk,
    so an upright base would stand the robot on its heels)."""
    sole = np.asarray(sole_rotation, dtype=float).reshape(3, 3)
    yaw = math.atan2(sole[1, 0], sole[0, 0])
    level = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return level @ sole.T


class TrunkStabilizer:
    """IMU feedback on the trunk orientation, in joint space (the Bit-Bots' walk has the same
    idea as PID controllers on the fused trunk pitch and roll).

    Each control tick the error between the measured fused roll/pitch of the base and the
    engine's planned trunk roll/pitch is multiplied by a gain [rad/rad] and added to the hip
    and ankle roll/pitch targets of both legs.  With the legs' +x (roll) and +y (pitch) joint
    axes, a positive hip gain turns the trunk back towards its planned orientation relative to
    the legs; an ankle gain tilts the soles against the lean.  All gains 0 = open loop (the
    engine's targets untouched, no extra base reads).
    """

    GAINS = ("hip_roll", "hip_pitch", "ankle_roll", "ankle_pitch")
    _HIP_ROLL, _HIP_PITCH, _ANKLE_PITCH, _ANKLE_ROLL = [1, 7], [2, 8], [4, 10], [5, 11]  # LEG_JOINT_NAMES

    def __init__(
        self, hip_roll: float = 0.0, hip_pitch: float = 0.0, ankle_roll: float = 0.0, ankle_pitch: float = 0.0
    ):
        gains = {"hip_roll": hip_roll, "hip_pitch": hip_pitch, "ankle_roll": ankle_roll, "ankle_pitch": ankle_pitch}
        for key, value in gains.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"backend.stabilizer.{key} must be a finite number, got {value!r}")
        self.hip_roll, self.hip_pitch = float(hip_roll), float(hip_pitch)
        self.ankle_roll, self.ankle_pitch = float(ankle_roll), float(ankle_pitch)
        self.active = any(v != 0.0 for v in gains.values())
        # Per-joint gains (LEG_JOINT_NAMES order) so a correction is two vector operations per tick;
        # rows of one (2, 12) array, as the compiled tick (footsim.kernels3d.control_tick) takes them.
        self.gains = np.zeros((2, 12))
        self._roll_gains, self._pitch_gains = self.gains  # views
        self._roll_gains[self._HIP_ROLL], self._roll_gains[self._ANKLE_ROLL] = self.hip_roll, self.ankle_roll
        self._pitch_gains[self._HIP_PITCH], self._pitch_gains[self._ANKLE_PITCH] = self.hip_pitch, self.ankle_pitch

    @classmethod
    def from_config(cls, config) -> TrunkStabilizer:
        if config is None:
            return cls()
        config = dict(config)
        unknown = sorted(set(config) - set(cls.GAINS))
        if unknown:
            raise ValueError(f"backend.stabilizer: unknown key(s) {unknown}; valid: {list(cls.GAINS)}")
        return cls(**config)

    def correct(
        self, targets: np.ndarray, tilt: tuple[float, float], planned_roll: float, planned_pitch: float
    ) -> np.ndarray:
        """``targets`` (12,) corrected for the measured fused ``tilt`` = (roll, pitch) (a new array)."""
        return targets + (self._roll_gains * (tilt[0] - planned_roll) + self._pitch_gains * (tilt[1] - planned_pitch))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


class PhysicsSim(ABC):
    """The physics verbs a 3D backend provides.  Joints are addressed by name at ``build``."""

    #: Physics randomization terms this sim applies in ``apply_physics_randomization``.
    capabilities: frozenset[str] = frozenset()

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

    def control_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None] | None:
        """For a sim whose state lives in numpy arrays: ``(quat, ctrl, leg_ids, feed_forward)`` so
        that the driver's compiled control tick (``footsim.kernels3d.control_tick``) reads the
        tilt and writes the leg commands itself, with the results of ``base_tilt`` and
        ``set_leg_targets``.  ``quat``: a live view of the base orientation (w, x, y, z);
        ``ctrl``: the live actuator-input array; ``leg_ids``: its index of each leg joint;
        ``feed_forward``: the servo feed-forward's (2, 12) [gain, previous] or None.  None (the
        default): the driver calls the verbs."""
        return None

    def status_arrays(self) -> tuple | None:
        """For a sim whose state lives in numpy arrays: ``(root_q, qpos, qvel, warnings,
        warning_ids)`` (live views: the free joint's 7 coordinates, the whole state, the
        warning counters and the fatal ones' indices) so that the driver's periodic check is
        one compiled call (``footsim.kernels3d.quick_status``) while all is well.  None (the
        default, or while the sim holds an error of its own): the driver calls the verbs."""
        return None

    def stabilized_ticks(
        self, targets: np.ndarray, trunk: np.ndarray, gains: np.ndarray, substeps: int
    ) -> Callable[[int, int], None] | None:
        """For a sim that can run stabilized control ticks cheaper than the verbs: ``run(k0, k1)``
        doing control ticks ``k0 … k1 − 1``, each commanding ``targets[k]`` corrected by the
        stabilizer ``gains`` for the measured tilt against ``trunk[k]`` and then ``substeps``
        physics timesteps (the result of ``base_tilt`` → ``TrunkStabilizer.correct`` →
        ``set_leg_targets`` → ``advance``, tick by tick).  None (the default): the driver calls
        the verbs."""
        return None

    def status_ok(self, out_of_bounds: float, tilt: np.ndarray) -> bool:
        """The driver's periodic check while all is well, in one cheap call: True, with the base's
        fused (roll, pitch) written into ``tilt``, when the state is sound (finite, within
        ``out_of_bounds``, right side up, no error of the sim's own); False when the driver should
        run its full check, which names the problem.  Default: ``kernels3d.quick_status`` on
        ``status_arrays`` (False without them)."""
        arrays = self.status_arrays()
        return arrays is not None and quick_status(*arrays, out_of_bounds, tilt)

    @abstractmethod
    def advance(self, n_steps: int) -> None:
        """Advance the physics by ``n_steps`` timesteps."""

    @abstractmethod
    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Base (trunk) position (3,) and body-to-world rotation matrix (3, 3)."""

    def base_tilt(self) -> tuple[float, float]:
        """Fused (roll, pitch) of the base; a sim may override it with a cheaper read."""
        return fused_roll_pitch(self.base_pose()[1])

    @abstractmethod
    def obstacle_contact(self) -> bool:
        """Is any part of the robot touching an obstacle or the ball?"""

    def sim_error(self) -> str | None:
        """A reason if the simulation became invalid (NaN state, instability), else None."""
        return None

    def apply_base_force(self, force_xyz: np.ndarray) -> None:
        """Apply this external force [N] (world frame) at the torso's centre of mass on every
        physics tick until it is changed (zeros: no force).  Cleared by nothing else."""
        raise NotImplementedError(f"{type(self).__name__} cannot push the torso")

    def apply_physics_randomization(self, values: dict[str, float]) -> None:
        """Set the model to NOMINAL (as built) modified by ``values`` (terms of ``capabilities``;
        a term not in ``values`` is back at nominal), so nothing compounds across episodes.
        ``terrain_slope`` comes with ``terrain_slope_direction`` [rad] (the downhill azimuth,
        drawn by the driver).  Called before ``reset_robot`` (and, for per-step terms, between
        double steps)."""
        if set(values) - {"terrain_slope_direction"}:
            raise ValueError(f"{type(self).__name__} cannot apply randomization terms {sorted(values)}")

    def render(self, overlay: RenderOverlay | None, width: int, height: int) -> np.ndarray | None:
        return None

    def close(self) -> None:
        pass


class Physics3DBackend(Backend):
    """A ``Backend`` that walks the robot with the quintic engine on a ``PhysicsSim``.

    A backend subclass names its ``sim_class`` and default timing; every option of its config
    that is not the driver's goes to the sim's constructor (``control_dt`` to both when the sim
    takes it), so a backend adds no constructor of its own.
    """

    kind = "3d"
    #: Use the compiled control tick where the sim offers ``control_arrays`` (False: always the
    #: verbs; same results, the tests compare the two).
    compiled_ticks = True
    collision_ends_episode = False  # thesis: 3D contacts destabilise the robot, they do not end the episode
    sim_class: type[PhysicsSim] | None = None
    default_control_dt = 0.005
    default_physics_dt = 0.005

    def __init__(
        self,
        robot: RobotSpec,
        walk: WalkParams,
        sim: PhysicsSim | None = None,
        control_dt: float | None = None,
        physics_dt: float | None = None,
        fall_threshold: float = DEFAULT_FALL_THRESHOLD,
        collision_ends_episode: bool = False,
        contact_check_every: int = 5,
        settle_time: float = 0.1,
        out_of_bounds: float = 50.0,
        render_size: tuple[int, int] = (480, 480),
        stabilizer: dict | None = None,
        **sim_options,
    ):
        control_dt = self.default_control_dt if control_dt is None else control_dt
        physics_dt = self.default_physics_dt if physics_dt is None else physics_dt
        if sim is None:
            sim = self._make_sim(sim_options, control_dt)
        elif sim_options:
            raise ValueError(f"backend {self.name}: unknown option(s) {sorted(sim_options)}")
        try:
            self.stabilizer = TrunkStabilizer.from_config(stabilizer)
            self._init_driver(
                robot,
                walk,
                sim,
                control_dt,
                physics_dt,
                fall_threshold,
                collision_ends_episode,
                contact_check_every,
                settle_time,
                out_of_bounds,
                render_size,
            )
        except BaseException:
            sim.close()
            raise

    def _make_sim(self, options: dict, control_dt: float) -> PhysicsSim:
        if self.sim_class is None:
            raise TypeError(f"{type(self).__name__} has no sim_class; pass a PhysicsSim")
        accepted = set(inspect.signature(self.sim_class.__init__).parameters) - {"self"}
        unknown = sorted(set(options) - accepted)
        if unknown:
            raise ValueError(
                f"backend {self.name}: unknown option(s) {unknown}; "
                f"simulator options: {sorted(accepted - {'control_dt'})}"
            )
        if "control_dt" in accepted:
            options = {**options, "control_dt": control_dt}
        return self.sim_class(**options)

    def _init_driver(
        self,
        robot,
        walk,
        sim,
        control_dt,
        physics_dt,
        fall_threshold,
        collision_ends_episode,
        contact_check_every,
        settle_time,
        out_of_bounds,
        render_size,
    ) -> None:
        substeps = control_dt / physics_dt
        if not (physics_dt > 0 and control_dt > 0 and abs(substeps - round(substeps)) < 1e-6):
            raise ValueError(
                f"backend.control_dt ({control_dt}) must be a positive multiple of backend.physics_dt ({physics_dt})"
            )
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
        self._joint_limits = np.vstack([robot.leg_limits(Side.LEFT), robot.leg_limits(Side.RIGHT)])
        self.engine = QuinticWalk(
            walk, self.geometry, robot.leg_geometry, self.control_dt, joint_limits=self._joint_limits
        )
        self.sim.build(robot, self.physics_dt)
        self.scene: Scene | None = None
        # Randomization state (see apply_randomization): the walk actually used, latency, pushes.
        self.walk_nominal = self.walk_current = walk
        self._values: dict[str, float] = {}  # the randomization values in force (merged)
        self._sim_values: dict[str, float] = {}  # what the sim was last given
        self._sim_dirty = False
        self._latency = 0
        self._delay: deque | None = None  # the last latency + 1 joint targets
        self._push_ticks: tuple[int, int] | None = None  # (interval, duration) in control ticks
        self._push_force = 0.0
        self._tick = 0  # control ticks since reset
        self._next_push = self._push_end = -1
        self._rng = np.random.default_rng(0)
        self.randomization_detail: dict[str, float] = {}  # directions drawn from the backend rng
        self._tilt, self._max_tilt = (0.0, 0.0), 0.0  # fused (roll, pitch) at the last check; max this step
        self._tilt_buffer = np.zeros(2)  # quick_status writes the tilt here

    # -- randomization --------------------------------------------------------------------
    @property
    def capabilities(self) -> frozenset[str]:
        """The driver's terms (latency, pushes, walk jitter) and the sim's physics terms."""
        return DRIVER_TERMS | self.sim.capabilities

    def apply_randomization(self, values: dict[str, float]) -> None:
        """Record drawn values.  Before ``reset`` (per-episode draw) they take effect at reset;
        between double steps (per-step terms) the sim terms are re-applied before the next
        ``execute`` and the driver terms take effect at once (walk jitter: at the next reset)."""
        unsupported = sorted(set(values) - self.capabilities)
        if unsupported:
            raise ValueError(f"backend {self.name!r} cannot apply randomization terms {unsupported}")
        for name in ("walk_freq_scale", "walk_trunk_height_scale", "push_duration", "push_interval"):
            if name in values and not values[name] > 0:
                raise ValueError(f"randomization {name} must be > 0, got {values[name]}")
        self._values.update(values)
        if set(values) & self.sim.capabilities:
            self._sim_dirty = True
        self._latency = max(0, int(round(self._values.get("control_latency", 0.0))))
        if "push_force" in self._values:
            duration = self._values.get("push_duration", DEFAULT_PUSH_DURATION)
            interval = self._values.get("push_interval", DEFAULT_PUSH_INTERVAL)
            ticks = (max(1, int(round(interval / self.control_dt))), max(1, int(round(duration / self.control_dt))))
            if self._push_ticks is not None and ticks[0] != self._push_ticks[0] and self._push_end < 0:
                self._next_push = self._tick + ticks[0]  # a new interval counts from now
            self._push_ticks = ticks
            self._push_force = abs(float(self._values["push_force"]))
        elif "push_duration" in values or "push_interval" in values:
            raise ValueError("randomization push_duration / push_interval need push_force")

    def _apply_sim_randomization(self, direction_rng: np.random.Generator | None) -> None:
        sim_values = {k: v for k, v in self._values.items() if k in self.sim.capabilities}
        if "terrain_slope" in sim_values:
            if direction_rng is not None or "terrain_slope_direction" not in self.randomization_detail:
                rng = direction_rng if direction_rng is not None else self._rng
                self.randomization_detail["terrain_slope_direction"] = float(rng.uniform(-math.pi, math.pi))
            sim_values["terrain_slope_direction"] = self.randomization_detail["terrain_slope_direction"]
        if sim_values or self._sim_values:  # also back to nominal when the terms are gone
            self.sim.apply_physics_randomization(sim_values)
        self._sim_values = sim_values
        self._sim_dirty = False

    def _rebuild_walk(self) -> None:
        v = self._values
        walk = dataclasses.replace(
            self.walk_nominal,
            freq=self.walk_nominal.freq * v.get("walk_freq_scale", 1.0),
            trunk_height=self.walk_nominal.trunk_height * v.get("walk_trunk_height_scale", 1.0),
        )
        if walk != self.walk_current:
            self.walk_current = walk
            self.engine = QuinticWalk(
                walk, self.geometry, self.robot.leg_geometry, self.control_dt, joint_limits=self._joint_limits
            )

    def _send_targets(self, target: np.ndarray) -> None:
        """Joint targets through the latency line (``control_latency`` ticks late) and the push
        schedule; one call per control tick."""
        if self._latency:
            line = self._delay
            if line is None or line.maxlen != self._latency + 1:  # latency redrawn mid-episode
                line = self._delay = deque(
                    [line[-1] if line else target] * (self._latency + 1), maxlen=self._latency + 1
                )
            line.append(target)
            target = line[0]
        self.sim.set_leg_targets(target)
        if self._push_ticks is not None:
            self._push_tick()
        else:
            self._tick += 1

    def _push_tick(self) -> None:
        """The push schedule at this control tick (start or end a push); counts the tick."""
        tick = self._tick
        if tick == self._push_end:
            self.sim.apply_base_force(np.zeros(3))
            self._push_end = -1
        if tick >= self._next_push:
            interval, duration = self._push_ticks
            if self._push_force > 0:
                angle = float(self._rng.uniform(-math.pi, math.pi))
                self.randomization_detail["push_direction"] = angle
                self.randomization_detail["pushes"] = self.randomization_detail.get("pushes", 0) + 1
                self.sim.apply_base_force(self._push_force * np.array([math.cos(angle), math.sin(angle), 0.0]))
                self._push_end = tick + duration
            self._next_push = tick + interval
        self._tick += 1

    def _ticks(self, trajectory) -> Callable[[int, int], None]:
        """This double step's ticks: ``run(k0, k1)`` does control ticks ``k0 … k1 − 1``, each
        commanding its joint targets (stabilizer correction, latency, feed-forward, push
        schedule) and then advancing the physics one control period."""
        targets, trunk = trajectory.joint_targets, trajectory.trunk_in_support  # roll, pitch: as in .trunk
        gains = self.stabilizer.gains if self.stabilizer.active else None
        substeps, advance = self.substeps, self.sim.advance
        plain = not (self._latency or self._push_ticks is not None)
        if plain and gains is not None and self.compiled_ticks:
            # The sim's own loop: fewer Python calls per tick than control + advance (PyBullet).
            run = self.sim.stabilized_ticks(targets, trunk, gains, substeps)
            if run is not None:
                return run
        control = self._control(targets, trunk, gains, plain)

        def run(k0: int, k1: int) -> None:
            for k in range(k0, k1):
                control(k)
                advance(substeps)

        return run

    def _control(self, targets, trunk, gains, plain):
        """``control(k)`` commands tick ``k``'s joint targets (no physics)."""
        arrays = self.sim.control_arrays() if self.compiled_ticks and not self._latency else None
        if arrays is not None:
            # One compiled call per tick does what base_tilt + correct + set_leg_targets do (~1 µs
            # instead of ~10 µs of numpy on 12-vectors; mj_step is ~50 µs).  The latency line
            # stays in Python (randomized runs only).
            quat, ctrl, leg_ids, feed_forward = arrays
            tick = partial(control_tick, targets, trunk, quat, gains, feed_forward, ctrl, leg_ids)
            if self._push_ticks is None:
                return tick

            def tick_and_push(k):
                tick(k)
                self._push_tick()

            return tick_and_push
        set_targets = self.sim.set_leg_targets if plain else self._send_targets
        if gains is None:
            return lambda k: set_targets(targets[k])
        base_tilt = self.sim.base_tilt  # TrunkStabilizer.correct, compiled: stabilized_targets
        return lambda k: set_targets(stabilized_targets(targets, trunk, gains, k, *base_tilt()))

    # -- episode --------------------------------------------------------------------------
    def reset(self, scene: Scene, rng: np.random.Generator) -> Pose2D:
        self.scene = scene
        self._rng = rng
        self.randomization_detail = {}
        self._rebuild_walk()
        self.sim.set_obstacles(scene)
        self._apply_sim_randomization(rng)  # before the robot is placed (masses, floor tilt, …)
        self.engine.reset()
        standing = self.engine.standing_joint_targets()
        joints = dict(self.robot.walk_ready)
        joints.update(zip(LEG_JOINT_NAMES, standing.tolist()))
        self.sim.reset_robot(np.array([0.0, 0.0, self.walk_current.trunk_height]), joints)
        self.sim.set_leg_targets(standing)
        self._delay = deque([standing] * (self._latency + 1), maxlen=self._latency + 1) if self._latency else None
        self._tick = 0
        self._push_end = -1
        if self._push_ticks is not None:
            self.sim.apply_base_force(np.zeros(3))
            self._next_push = self._push_ticks[0]  # the first push one interval after the start
        self.sim.advance(self.settle_ticks * self.substeps)  # let the contacts settle
        return self.planar_pose()

    def execute(self, double_step: DoubleStep) -> StepResult:
        if self._sim_dirty:  # per-step physics terms drawn since the last step
            self._apply_sim_randomization(None)
        trajectory = self.engine.double_step(double_step)
        self._max_tilt = 0.0  # updated by every _status() check of this step
        fell = collided = False
        error = None
        ticks, n_ticks, check = 0, len(trajectory.joint_targets), self.contact_check_every
        run = self._ticks(trajectory)
        watch_contacts = bool(self.scene.all_obstacles)
        while ticks < n_ticks:  # runs of `check` ticks, the checks between them
            start, ticks = ticks, min(ticks + check, n_ticks)
            run(start, ticks)
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
        info = {"foot_interference": trajectory.interfered, "ik_unreachable_ticks": int((~trajectory.reachable).sum())}
        if self.randomization_detail:
            info["randomization_detail"] = dict(self.randomization_detail)
        return StepResult(
            pose=pose,
            duration_s=ticks * self.control_dt,
            feet=trajectory.feet,
            executed=trajectory.executed,
            fell=fell,
            collided=collided,
            sim_error=error,
            info=info,
            tilt=self._tilt if error is None else (0.0, 0.0),
            max_tilt=self._max_tilt if error is None else 0.0,
        )

    # -- truth ----------------------------------------------------------------------------
    def planar_pose(self) -> Pose2D:
        """The base projected on the ground: (x, y, yaw of the trunk's x axis)."""
        position, rotation = self.sim.base_pose()
        return Pose2D(float(position[0]), float(position[1]), math.atan2(rotation[1, 0], rotation[0, 0]))

    def _fallen(self) -> bool:
        return self._status()[1]

    def _status(self) -> tuple[str | None, bool]:
        """``(sim error or None, fallen)``; also records the fused roll/pitch.  While all is well
        one compiled call does it (the same values as :meth:`_full_status`, ~1 µs instead of
        ~20 µs, 12 times per double step); otherwise the full check names the problem."""
        if self.sim.status_ok(self.out_of_bounds, self._tilt_buffer):
            return None, self._record_tilt(float(self._tilt_buffer[0]), float(self._tilt_buffer[1]))
        return self._full_status()

    def _record_tilt(self, roll: float, pitch: float) -> bool:
        """Keep the fused roll/pitch of this check (and the step's maximum); fallen?"""
        self._tilt = (roll, pitch)
        self._max_tilt = max(self._max_tilt, abs(roll), abs(pitch))
        return abs(roll) > self.fall_threshold or abs(pitch) > self.fall_threshold

    def _full_status(self) -> tuple[str | None, bool]:
        """``(sim error or None, fallen)`` from one read of the base: the simulator's own
        verdict, NaN and out-of-bounds checks, then fused roll/pitch against the threshold."""
        error = self.sim.sim_error()
        if error is not None:
            return error, False
        position, rotation = self.sim.base_pose()
        if not (all_finite(position) and all_finite(rotation)):
            return "non-finite base pose", False
        if max(map(abs, position.tolist())) > self.out_of_bounds:  # 3 floats: cheaper than numpy's abs().max()
            return f"base left the ±{self.out_of_bounds} m bounds", False
        if rotation[2, 2] < 0.0:
            self._tilt, self._max_tilt = (math.pi / 2, math.pi / 2), math.pi / 2
            return None, True
        return None, self._record_tilt(*fused_roll_pitch(rotation))

    def stop_walking(self) -> float:
        """Run the engine's stop sequence (back to standing); returns its duration [s]."""
        trajectory = self.engine.stop()
        set_targets = (
            self._send_targets if (self._latency or self._push_ticks is not None) else self.sim.set_leg_targets
        )
        for target in trajectory.joint_targets:
            set_targets(target)
            self.sim.advance(self.substeps)
        return len(trajectory) * self.control_dt

    def hold(self, seconds: float) -> None:
        """Keep the current joint targets for a while (used by the walk checks)."""
        self.sim.advance(int(round(seconds / self.control_dt)) * self.substeps)

    def render(self, overlay: RenderOverlay | None = None) -> np.ndarray | None:
        return self.sim.render(overlay, *self.render_size)

    def close(self) -> None:
        self.sim.close()
