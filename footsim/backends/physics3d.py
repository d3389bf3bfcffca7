"""The shared 3D driver: walk engine → leg IK → joint targets → physics ticks → truth.

A 3D backend subclasses ``Physics3DBackend`` and gives it a ``PhysicsSim``: the physics verbs
(build the world, place obstacles, reset the robot, advance, read the base pose, contacts, …)
and a small state contract, :class:`SimState`: the arrays holding the base orientation and the
leg commands (views of ``mjData`` for the MuJoCo family; arrays the sim fills and sends for
PyBullet).  The driver's one control tick is: read the state (a sim whose arrays are not live
views refreshes them) → the control law (``footsim.backends.control.control_tick``: tilt,
stabilizer, latency, servo feed-forward, command write) → send the commands (the same) →
advance.  The walk-engine loop, the periodic state check (fall by fused tilt, sim errors),
obstacle-contact bookkeeping, timing and the planar pose live here, once.  So do the walk node's
options of ``WalkParams`` (``_node_ticks``): the engine update rate, the trunk PID and the phase
reset on foot contact; with them off the control tick is the plain one.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from footsim.backends.base import Backend, FrameHook, RenderOverlay, StepResult, TrackingCamera
from footsim.backends.control import (
    TrunkPID,
    TrunkStabilizer,
    all_finite,
    contact_watch,
    control_tick_packed,
    fused_roll_pitch,
    node_tick_packed,
    state_ok_packed,
    write_targets,
)
from footsim.compiled import pack, typed_entry
from footsim.geometry import Pose2D
from footsim.robots.spec import RobotSpec
from footsim.scene import Scene
from footsim.walk.engine import QuinticWalk, WalkState, WalkTrajectory
from footsim.walk.footsteps import DoubleStep, FootstepGeometry, Side
from footsim.walk.ik import LEG_JOINT_NAMES
from footsim.walk.params import WalkParams

#: Randomization terms the driver applies itself, on every 3D backend.
DRIVER_TERMS = frozenset(
    {"control_latency", "push_force", "push_duration", "push_interval", "walk_freq_scale", "walk_trunk_height_scale"}
)
#: The physics randomization terms of the 3D sims (``PhysicsSim.apply_physics_randomization``):
#: one vocabulary; a sim that cannot apply one of them leaves it out of its ``capabilities``.
PHYSICS_TERMS = frozenset(
    {
        "floor_friction",
        "foot_friction",
        "rolling_friction_scale",
        "link_mass_scale",
        "torso_com_offset_x",
        "torso_com_offset_y",
        "actuator_kp_scale",
        "torque_limit_scale",
        "joint_damping_scale",
        "terrain_slope",
    }
)
#: Push timing when a preset sets ``push_force`` but not these [s].
DEFAULT_PUSH_DURATION, DEFAULT_PUSH_INTERVAL = 0.1, 2.0

#: Fused roll or pitch beyond this counts as a fall [rad].  Walking tilts stay below ~0.25 rad;
#: past 0.7 rad (40°) the open-loop walk engine cannot recover.
DEFAULT_FALL_THRESHOLD = 0.7


def levelling_rotation(sole_rotation: np.ndarray) -> np.ndarray:
    """Base rotation that makes a sole level, keeping its yaw.  ``sole_rotation`` is the sole's
    rotation with the base at identity orientation (the walk's standing pose pitches the trunk,
    so an upright base would stand the robot on its heels)."""
    sole = np.asarray(sole_rotation, dtype=float).reshape(3, 3)
    yaw = math.atan2(sole[1, 0], sole[0, 0])
    level = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return level @ sole.T


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


@dataclass(eq=False)
class SimState:
    """A 3D sim's state contract: the arrays the driver's control law writes and its state
    check reads (``footsim.backends.control``).  Made by the sim at ``build``.

    With ``live`` the arrays are views of the simulator's own state (MuJoCo's ``mjData``): the
    driver reads and writes them directly.  Otherwise the sim refreshes them in
    ``PhysicsSim.read_state`` and sends ``command`` in ``PhysicsSim.write_command``.
    """

    quat: np.ndarray  #: (4,) orientation of the base body the simulator integrates
    position: np.ndarray  #: (3,) its position
    command: np.ndarray  #: the leg commands: the simulator's actuator inputs or a buffer sent to it
    leg_ids: np.ndarray  #: ``command``'s index of each leg joint (``LEG_JOINT_NAMES`` order)
    finite: tuple[np.ndarray, ...]  #: every value that must stay finite
    live: bool = True
    w_last: bool = False  #: ``quat`` is (x, y, z, w) rather than (w, x, y, z)
    #: The integrated body's frame in the base link's: rotation (3, 3) and origin (3,); None: the link.
    frame: np.ndarray | None = None
    offset: np.ndarray | None = None
    #: The sim's own quaternion → matrix (``base_pose``) divides by |q|² (Bullet's does).
    matrix_normalizes: bool = False
    velocity: np.ndarray | None = None  #: (6,) linear and angular velocity of the base, checked against max_speed
    max_speed: float = math.inf  #: [m/s]; angular: 6 × this [rad/s]
    warnings: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))  #: simulator warning counters
    warning_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))  #: the fatal ones
    fault: np.ndarray = field(default_factory=lambda: np.zeros(1, dtype=np.int8))  #: [0] ≠ 0: the sim failed
    feed_forward: np.ndarray | None = None  #: the servo feed-forward's (2, 12) [gain, previous targets]

    def check_args(self, out_of_bounds: float, tilt: np.ndarray) -> tuple:
        """The arguments of ``control.state_ok`` for this state (``tilt``: (2,) receives the tilt)."""
        return (
            self.fault,
            self.warnings,
            self.warning_ids,
            self.finite,
            self.velocity,
            self.max_speed,
            self.position,
            self.quat,
            self.w_last,
            self.matrix_normalizes,
            self.frame,
            self.offset,
            float(out_of_bounds),
            tilt,
        )

    def last_targets(self) -> np.ndarray:
        """The leg targets of the last command, before the servo feed-forward (a copy)."""
        if self.feed_forward is not None:
            return self.feed_forward[1].copy()
        return self.command[self.leg_ids].copy()


class PhysicsSim(ABC):
    """The physics verbs and the state contract (``state``, a :class:`SimState`) a 3D sim provides.
    Joints are addressed by name at ``build``."""

    #: Physics randomization terms this sim applies in ``apply_physics_randomization`` (all of
    #: ``PHYSICS_TERMS`` for the simulators here; none for a sim without randomization verbs).
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

    #: The state contract (see :class:`SimState`); set by ``build``.
    state: SimState

    def read_state(self, velocity: bool = False) -> None:
        """Refresh ``state``'s orientation and position (and, with ``velocity``, the velocity)
        from the simulator.  Nothing to do for live views (the default)."""
        return None

    def write_command(self) -> None:
        """Send ``state.command`` to the simulator.  Nothing to do for live views (the default)."""
        return None

    def set_leg_targets(self, targets: np.ndarray) -> None:
        """Command these 12 leg targets (``LEG_JOINT_NAMES`` order) through the servo
        feed-forward, outside the control ticks (standing at reset, replays)."""
        s = self.state
        write_targets(np.asarray(targets, dtype=float), s.feed_forward, s.command, s.leg_ids)
        self.write_command()

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

    def sole_forces(self) -> tuple[float, float]:
        """The normal contact force [N] on the (left, right) foot link from everything it touches
        (floor, obstacles, the other foot): the foot-pressure read of the phase reset."""
        raise NotImplementedError(f"{type(self).__name__} reads no foot contact forces (needed by the phase reset)")

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

    def render(
        self,
        overlay: RenderOverlay | None,
        width: int,
        height: int,
        camera: TrackingCamera | None = None,
        base: Pose2D | None = None,
    ) -> np.ndarray | None:
        """An RGB frame from ``camera`` (None: the default :class:`TrackingCamera`) following the
        base's planar pose ``base`` (None: read from the sim); None: this sim has no renderer."""
        return None

    def camera_view(self, camera: TrackingCamera | None, base: Pose2D | None) -> tuple[TrackingCamera, Pose2D]:
        """``render``'s camera and base pose, with its defaults filled in."""
        if base is None:
            position, rotation = self.base_pose()
            base = Pose2D(float(position[0]), float(position[1]), math.atan2(rotation[1, 0], rotation[0, 0]))
        return (TrackingCamera() if camera is None else camera), base

    def close(self) -> None:
        """Release what the simulator holds (nothing by default)."""
        return None


# The stepping half steps' state codes (the phase reset's), as plain ints for the compiled code.
_STEPPING = (int(WalkState.START_STEP), int(WalkState.WALKING))


def _filmed(
    run: Callable[[int, int], int | None], hook: FrameHook, done: int, due: list[int]
) -> Callable[[int, int], int | None]:
    """``run`` (ticks ``k0 … k1 − 1`` of a part of the double step that starts after ``done``
    ticks) split where a frame is due: ``due[0]`` ticks into the double step, ``hook.frame``
    renders and names the next one.  The ticks and their order are ``run``'s: only the calls are
    cut, so the checks between them stay at the same ticks."""

    def filmed(k0: int, k1: int) -> int | None:
        k = k0
        while due[0] - done <= k1:
            cut = max(due[0] - done, k)
            if cut > k:
                ended = run(k, cut)
                if ended is not None:  # a phase reset: the step goes on from a new plan
                    if done + ended + 1 == due[0]:  # it stopped where the frame is due
                        due[0] = hook.frame(due[0])
                    return ended
                k = cut
            due[0] = hook.frame(done + k)
        return run(k, k1) if k < k1 else None

    return filmed


class Physics3DBackend(Backend):
    """A ``Backend`` that walks the robot with the quintic engine on a ``PhysicsSim``.

    A backend subclass names its ``sim_class`` and default timing; every option of its config
    that is not the driver's goes to the sim's constructor (``control_dt`` to both when the sim
    takes it), so a backend adds no constructor of its own.
    """

    kind = "3d"
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
        camera: dict | None = None,
        **sim_options,
    ):
        control_dt = self.default_control_dt if control_dt is None else control_dt
        physics_dt = self.default_physics_dt if physics_dt is None else physics_dt
        if sim is None:
            sim = self._make_sim(sim_options, control_dt)
        elif sim_options:
            raise ValueError(f"backend {self.name}: unknown option(s) {sorted(sim_options)}")
        try:
            self.camera = TrackingCamera.from_config(camera)
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
            raise ValueError(f"fall_threshold must be in (0, pi/2) rad, got {fall_threshold!r}")
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
        # The stabilizer's gains act on the IK's chain axes (hip roll +x, pitch +y, ...): the robot's
        # joints turn the other way where their sign is -1.
        self._stabilizer_gains = self.stabilizer.gains * robot.leg_geometry.signs
        self.sim.build(robot, self.physics_dt)
        self.scene: Scene | None = None
        # Randomization state (see apply_randomization): the walk actually used, latency, pushes.
        self.walk_nominal = self.walk_current = walk
        self._values: dict[str, float] = {}  # the randomization values in force (merged)
        self._sim_values: dict[str, float] = {}  # what the sim was last given
        self._sim_dirty = False
        self._latency = 0
        self._delay: np.ndarray | None = None  # the latency line: targets not yet sent
        self._delay_slot = np.zeros(2, dtype=np.int64)  # [row of the oldest target, fill the line first]
        self._entries: dict = {}  # compiled entries of the control tick and the state check
        self._check: tuple = (None, None, None)  # the state check's entry, state and packed arguments
        self._push_ticks: tuple[int, int] | None = None  # (interval, duration) in control ticks
        self._push_force = 0.0
        self._tick = 0  # control ticks since reset
        self._next_push = self._push_end = -1
        self._rng = np.random.default_rng(0)
        self.randomization_detail: dict[str, float] = {}  # directions drawn from the backend rng
        self._tilt, self._max_tilt = (0.0, 0.0), 0.0  # fused (roll, pitch) at the last check; max this step
        self._tilt_buffer = np.zeros(2)  # state_ok writes the tilt here
        # The walk node's options (WalkParams): the trunk PID, the engine update rate, the phase reset.
        self.trunk_pid = TrunkPID.from_walk(walk)
        self._node = np.zeros(2)  # the last engine update: its index (engine time × engine_freq), engine time [s]
        self._held = np.zeros(18)  # the targets (12) and trunk pose (6) of the last engine update

    # -- randomization --------------------------------------------------------------------
    @property
    def capabilities(self) -> frozenset[str]:  # type: ignore[override]  # derived from the sim, not assignable
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

    def clear_randomization(self) -> None:
        """Forget every value drawn so far: the driver terms are off at once, the sim's terms are
        back at nominal at the next ``reset`` or ``execute``."""
        self._values = {}
        self._latency = 0
        self._push_ticks = None
        self._push_force = 0.0
        self._sim_dirty = True

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

    def _delay_line(self) -> np.ndarray | None:
        """The latency line for this double step's ticks: ``control_latency`` rows of targets not
        yet sent (None without latency).  A latency redrawn mid-episode starts a new line filled
        with the newest target of the old one (with none: with its first tick's target)."""
        latency = self._latency
        if not latency:
            self._delay = None
        elif self._delay is None or len(self._delay) != latency:
            old, slot = self._delay, self._delay_slot
            self._delay = np.zeros((latency, 12))
            if old is None:
                slot[1] = 1  # control_tick fills the line with its first target
            else:
                self._delay[:] = old[(slot[0] - 1) % len(old)]
            slot[0] = 0
        return self._delay

    def _push_tick(self) -> None:
        """The push schedule at this control tick (start or end a push); counts the tick."""
        tick = self._tick
        if tick == self._push_end:
            self.sim.apply_base_force(np.zeros(3))
            self._push_end = -1
        if tick >= self._next_push:
            interval, duration = self._push_ticks  # type: ignore[misc]  # called only while pushes are scheduled
            if self._push_force > 0:
                angle = float(self._rng.uniform(-math.pi, math.pi))
                self.randomization_detail["push_direction"] = angle
                self.randomization_detail["pushes"] = self.randomization_detail.get("pushes", 0) + 1
                self.sim.apply_base_force(self._push_force * np.array([math.cos(angle), math.sin(angle), 0.0]))
                self._push_end = tick + duration
            self._next_push = tick + interval
        self._tick += 1

    def _ticks(self, trajectory: WalkTrajectory, stabilized: bool = True) -> Callable[[int, int], int | None]:
        """This trajectory's control ticks: ``run(k0, k1)`` does ticks ``k0 … k1 − 1``, each the
        one tick of the module docstring: read the state, the control law (stabilizer unless
        ``stabilized`` is False, latency, servo feed-forward), send the commands, the push
        schedule, and the physics of one control period."""
        gains = self._stabilizer_gains if (stabilized and self.stabilizer.active) else None
        walk = self.walk_current
        pid = self.trunk_pid if (stabilized and self.trunk_pid.active) else None
        reset = stabilized and walk.phase_reset_foot_pressure_active
        if walk.engine_freq is not None or pid is not None or reset:
            return self._node_ticks(trajectory, gains, pid, reset)
        targets, trunk = trajectory.joint_targets, trajectory.trunk_in_support  # roll, pitch: as in .trunk
        tick, packed = self._control_tick(targets, trunk, gains, self._delay_line())
        read, write, push = self._tick_io(gains is not None)
        advance, substeps = self.sim.advance, self.substeps

        def run(k0: int, k1: int) -> int | None:
            for k in range(k0, k1):
                if read is not None:
                    read()
                tick(k, packed)
                if write is not None:
                    write()
                if push is not None:
                    push()
                advance(substeps)
            return None

        return run

    def _node_ticks(
        self, trajectory: WalkTrajectory, gains: np.ndarray | None, pid: TrunkPID | None, reset: bool
    ) -> Callable[[int, int], int | None]:
        """:meth:`_ticks` with the walk node's options (``WalkParams``): each tick takes the
        engine's targets only at an engine update (``engine_freq``; None: every tick), else holds
        the last ones; at an update the trunk PID moves the trunk (``pid``); after the physics
        the phase reset (``reset``) may end the step: ``run(k0, k1)`` then stops after tick k and
        returns k (else None).

        An engine update is due at tick k when ``floor(t_k · engine_freq)`` (``t_k``: the tick's
        engine time) has moved on since the last one: at most ``engine_freq`` updates a second,
        each seen at the first control tick at or after its instant."""
        walk = self.walk_current
        # The trajectory's targets, copied as the run reaches them (solving a half step at a time:
        # a phase reset leaves the rest unsolved), and written in place by the node.
        targets, trunk = np.empty((len(trajectory), 12)), trajectory.trunk_in_support.copy()
        solve, copied = trajectory.solve, 0
        read, write, push = self._tick_io(gains is not None or pid is not None)
        advance, substeps, sole_forces = self.sim.advance, self.substeps, self.sim.sole_forces
        times = trajectory.t
        rate = 0.0 if walk.engine_freq is None else float(walk.engine_freq)  # node_tick: 0 = every tick
        arrays = pid.arrays if pid is not None else None
        tick, packed = self._node_tick(
            rate, targets, trunk, times, trajectory.local_poses, arrays, self.engine.ik_legs, gains, self._delay_line()
        )
        # Per tick, the phase reset's read after the physics (control.contact_watch): the flying
        # foot's index in sole_forces() in the contact window, else -1.
        watch: list[int] | None = None
        if reset:
            out = np.empty(len(times), dtype=np.int64)
            contact_watch(
                trajectory.state, trajectory.phase, trajectory.support, _STEPPING, 0.5 * walk.phase_reset_min_phase, out
            )
            watch = out.tolist()
        threshold = walk.phase_reset_ground_min_pressure

        def run(k0: int, k1: int) -> int | None:
            nonlocal copied
            if k1 > copied:
                joints, _, solved = solve(k1)
                targets[copied:solved] = joints[copied:solved]
                copied = solved
            for k in range(k0, k1):
                if read is not None:
                    read()
                tick(k, packed)
                if write is not None:
                    write()
                if push is not None:
                    push()
                advance(substeps)
                if watch is not None and watch[k] >= 0 and sole_forces()[watch[k]] > threshold:
                    return k
            return None

        return run

    def _tick_io(self, reads_state: bool) -> tuple[Callable | None, Callable | None, Callable | None]:
        """What one tick does around the control law, for both tick loops: the state read (only
        when the law reads the base and the sim's arrays are not live views), the command write
        (sims without live views) and the push schedule's tick (None: no pushes)."""
        s = self.sim.state
        read = None if (s.live or not reads_state) else self.sim.read_state
        write = None if s.live else self.sim.write_command
        push = None if self._push_ticks is None else self._push_tick
        return read, write, push

    def _control_tick(self, targets: np.ndarray, trunk: np.ndarray, gains: np.ndarray | None, delay):
        """``control_tick``'s compiled code for these arrays and the sim's state contract, and its
        arguments but the tick, packed: ``(entry, packed)``, called ``entry(k, packed)``."""
        packed = pack((targets, trunk, gains, *self._law_args(delay)))
        return self._packed_entry(control_tick_packed, 0, packed), packed

    def _node_tick(self, rate: float, targets, trunk, times, local, pid, legs, gains, delay):
        """``node_tick``'s compiled code for these arrays, the trunk PID's (None: off), the engine's
        legs and the sim's state contract, and its arguments but the tick, packed: ``(entry,
        packed)``, called ``entry(k, packed)``."""
        args = (rate, times, self._node, self._held, targets, trunk, pid, local, legs, gains)
        packed = pack(args + self._law_args(delay))
        return self._packed_entry(node_tick_packed, 0, packed), packed

    def _packed_entry(self, kernel, *example):
        """``kernel``'s compiled code for the types of ``example``: a tick (the control ticks) or
        nothing (the state check), then packed arguments, whose type (that of what they hold) is
        the key."""
        return self._typed(kernel, (kernel, example[-1]._numba_type_), example)

    def _law_args(self, delay) -> tuple:
        """``control_tick``'s arguments after (targets, trunk, k, gains): the state contract's base
        orientation, the latency line, the feed-forward, the command and its joint ids."""
        s = self.sim.state
        return (s.quat, s.w_last, s.frame, delay, self._delay_slot, s.feed_forward, s.command, s.leg_ids)

    def _typed(self, kernel, key: tuple, args: tuple):
        """``kernel``'s compiled code for the types of ``args`` (``footsim.compiled.typed_entry``), kept
        under ``key``: whatever decides those types (the state contract's arrays keep theirs; the
        optional ones are None or not)."""
        entry = self._entries.get(key)
        if entry is None:
            entry = self._entries[key] = typed_entry(kernel, *args)
        return entry

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
        self._delay = np.tile(standing, (self._latency, 1)) if self._latency else None
        self._delay_slot[:] = 0
        self._tick = 0
        self._restart_walk_node(standing)
        self._push_end = -1
        if self._push_ticks is not None:
            self.sim.apply_base_force(np.zeros(3))
            self._next_push = self._push_ticks[0]  # the first push one interval after the start
        self.sim.advance(self.settle_ticks * self.substeps)  # let the contacts settle
        return self.planar_pose()

    #: Frames while a double step runs (video, :class:`~footsim.backends.base.FrameHook`); None:
    #: no frames, and ``execute`` runs exactly the code it runs without a recorder.
    frame_hook: FrameHook | None = None

    def execute(self, double_step: DoubleStep) -> StepResult:
        if self._sim_dirty:  # per-step physics terms drawn since the last step
            self._apply_sim_randomization(None)
        hook = self.frame_hook
        before = self.engine.feet if hook is not None else None
        trajectory = self.engine.double_step(double_step)
        if hook is not None:
            due = [hook.begin(self.control_dt, self._commanded_footsteps(before, trajectory))]
        self._max_tilt = 0.0  # updated by every _status() check of this step
        fell = collided = stopped = False
        error = None
        check = self.contact_check_every
        watch_contacts = bool(self.scene.all_obstacles)  # type: ignore[union-attr]  # reset() set the scene
        done = unreachable = 0  # ticks run in earlier parts (a phase reset re-plans the rest)
        while True:
            ticks, n_ticks, ended = 0, len(trajectory), None
            if not n_ticks:  # a phase reset ended the call's last half step: no ticks left
                break
            run = self._ticks(trajectory)
            if hook is not None:  # the same runs of ticks, cut where a frame is due
                run = _filmed(run, hook, done, due)
            while ticks < n_ticks:  # runs of `check` ticks, the checks between them
                start, ticks = ticks, min(ticks + check, n_ticks)
                ended = run(start, ticks)
                if ended is not None:  # a phase reset after tick `ended`
                    ticks = ended + 1
                    break
                if ticks % check == 0:
                    error, fell = self._status()
                    if error is not None or fell:
                        break
                    if watch_contacts and not collided and self.sim.obstacle_contact():
                        collided = True
                        if self.collision_ends_episode:
                            stopped = True
                            break
            planned = n_ticks if ended is None else ticks
            unreachable += planned - int(np.count_nonzero(trajectory.solve(planned)[1][:planned]))
            done += ticks
            if ended is None or error is not None or fell or stopped:
                break
            trajectory = self.engine.end_step(trajectory, ended)
        ticks = done
        if error is None and not fell:
            error, fell = self._status()
        pose = self.planar_pose() if error is None else Pose2D(math.nan, math.nan, math.nan)
        info: dict[str, object] = {
            "foot_interference": trajectory.interfered,
            "ik_unreachable_ticks": unreachable,
        }
        if self.randomization_detail:
            info["randomization_detail"] = dict(self.randomization_detail)
        return StepResult(
            pose=pose,
            duration_s=ticks * self.control_dt,
            feet=trajectory.feet,
            executed=trajectory.executed,
            collided=collided,
            sim_error=error,
            info=info,
            tilt=self._tilt if error is None else (0.0, 0.0),
            max_tilt=self._max_tilt if error is None else 0.0,
        )

    def _commanded_footsteps(self, before, trajectory: WalkTrajectory) -> tuple[Pose2D, Pose2D]:
        """Where this double step's two put-downs are commanded (right, then left), in the world:
        the engine's planned landings (its odometry frame) moved by the offset between the
        engine's navigation frame at the step's start and the base's true planar pose."""
        frame = self.planar_pose().compose(before.nav_pose.inverse())
        return frame.compose(trajectory.feet.right), frame.compose(trajectory.feet.left)

    @property
    def tick(self) -> int:
        """Control ticks since the last reset."""
        return self._tick

    # -- truth ----------------------------------------------------------------------------
    def planar_pose(self) -> Pose2D:
        """The base projected on the ground: (x, y, yaw of the trunk's x axis)."""
        position, rotation = self.sim.base_pose()
        return Pose2D(float(position[0]), float(position[1]), math.atan2(rotation[1, 0], rotation[0, 0]))

    def _fallen(self) -> bool:
        return self._status()[1]

    def _status(self) -> tuple[str | None, bool]:
        """``(sim error or None, fallen)``; also records the fused roll/pitch.  While all is well
        one compiled call over the state contract does it (``control.state_ok``: the same values
        as :meth:`_full_status`); otherwise the full check names the problem."""
        s = self.sim.state
        if not s.live:
            self.sim.read_state(velocity=True)
        check, state, packed = self._check
        if state is not s:  # the arguments are the contract's arrays: packed once per state
            packed = pack(s.check_args(self.out_of_bounds, self._tilt_buffer))
            check = self._packed_entry(state_ok_packed, packed)
            self._check = check, s, packed
        if check(packed):
            roll, pitch = self._tilt_buffer.tolist()
            return None, self._record_tilt(roll, pitch)
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
        """Run the engine's stop sequence (back to standing, open loop); returns its duration [s]."""
        trajectory = self.engine.stop()
        self._ticks(trajectory, stabilized=False)(0, len(trajectory))
        self.trunk_pid.reset()  # the next walk starts without the old I and D state
        return len(trajectory) * self.control_dt

    def _restart_walk_node(self, standing: np.ndarray) -> None:
        """The walk node's state at reset: engine update 0 at engine time 0 = the standing pose."""
        self.trunk_pid.reset()
        self._node[:] = 0.0
        self._held[:] = 0.0
        self._held[:12] = standing
        self._held[12 + 2], self._held[12 + 4] = self.walk_current.trunk_height, self.walk_current.trunk_pitch

    def hold(self, seconds: float) -> None:
        """Keep the current joint targets for a while (used by the walk checks)."""
        self.sim.advance(int(round(seconds / self.control_dt)) * self.substeps)

    def render(self, overlay: RenderOverlay | None = None) -> np.ndarray | None:
        return self.sim.render(overlay, *self.render_size, self.camera, self.planar_pose())

    def close(self) -> None:
        self._entries.clear()
        self._check = (None, None, None)  # its pack holds the sim's state arrays
        self.sim.close()
