"""The quintic walk engine: footstep (or velocity) orders → leg joint trajectories.

Behaviour follows the Bit-Bots / Rhoban *Quintic Walk* (thesis 3.3, ``shared/FACTS.md``);
the implementation is our own, numpy (no simulator); the foot-overlap band of the swing-path
check is the compiled kernel the footstep placement uses (:mod:`footsim.walk.kernels`).

* The walk phase runs over [0, 1) per double step; phase < 0.5 is left support, so the right
  foot flies first (``DoubleStep.first``), then the left foot.
* Each half step starts with double support (``double_support_ratio`` of the half period),
  then single support.  The flying foot holds x/y/yaw through double support, lifts to
  ``foot_rise`` at ``foot_apex_phase`` of single support (held for ``foot_z_pause``, the sole
  pitched by ``foot_apex_pitch``), may overshoot the target by ``foot_overshoot_ratio`` of the
  step at ``foot_overshoot_phase``, and is put down on the target at ``foot_put_down_phase``
  (``foot_put_down_z_offset`` above it, then lowered).  The put-down target always comes from
  :meth:`FootstepGeometry.landing` (clipping and foot–foot interference live there only).
* The trunk follows splines towards "apex" points that are shifted in time by
  ``trunk_phase`` (``first_step_trunk_phase`` in the start movement and start step): laterally
  it swings towards the support foot by ``trunk_swing`` × half the lateral foot offset and holds
  there for ``trunk_pause`` of a half step; forward it keeps pace with the feet, ahead of the
  support foot by ``trunk_x_offset`` (+ coefficients × step x and |step yaw|); its height is ``trunk_height``
  over the support foot and dips by ``trunk_z_movement`` while the weight moves between the
  feet; pitch = ``trunk_pitch`` + coefficients × step x and |step yaw|; yaw = mean of the feet.
* Splines live in the support-foot frame and are rebuilt at every half-step boundary in the new
  support frame, starting from the previous trunk spline's position, velocity and
  acceleration (C2 hand-over).  Feet start and end every half step at rest, so they are C2 too.
* States: IDLE → START_MOVEMENT (a trunk-only half cycle) → START_STEP → WALKING;
  STOP_STEP → STOP_MOVEMENT → IDLE.
* Phase reset: :meth:`QuinticWalk.end_step` ends a step early where the flying foot touched down
  and plans the rest of the call from there (the 3D driver calls it on foot contact).

Timing.  The engine runs at ``control_dt`` (the backend's control period; ``WalkParams.engine_freq``,
the Bit-Bots' walk-node rate, is the 3D driver's: it holds the targets between updates).  A double step lasts exactly
``n = round(1 / (freq · control_dt))`` ticks: the walk period is quantised to a whole number of
ticks, so the engine's effective frequency is ``1 / (n · control_dt)`` (``engine.freq``; for the
defaults at 500 Hz, 255 ticks = 0.510 s vs 1/freq = 0.50935 s, −0.13 %).  The phase advances
``control_dt · engine.freq`` per tick and returns to exactly 0 after each double step, so
durations never drift.  The half-step boundary sits at ``n/2`` ticks (between two ticks when
``n`` is odd — splines are evaluated at exact times, so nothing is lost).  The start movement
takes ``ceil(n/2)`` ticks so every call returns whole ticks.

Tick convention: a trajectory's tick ``k`` holds the targets for the end of the k-th control
interval, so the last tick of a double step is the put-down instant of the second foot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property

import numpy as np

from footsim.geometry import Pose2D, mean_pose, wrap_angles
from footsim.walk import kernels
from footsim.walk.footsteps import DoubleStep, FeetState, Footstep, FootstepGeometry, Side
from footsim.walk.ik import LEG_JOINT_NAMES, IkLegs, LegGeometry, ik_legs, legs_ik, legs_ik_tick, legs_ik_ticks
from footsim.walk.params import WalkParams
from footsim.walk.spline import knots_state, sample_positions

__all__ = ["LEG_JOINT_NAMES", "QuinticWalk", "WalkState", "WalkTrajectory"]

DEFAULT_LEG = LegGeometry()  # Wolfgang-OP's leg (FACTS.md), the engine's default
ORIGIN = Pose2D()


class WalkState(IntEnum):
    IDLE = 0
    START_MOVEMENT = 1
    START_STEP = 2
    WALKING = 3
    STOP_STEP = 4
    STOP_MOVEMENT = 5


# Pose channel order, for feet and trunk alike.
X, Y, Z, ROLL, PITCH, YAW = range(6)
# Channels that move and get splines: the soles never roll (the flying sole pitches by
# foot_apex_pitch) and the trunk never rolls, so the roll channels are constant zero and are not
# evaluated.  Index arrays: numpy indexes with them without converting a list at every call.
_FOOT_CHANNELS = np.array([X, Y, Z, PITCH, YAW])
_TRUNK_CHANNELS = np.array([X, Y, Z, PITCH, YAW])
# Swing-path clearance: interior samples of the planar path checked against the support foot,
# and the largest outward detour [m] the flying foot may take around it.
_SWEEP_SAMPLES = np.linspace(0.0, 1.0, 25)[1:-1]
_MAX_DETOUR = 0.1
# The arrays of a trajectory without ticks (t, phase, support, state, local and support poses):
# shared, as nothing can be written into an array without elements.
_EMPTY = (
    np.zeros(0),
    np.zeros(0),
    np.zeros(0, dtype=bool),
    np.zeros(0, dtype=np.int8),
    np.zeros((3, 6, 0)),
    np.zeros((3, 0)),
)
# The trunk's hand-over state: (position, velocity, acceleration) of each of the six channels, in
# Python floats (the handful of operations per half step cost less on floats than on numpy arrays).
TrunkState = list[tuple[float, float, float]]


@dataclass(frozen=True)
class WalkTrajectory:
    """Every control tick of one engine call (a double step, possibly with its start; or a stop).

    Poses are ``(x, y, z, roll, pitch, yaw)`` of the sole frames and the trunk (base) frame in
    the engine's odometry frame (the frame the feet were placed in at :meth:`QuinticWalk.reset`;
    z = 0 is the ground), yaw wrapped to (−π, π].  They are computed from the support-frame poses
    on first access: the 3D driver needs only the joint targets and the trunk's roll and pitch
    (:attr:`trunk_in_support`), which no frame change about z alters.

    The joint targets too are computed on first need, a half step at a time (:meth:`solve`): a
    phase reset (:meth:`QuinticWalk.end_step`) re-plans the rest of the call, so the 3D driver
    solves only the half steps it reaches.
    """

    dt: float
    t: np.ndarray  # (n,) engine time at each tick [s]
    phase: np.ndarray  # (n,) walk phase in [0, 1) at each tick
    support: np.ndarray  # (n,) bool: True = left support (phase < 0.5)
    state: np.ndarray  # (n,) WalkState of the half step each tick belongs to
    executed: DoubleStep | None  # the double step actually placed (clipped / interference); None for a stop
    feet: FeetState  # planar feet after the call
    interfered: int = 0  # footsteps shortened by foot–foot interference
    # (3, 6, n): left sole, right sole, trunk in each tick's support-sole frame; (3, n) that frame
    # (x, y, theta) in the odometry frame
    local_poses: np.ndarray = field(default_factory=lambda: np.zeros((3, 6, 0)), repr=False)
    support_poses: np.ndarray = field(default_factory=lambda: np.zeros((3, 0)), repr=False)
    # The leg IK's legs (QuinticWalk.ik_legs) and where each half step's ticks end (the IK's parts)
    legs: IkLegs | None = field(default=None, repr=False)
    half_step_ends: tuple[int, ...] = ()

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @cached_property
    def _ik(self) -> tuple[np.ndarray, np.ndarray, list[int]]:
        # The joint targets, reachability and how many ticks are solved so far.
        n = len(self)
        return np.empty((n, 12)), np.empty(n, dtype=np.bool_), [0]

    def solve(self, stop: int) -> tuple[np.ndarray, np.ndarray, int]:
        """The leg IK of every tick before ``stop``, run for the half steps not solved yet.
        Returns ``(joint targets (n, 12), reachable (n,), solved)``: the rows before ``solved`` (≥
        ``stop``, the end of a half step) are final, the later ones not computed yet."""
        joints, reachable, solved = self._ik
        if stop > solved[0]:
            assert self.legs is not None  # every trajectory with ticks has them
            end = next(end for end in self.half_step_ends if end >= stop)
            legs_ik_ticks(self.local_poses, solved[0], end, self.legs, joints, reachable)
            solved[0] = end
        return joints, reachable, solved[0]

    @property
    def joint_targets(self) -> np.ndarray:
        """(n, 12) radians, LEG_JOINT_NAMES order."""
        return self.solve(len(self))[0]

    @property
    def reachable(self) -> np.ndarray:
        """(n,) bool: the IK reached both feet within the joint limits."""
        return self.solve(len(self))[1]

    @property
    def duration(self) -> float:
        return len(self) * self.dt

    @property
    def trunk_in_support(self) -> np.ndarray:
        """(n, 6) trunk pose in each tick's support-sole frame (roll and pitch as in :attr:`trunk`)."""
        return self.local_poses[2].T

    @cached_property
    def _odometry_poses(self) -> np.ndarray:
        # Rotate about z by the support sole's heading and translate.
        local = self.local_poses
        sx, sy, stheta = self.support_poses
        c, s = np.cos(stheta), np.sin(stheta)
        world = local.copy()
        world[:, X] = sx + c * local[:, X] - s * local[:, Y]
        world[:, Y] = sy + s * local[:, X] + c * local[:, Y]
        world[:, YAW] = wrap_angles(local[:, YAW] + stheta)
        return world

    @property
    def left_foot(self) -> np.ndarray:
        """(n, 6) left sole pose in the odometry frame."""
        return self._odometry_poses[0].T

    @property
    def right_foot(self) -> np.ndarray:
        """(n, 6) right sole pose in the odometry frame."""
        return self._odometry_poses[1].T

    @property
    def trunk(self) -> np.ndarray:
        """(n, 6) trunk (base) pose in the odometry frame."""
        return self._odometry_poses[2].T


@dataclass
class _HalfStep:
    """One half step's plan: everything needed to build its splines."""

    kind: WalkState
    support: Side
    support_pose: Pose2D  # support sole in the odometry frame
    duration: float
    last: Pose2D  # flying foot at the start, in the support frame
    landing: Pose2D  # flying foot at put-down, in the support frame
    tick_times: np.ndarray  # local times of this half step's ticks, in (0, duration]
    phase_start: float  # walk phase at local time 0
    phase_span: float  # phase advanced over `duration`
    last_z: float = 0.0  # flying foot's height at the start, in the support frame (after a phase reset)


@dataclass(frozen=True)
class _CallLayout:
    """The tick tables shared by every engine call with the same sequence of half steps (kind and
    support side; they decide each half step's tick times and phases): built once per engine and
    sequence.

    The splines of a call are sampled as one table, ``channels per half step`` rows per half step
    (the flying foot's, then the trunk's channels), each row at its half step's tick times padded
    to the longest half step; ``sampled`` and ``local`` map it (flat indices) to the call's
    support-frame poses ``(3, 6, n)`` (left sole, right sole, trunk).
    """

    sample_times: np.ndarray  # (half steps × channels per half step, most ticks)
    sampled: np.ndarray  # flat indices into the sampled table of every pose entry that moves ...
    local: np.ndarray  # ... and where each goes in the flat (3, 6, n) local poses
    half_step: np.ndarray  # (n,) index of the half step each tick belongs to
    ticks: np.ndarray  # (n,) 1 … n
    phase: np.ndarray  # (n,) walk phase in [0, 1)
    state: np.ndarray  # (n,) WalkState (int8)
    half_step_ends: tuple[int, ...]  # the tick after each half step's last

    @classmethod
    def of(cls, plans: list[_HalfStep]) -> _CallLayout:
        counts = [len(plan.tick_times) for plan in plans]
        n, width = sum(counts), max(counts)
        times = np.empty((len(plans), width))
        for i, plan in enumerate(plans):
            times[i, : counts[i]] = plan.tick_times
            times[i, counts[i] :] = plan.duration  # padding, never copied out
        sampled, local = [], []
        begin = 0
        for i, (plan, count) in enumerate(zip(plans, counts)):
            flying = 0 if plan.support is Side.RIGHT else 1
            poses = [(flying, c) for c in _FOOT_CHANNELS] + [(2, c) for c in _TRUNK_CHANNELS]
            for row, (pose, channel) in enumerate(poses, start=i * len(poses)):
                sampled.append(row * width + np.arange(count))
                local.append((pose * 6 + channel) * n + begin + np.arange(count))
            begin += count
        phase = np.concatenate([plan.phase_start + plan.phase_span / plan.duration * plan.tick_times for plan in plans])
        phase[phase >= 1.0] -= 1.0
        tables = (
            np.repeat(times, len(_FOOT_CHANNELS) + len(_TRUNK_CHANNELS), axis=0),
            np.concatenate(sampled),
            np.concatenate(local),
            np.repeat(np.arange(len(plans)), counts),
            np.arange(1, n + 1),
            phase,
            np.repeat(np.array([int(plan.kind) for plan in plans], dtype=np.int8), counts),
        )
        for table in tables:
            table.setflags(write=False)  # shared by every call of this layout
        return cls(*tables, tuple(np.cumsum(counts).tolist()))


def _transform_trunk_state(state: TrunkState, frame: Pose2D) -> TrunkState:
    """Re-express a trunk pos/vel/acc state (six channels) in ``frame`` (a planar pose in the old frame).

    The frames are fixed relative to each other, so velocities and accelerations just rotate;
    rpy under a rotation about z only changes yaw (Rz(−θ)·Rz(y)Ry(p)Rx(r) = Rz(y−θ)Ry(p)Rx(r)).
    """
    c, s = math.cos(frame.theta), math.sin(frame.theta)
    (x, vx, ax), (y, vy, ay), z, roll, pitch, (yaw, v_yaw, a_yaw) = state
    x, y = x - frame.x, y - frame.y
    return [
        (c * x + s * y, c * vx + s * vy, c * ax + s * ay),
        (-s * x + c * y, -s * vx + c * vy, -s * ax + c * ay),
        z,
        roll,
        pitch,
        (yaw - frame.theta, v_yaw, a_yaw),
    ]


def _overlap_bands(x: np.ndarray, theta: np.ndarray, half_l: float, half_w: float) -> tuple[np.ndarray, np.ndarray]:
    """``footsteps._overlap_band_y`` per sample: the y interval where a foot at (x, y, theta)
    overlaps an identical foot at the origin; NaN where no y overlaps.  The band is the compiled
    kernel ``FootstepGeometry.landing`` uses (:func:`footsim.walk.kernels.overlap_band`), looped in
    compiled code: the numpy version of the four axes cost more than the rest of a double step."""
    lo, hi = np.empty(x.shape), np.empty(x.shape)
    kernels.overlap_bands(
        np.ascontiguousarray(x, dtype=float), np.cos(theta), np.sin(theta), float(half_l), float(half_w), lo, hi
    )
    return lo, hi


def _check_swing_timing(p: WalkParams) -> None:
    """The flying foot's knots (shares of single support) must come in order: lift, the apex
    (held for ``foot_z_pause`` around ``foot_apex_phase``), the overshoot, put-down."""
    if p.foot_apex_phase >= p.foot_put_down_phase:
        raise ValueError(
            f"WalkParams.foot_apex_phase ({p.foot_apex_phase}) must come before "
            f"foot_put_down_phase ({p.foot_put_down_phase})"
        )
    rise, fall = p.foot_apex_phase - 0.5 * p.foot_z_pause, p.foot_apex_phase + 0.5 * p.foot_z_pause
    if p.foot_z_pause > 0 and not (0.0 < rise and fall < p.foot_put_down_phase):
        raise ValueError(
            f"WalkParams.foot_z_pause ({p.foot_z_pause}) around foot_apex_phase ({p.foot_apex_phase}) must end "
            f"after lift-off (0) and before foot_put_down_phase ({p.foot_put_down_phase})"
        )
    if p.foot_overshoot_phase < 1.0 and not p.foot_overshoot_phase * p.foot_put_down_phase > fall:
        raise ValueError(
            f"WalkParams.foot_overshoot_phase ({p.foot_overshoot_phase}) × foot_put_down_phase "
            f"({p.foot_put_down_phase}) must come after the apex (foot_apex_phase {p.foot_apex_phase}"
            f" + half foot_z_pause {p.foot_z_pause}), or be 1 (no overshoot)"
        )
    if p.foot_put_down_z_offset > 0 and p.foot_put_down_phase >= 1.0:
        raise ValueError(
            f"WalkParams.foot_put_down_z_offset ({p.foot_put_down_z_offset}) needs foot_put_down_phase < 1 "
            f"(got {p.foot_put_down_phase}): the rest of single support lowers the foot to the ground"
        )


def _paused_knots(t: float, position: float, velocity: float, pause: float, min_gap: float) -> list:
    """Knots holding a lateral trunk apex from ``t - pause`` to ``t + pause``: the apex position at
    the apex velocity (zero in straight walking, where the trunk stands still laterally); knots
    closer than ``min_gap`` to the half step's start are left out."""
    knots = [(t - pause, position - velocity * pause, velocity), (t + pause, position + velocity * pause, velocity)]
    return [knot for knot in knots if knot[0] > min_gap]


def _constant_knots(value: float, duration: float) -> list:
    return [(0.0, value), (duration, value)]


class QuinticWalk:
    """Quintic-spline walk engine with analytic leg IK.  See the module docstring."""

    def __init__(
        self,
        params: WalkParams,
        geometry: FootstepGeometry,
        leg: LegGeometry = DEFAULT_LEG,
        control_dt: float = 1.0 / 500.0,
        joint_limits=None,
    ):
        if not (math.isfinite(control_dt) and control_dt > 0):
            raise ValueError(f"control_dt must be a positive number, got {control_dt!r}")
        if abs(geometry.foot_distance - params.foot_distance) > 1e-9:
            raise ValueError(
                f"WalkParams.foot_distance ({params.foot_distance}) and FootstepGeometry.foot_distance "
                f"({geometry.foot_distance}) differ; build the geometry with the walk's foot distance"
            )
        _check_swing_timing(params)
        self.params = params
        self.geometry = geometry
        self.leg = leg
        self.control_dt = float(control_dt)
        n = int(round(1.0 / (params.freq * control_dt)))
        if n < 4:
            raise ValueError(f"control_dt {control_dt} is too coarse for freq {params.freq}: {n} ticks per double step")
        self.ticks_per_double_step = n
        self.double_step_duration = n * self.control_dt
        self.freq = 1.0 / self.double_step_duration  # effective (tick-quantised) frequency
        self.half_period = 0.5 * self.double_step_duration
        self.start_ticks = (n + 1) // 2
        # Local tick times of the two half steps of a double step (ticks k = 1..n at k·dt; those
        # at t <= T/2 belong to the first half): the same every double step, so computed once.
        times = np.arange(1, n + 1) * self.control_dt
        first = times <= self.half_period + 1e-12
        self._half_tick_times = (times[first], times[~first] - self.half_period)
        for local in self._half_tick_times:
            local.setflags(write=False)  # shared by every half step's plan
        self._layouts: dict[tuple[tuple[WalkState, Side], ...], _CallLayout] = {}
        self._tick_times: dict[int, np.ndarray] = {}  # _plan's local tick times by number of ticks
        if joint_limits is None:
            self._limits = None
        else:
            lim = np.asarray(joint_limits, dtype=float)
            if lim.shape != (12, 2) or not np.all(lim[:, 0] <= lim[:, 1]):
                raise ValueError("joint_limits must be (12, 2) [lower, upper] in LEG_JOINT_NAMES order")
            self._limits = lim
        self.reset()

    # --- state ---------------------------------------------------------------------------

    def reset(self, pose: Pose2D = ORIGIN) -> None:
        """Stand still (IDLE) with the feet at rest around ``pose`` (the navigation frame)."""
        self._state = WalkState.IDLE
        self._tick = 0
        self._feet = self.geometry.initial_feet(pose)
        self._last_call: tuple | None = None  # the last call's trajectory and plans (end_step)
        # The trunk state is always kept in the frame of the next half step's support foot; the
        # next half step from IDLE is the start movement, in right support.
        self._trunk: TrunkState = [tuple(row) for row in self._standing_trunk_state(Side.RIGHT).tolist()]

    @property
    def state(self) -> WalkState:
        return self._state

    @property
    def feet(self) -> FeetState:
        return self._feet

    @property
    def time(self) -> float:
        return self._tick * self.control_dt

    @property
    def phase(self) -> float:
        """Calls always end on a double-step boundary, where the phase is 0."""
        return 0.0

    # --- orders --------------------------------------------------------------------------

    def footsteps_from_velocity(self, vx: float, vy: float, omega: float) -> DoubleStep:
        """The double step a velocity order asks for.

        Per step: ``v / (2 · freq) · multiplier`` (``freq`` = the engine's effective frequency),
        clipped to the step limits.  Forward steps go on both feet.  Lateral steps and turns go
        only on the step whose flying foot is on the side of the motion (the outward step); the
        other foot returns to its resting pose (y = 0, θ = 0), as in the original engine, so
        the feet never cross or toe in.  Consequently the realised lateral speed and turn rate
        are half the order times the multiplier (set ``y_/yaw_speed_multiplier`` = 2 to track
        them one-to-one).
        """
        values = (vx, vy, omega)
        if not all(isinstance(v, (int, float, np.floating, np.integer)) and math.isfinite(v) for v in values):
            raise ValueError(f"velocity order must be finite numbers, got {values!r}")
        p = self.params
        scale = 1.0 / (2.0 * self.freq)
        x, y, theta = self.geometry.limits.clip(
            vx * scale * p.x_speed_multiplier, vy * scale * p.y_speed_multiplier, omega * scale * p.yaw_speed_multiplier
        )
        right = Footstep(x, min(y, 0.0), min(theta, 0.0))  # right foot flies first
        left = Footstep(x, max(y, 0.0), max(theta, 0.0))
        return DoubleStep(right, left)

    def velocity_double_step(self, vx: float, vy: float, omega: float) -> WalkTrajectory:
        return self.double_step(self.footsteps_from_velocity(vx, vy, omega))

    def double_step(self, double_step: DoubleStep) -> WalkTrajectory:
        """All control ticks of one double step (preceded by the start movement when IDLE)."""
        values = double_step.as_array().tolist()
        if not all(map(math.isfinite, values)):  # six floats: cheaper than numpy's isfinite().all()
            raise ValueError(f"double step contains NaN or inf: {values}")
        plans = []
        feet = self._feet
        if self._state == WalkState.IDLE:
            # Trunk-only half cycle in right support (phase 0.5 → 1), feet still.
            duration = self.start_ticks * self.control_dt
            left_in_right = feet.right.relative(feet.left)
            plans.append(
                self._plan(WalkState.START_MOVEMENT, Side.RIGHT, feet, left_in_right, left_in_right, duration, 0.5, 0.5)
            )
            first_kind = WalkState.START_STEP
        else:
            first_kind = WalkState.WALKING
        executed = []
        interfered = 0
        half_plans = []
        for i, (flying, step) in enumerate(double_step.steps()):
            support = flying.other
            landing, done, hit = self.geometry.landing(flying, step)
            executed.append(done)
            interfered += int(hit)
            last = feet.foot(support).relative(feet.foot(flying))
            kind = first_kind if i == 0 else WalkState.WALKING
            half_plans.append((kind, support, feet, last, landing, 0.5 * i))
            feet = feet.with_foot(flying, feet.foot(support).compose(landing))
        plans += self._half_step_plans(half_plans)
        trajectory = self._run(plans, DoubleStep(executed[0], executed[1]), feet, interfered)
        self._state = WalkState.WALKING
        return trajectory

    def stop(self) -> WalkTrajectory:
        """Stop step (right foot back beside the left) and stop movement, back to IDLE.

        Returns an empty trajectory when already standing.
        """
        if self._state == WalkState.IDLE:
            return self._empty_trajectory()
        feet = self._feet
        landing, _, _ = self.geometry.landing(Side.RIGHT, Footstep())
        last = feet.left.relative(feet.right)
        after = feet.with_foot(Side.RIGHT, feet.left.compose(landing))
        left_in_right = after.right.relative(after.left)
        plans = self._half_step_plans(
            [
                (WalkState.STOP_STEP, Side.LEFT, feet, last, landing, 0.0),
                (WalkState.STOP_MOVEMENT, Side.RIGHT, after, left_in_right, left_in_right, 0.5),
            ]
        )
        trajectory = self._run(plans, None, after, 0)
        self._state = WalkState.IDLE
        return trajectory

    def end_step(self, trajectory: WalkTrajectory, k: int) -> WalkTrajectory:
        """Phase reset: the half step of ``trajectory``'s tick ``k`` ends at that tick (the flying
        foot touched the ground early) and the rest of the call is planned again from there.

        ``trajectory`` must be this engine's last call (a double step) and tick ``k`` in one of
        its stepping half steps.  The flying sole's pose at tick ``k`` becomes the new support
        sole: its x, y and yaw place it, its height above the old support plane lifts the new
        support frame (the soles stay level in it), and the trunk's position, velocity and
        acceleration at that instant carry over into the new frame.  When that half step was
        the call's first, its second half step follows at once, in full, with the planned step
        relative to the new support foot; otherwise the call ends.  Returns the ticks after
        ``k`` (empty if the call ended); ``executed`` and ``feet`` of the returned trajectory are
        the call's, with the early foot where it landed.
        """
        if self._last_call is None or self._last_call[0] is not trajectory:
            raise ValueError("end_step needs the engine's last double step")
        _, plans, channels, layout = self._last_call
        if not 0 <= k < len(trajectory):
            raise ValueError(f"tick {k} is outside the trajectory's {len(trajectory)} ticks")
        h = int(layout.half_step[k])
        plan = plans[h]
        if plan.kind not in (WalkState.START_STEP, WalkState.WALKING) or trajectory.executed is None:
            raise ValueError(f"tick {k} is in a {plan.kind.name} half step: no flying foot to end it")
        local_time = float(plan.tick_times[k - (layout.half_step_ends[h - 1] if h else 0)])
        flying = plan.support.other
        foot_x, foot_y, height, _, _, foot_yaw = trajectory.local_poses[0 if flying is Side.LEFT else 1, :, k].tolist()
        touchdown = Pose2D(foot_x, foot_y, foot_yaw)
        # The trunk's state at the touchdown (support frame), then in the new support frame.
        trunk = channels[h * 10 + 5 : h * 10 + 10]  # after the flying foot's five channels
        x, y, z, pitch, yaw = (knots_state(knots, local_time) for knots in trunk)
        state = _transform_trunk_state([x, y, z, (0.0, 0.0, 0.0), pitch, yaw], touchdown)
        state[Z] = (state[Z][0] - height, state[Z][1], state[Z][2])
        placed = plan.support_pose.compose(touchdown)
        steps = list(trajectory.executed)
        i = 1 if plan.phase_start >= 0.5 else 0  # which step of the double step this half step is
        offset = self.geometry.foot_distance if flying is Side.LEFT else -self.geometry.foot_distance
        steps[i] = Footstep(touchdown.x, touchdown.y - offset, touchdown.theta)
        feet = self._feet.with_foot(flying, placed) if i == 1 else None
        self._tick += k + 1 - len(trajectory)
        self._trunk = state
        if i == 1:  # the call ends here
            self._feet = feet  # type: ignore[assignment]
            self._last_call = None
            return self._empty_trajectory(DoubleStep(steps[0], steps[1]), trajectory.interfered)
        second = plans[h + 1]
        before = FeetState(*(placed if side is flying else plan.support_pose for side in (Side.LEFT, Side.RIGHT)))
        rest = self._plan(
            second.kind, flying, before, touchdown.inverse(), second.landing, self.half_period, 0.5, 0.5, -height
        )
        after = before.with_foot(plan.support, placed.compose(second.landing))
        return self._run([rest], DoubleStep(steps[0], steps[1]), after, trajectory.interfered)

    def trunk_shifted_targets(self, trajectory: WalkTrajectory, k: int, dx: float, dy: float) -> np.ndarray:
        """Tick ``k``'s 12 joint targets with the trunk moved by (``dx``, ``dy``) [m] in the support
        sole's frame (the trunk PID's correction); the IK clamps them to the joint limits."""
        q = np.empty(12)
        legs_ik_tick(trajectory.local_poses, k, dx, dy, *self.ik_legs, q)
        return q

    @cached_property
    def ik_legs(self) -> IkLegs:
        """This engine's legs and joint limits as the compiled IK takes them (``ik.ik_legs``)."""
        return ik_legs(self.leg, self._limits)

    def standing_joint_targets(self) -> np.ndarray:
        """The 12 joint angles (LEG_JOINT_NAMES order) of the standing, walk-ready pose."""
        trunk = self._standing_trunk_state(Side.LEFT)[:, :1]  # (6, 1) in the left sole frame
        right = np.zeros((6, 1))
        right[Y] = -self.params.foot_distance
        feet_local = {Side.LEFT: np.zeros((6, 1)), Side.RIGHT: right}
        q, _ = self._leg_joints(trunk, feet_local[Side.LEFT], feet_local[Side.RIGHT])
        return q[0]

    # --- planning ------------------------------------------------------------------------

    def _plan(self, kind, support, feet, last, landing, duration, phase_start, phase_span, last_z=0.0) -> _HalfStep:
        n_ticks = int(round(duration / self.control_dt))
        tick_times = self._tick_times.get(n_ticks)
        if tick_times is None:  # the same few lengths every call: computed once each
            tick_times = self._tick_times[n_ticks] = np.arange(1, n_ticks + 1) * self.control_dt
            tick_times.setflags(write=False)  # shared by every half step's plan of this length
        return _HalfStep(
            kind=kind,
            support=support,
            support_pose=feet.foot(support),
            duration=duration,
            last=last,
            landing=landing,
            tick_times=tick_times,
            phase_start=phase_start,
            phase_span=phase_span,
            last_z=last_z,
        )

    def _half_step_plans(self, halves) -> list[_HalfStep]:
        """Two half steps filling exactly one double step (n ticks)."""
        return [
            _HalfStep(kind, support, feet.foot(support), self.half_period, last, landing, local, phase_start, 0.5)
            for (kind, support, feet, last, landing, phase_start), local in zip(halves, self._half_tick_times)
        ]

    # --- splines -------------------------------------------------------------------------

    def _standing_trunk_state(self, support: Side) -> np.ndarray:
        """Trunk (6, 3) pos/vel/acc standing between feet at rest, in ``support``'s frame."""
        other = Pose2D(0.0, support.other.sign * self.params.foot_distance, 0.0)
        return self._standing_trunk_between(Pose2D(), other)

    def _standing_trunk_between(self, support: Pose2D, other: Pose2D) -> np.ndarray:
        p = self.params
        mid = mean_pose(support, other)
        x, y = mid.transform_point(p.trunk_x_offset, p.trunk_y_offset)
        state = np.zeros((6, 3))
        state[:, 0] = (x, y, p.trunk_height, 0.0, p.trunk_pitch, mid.theta)
        return state

    def _trunk_apexes(self, last: Pose2D, landing: Pose2D, swing: float):
        """Trunk targets of a walking half step in the support frame.

        Returns ``(at_support, at_next)``, each six (position, velocity) pairs, one per
        channel (yaw is unused: it follows the feet): the apex over the support foot (time t1)
        and over the next support foot (t1 + half period).  Laterally the trunk stops short of
        each foot: it swings ``swing`` × half the lateral foot offset away from the middle.

        The apex over the next foot is placed in that foot's own frame (offsets rotated by its
        yaw), i.e. where the next rebuild will put its first apex if the foot spacing stays
        the same; in turns this removes most of the retargeting jump at the hand-over.
        """
        p = self.params
        half = self.half_period
        period = 2.0 * half
        pitch = (
            p.trunk_pitch + p.trunk_pitch_p_coef_forward * landing.x + p.trunk_pitch_p_coef_turn * abs(landing.theta)
        )
        half_offset_y = 0.5 * landing.y
        offset_x = (
            p.trunk_x_offset
            + p.trunk_x_offset_p_coef_forward * landing.x
            + p.trunk_x_offset_p_coef_turn * abs(landing.theta)
        )
        at_support = [
            (offset_x, (landing.x - last.x) / period),
            (p.trunk_y_offset + half_offset_y * (1.0 - swing), 0.0),
            (p.trunk_height, 0.0),
            (0.0, 0.0),
            (pitch, 0.0),
            (0.0, 0.0),
        ]
        c, s = math.cos(landing.theta), math.sin(landing.theta)
        offset_y = p.trunk_y_offset - half_offset_y * (1.0 - swing)
        speed = landing.x / half
        at_next = [
            (landing.x + c * offset_x - s * offset_y, c * speed),
            (landing.y + s * offset_x + c * offset_y, s * speed),
            (p.trunk_height, 0.0),
            (0.0, 0.0),
            (pitch, 0.0),
            (0.0, 0.0),
        ]
        return at_support, at_next

    def _apex_time(self, kind: WalkState) -> float:
        """t1: when the trunk is at its apex over the support foot, from the half step's start
        (``first_step_trunk_phase`` in the start movement and the start step, else ``trunk_phase``)."""
        p = self.params
        half = self.half_period
        start = kind in (WalkState.START_MOVEMENT, WalkState.START_STEP)
        trunk_phase = p.start_trunk_phase if start else p.trunk_phase
        time_shift = -0.5 * half + 0.5 * p.double_support_ratio * half + trunk_phase * half
        return half + time_shift

    def _trunk_knots(self, plan: _HalfStep, state: TrunkState, next_plan: _HalfStep | None, foot_yaw: list) -> list:
        """Knots of the trunk's x, y, z, pitch and yaw channels (support frame), from ``state``.

        The trunk yaw is the mean of the two feet's yaws at every instant: half the flying
        foot's yaw spline (the support foot has yaw 0 in its own frame).  Both feet are at rest
        at every half-step boundary, so this hands over C2 like the other channels.
        """
        channels = self._trunk_translation_pitch_knots(plan, state, next_plan)
        channels.append([(knot[0], 0.5 * knot[1]) for knot in foot_yaw])
        return channels

    def _trunk_translation_pitch_knots(self, plan: _HalfStep, state: TrunkState, next_plan: _HalfStep | None) -> list:
        """Knots of the trunk's x, y, z and pitch channels, of Python floats (numpy scalars would
        double the cost of the spline's knot table)."""
        p = self.params
        half = self.half_period
        min_gap = 0.02 * half  # knots closer than this to t = 0 would make needlessly stiff segments
        start = [(0.0, position, velocity, acceleration) for position, velocity, acceleration in state]
        t1 = self._apex_time(plan.kind)

        if plan.kind == WalkState.STOP_MOVEMENT:
            target = self._standing_trunk_between(Pose2D(), plan.landing).tolist()
            return [[start[c], (plan.duration, target[c][0])] for c in (X, Y, Z, PITCH)]

        if plan.kind == WalkState.START_MOVEMENT:
            # Head for the apex the start step will aim at (over the left foot, with the first-step
            # swing gain), expressed in this right-support frame; reached t1 into the start step.
            assert next_plan is not None
            at_support, _ = self._trunk_apexes(
                next_plan.last, next_plan.landing, p.trunk_swing * p.first_step_swing_factor
            )
            target = _transform_trunk_state([(p, v, 0.0) for p, v in at_support], plan.landing.inverse())
            t_target = plan.duration + t1 if plan.duration + t1 > min_gap else plan.duration + t1 + half
            return [[start[c], (t_target, target[c][0], target[c][1])] for c in (X, Y, Z, PITCH)]

        at_support, at_next = self._trunk_apexes(plan.last, plan.landing, p.trunk_swing)
        if plan.kind == WalkState.START_STEP:
            # The first step leans further over its support foot; the next apex is a normal one.
            at_support, _ = self._trunk_apexes(plan.last, plan.landing, p.trunk_swing * p.first_step_swing_factor)
        if plan.kind == WalkState.STOP_STEP:
            # Come to rest standing between the feet instead of swinging over to the next foot.
            at_next = [
                (position, 0.0) for position in self._standing_trunk_between(Pose2D(), plan.landing)[:, 0].tolist()
            ]
        t2 = t1 + half
        pause = 0.5 * p.trunk_pause * half  # half the lateral hold at each apex [s]
        channels = []
        for c in (X, Y, Z, PITCH):
            knots: list[tuple[float, ...]] = [start[c]]  # (t, position[, velocity[, acceleration]])
            if c == PITCH:
                pass  # a new pitch is reached over the whole horizon, not by t1: no violent nods
            elif c == Z and plan.kind != WalkState.STOP_STEP:
                dip = p.trunk_height - p.trunk_z_movement
                for t, value in ((t1 - 0.5 * half, dip), (t1, p.trunk_height), (t1 + 0.5 * half, dip)):
                    if t > min_gap:
                        knots.append((t, value))
            elif c == Y and pause > 0.0:
                for t, (position, velocity) in ((t1, at_support[Y]), (t2, at_next[Y])):
                    knots += _paused_knots(t, position, velocity, pause, min_gap)
                channels.append(knots)
                continue
            elif t1 > min_gap:
                knots.append((t1, at_support[c][0], at_support[c][1]))
            knots.append((t2, at_next[c][0], at_next[c][1]))
            channels.append(knots)
        return channels

    def _foot_knots(self, plan: _HalfStep) -> list:
        """Knots of the flying foot's x, y, z, pitch and yaw channels (support frame).

        Times as shares of single support after double support: the foot lifts at 0, reaches
        ``foot_rise`` at ``foot_apex_phase`` (held for ``foot_z_pause`` around it, with the sole
        pitched by ``foot_apex_pitch``), passes x/y beyond the landing by ``foot_overshoot_ratio``
        of the step at ``foot_overshoot_phase`` × ``foot_put_down_phase``, and is put down at
        ``foot_put_down_phase``, at height ``foot_put_down_z_offset``, lowered to the ground by the
        end of the half step.  The x overshoot is that share of the step's x (the landing in the
        support frame), the y overshoot that share of the y travel (landing − start).
        """
        p = self.params
        last, landing, half = plan.last, plan.landing, plan.duration
        if plan.kind in (WalkState.START_MOVEMENT, WalkState.STOP_MOVEMENT):
            return [_constant_knots(v, half) for v in (last.x, last.y, 0.0, 0.0, last.theta)]
        double_support = p.double_support_ratio * half
        single_support = half - double_support
        lift = double_support > 1e-9  # hold through double support only if it has a length
        put_down = double_support + single_support * p.foot_put_down_phase
        apex = double_support + single_support * p.foot_apex_phase
        settled = put_down < half - 1e-9
        overshoot = double_support + single_support * p.foot_put_down_phase * p.foot_overshoot_phase
        overshoots = put_down - overshoot > 1e-9
        # The apex instants: one, or the two ends of the z pause.
        pause = 0.5 * p.foot_z_pause * single_support
        apexes = [apex - pause, apex + pause] if pause > 0.0 else [apex]

        def planar(start: float, end: float, beyond: float | None = None) -> list:
            knots = [(0.0, start)]
            if lift:
                knots.append((double_support, start))
            if beyond is not None and overshoots:
                knots.append((overshoot, beyond))
            knots.append((put_down, end))
            if settled:
                knots.append((half, end))
            return knots

        def lifted(start: float, top: float, down: float) -> list:
            knots = [(0.0, start)]
            if lift:
                knots.append((double_support, start))
            knots += [(t, top) for t in apexes]
            knots.append((put_down, down))
            if settled:
                knots.append((half, 0.0))
            return knots

        ratio = p.foot_overshoot_ratio
        z = lifted(plan.last_z, p.foot_rise, p.foot_put_down_z_offset)
        pitch = lifted(0.0, p.foot_apex_pitch, 0.0)
        y = planar(last.y, landing.y, landing.y + ratio * (landing.y - last.y))
        if double_support < apex < put_down:
            y = self._swing_detour(y, plan, double_support, put_down, apex)
        x = planar(last.x, landing.x, landing.x + ratio * landing.x)
        return [x, y, z, pitch, planar(last.theta, landing.theta)]

    def _swing_detour(self, y_knots: list, plan: _HalfStep, start: float, end: float, apex: float) -> list:
        """Route the flying foot around the support foot when its straight path would cross it.

        ``FootstepGeometry.landing`` keeps the put-down pose clear of the support foot, but
        between two clear poses the interpolated (x, y, yaw) path can still sweep the turning
        plate over the support foot (e.g. a foot stepping inward and turning after an inward,
        turned step).  In 3D that kicks the support foot.  If any sampled pose of the straight
        path comes closer than the geometry's gap, a y knot at the apex pushes the foot outward
        (on its own side) far enough that every sample clears, up to ``_MAX_DETOUR``.
        """
        last, landing = plan.last, plan.landing
        sign = plan.support.other.sign  # the flying foot's side in the support frame
        g = self.geometry
        # Clear by construction when the flying foot stays laterally farther from the support
        # foot than any overlap can reach (half its width plus the flying plate's half diagonal);
        # y moves monotonically between the two ends, so the ends decide.
        half_l, half_w = 0.5 * (g.foot_length + g.min_foot_gap), 0.5 * (g.foot_width + g.min_foot_gap)
        if min(sign * last.y, sign * landing.y) > half_w + math.hypot(half_l, half_w):
            return y_knots
        u = _SWEEP_SAMPLES
        # All planar channels share one rest-to-rest quintic profile between start and end.
        sigma = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
        xs = last.x + sigma * (landing.x - last.x)
        thetas = last.theta + sigma * (landing.theta - last.theta)
        lo, hi = _overlap_bands(xs, thetas, half_l, half_w)
        edge = hi if sign > 0 else lo
        blocked = ~np.isnan(edge)
        if not blocked.any():
            return y_knots
        times = (start + u * (end - start))[None, :]  # one channel's sample times

        def deficit(knots) -> float:
            ys = sample_positions([knots], times)[0]
            return float(np.max(sign * (edge[blocked] - ys[blocked]), initial=0.0))

        if deficit(y_knots) <= 0.0:
            return y_knots
        span = end - start
        tau = (apex - start) / span
        line = last.y + (landing.y - last.y) * tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        line_v = (landing.y - last.y) * 30.0 * tau**2 * (1.0 - tau) ** 2 / span
        detour, knots = 0.0, y_knots
        for _ in range(6):  # the bump is smaller away from the apex: grow it until every sample clears
            missing = deficit(knots)
            if missing <= 1e-4 or detour >= _MAX_DETOUR:
                break
            detour = min(_MAX_DETOUR, detour + 1.5 * missing + 0.005)
            knots = sorted(y_knots + [(apex, line + sign * detour, line_v)], key=lambda k: k[0])
        return knots

    # --- evaluation ----------------------------------------------------------------------

    def _run(self, plans: list[_HalfStep], executed, feet_after: FeetState, interfered: int) -> WalkTrajectory:
        # Knots of every half step first: each trunk spline starts from the previous one's
        # exact end state (C2 hand-over), computed from its knots in plain floats.  Then one
        # spline holds every channel of every half step and is sampled in a single call, each
        # half step's channels at its own tick times.
        trunk_state = self._trunk
        channels = []
        for i, plan in enumerate(plans):
            next_plan = plans[i + 1] if i + 1 < len(plans) else None
            foot = self._foot_knots(plan)
            trunk = self._trunk_knots(plan, trunk_state, next_plan, foot[-1])
            channels += foot + trunk
            x, y, z, pitch, yaw = (knots_state(knots, plan.duration) for knots in trunk)  # _TRUNK_CHANNELS
            end_state = [x, y, z, (0.0, 0.0, 0.0), pitch, yaw]
            # ... expressed in the next support frame (the flying foot's landing pose).
            trunk_state = _transform_trunk_state(end_state, plan.landing)
        key = tuple((plan.kind, plan.support) for plan in plans)
        layout = self._layouts.get(key)
        if layout is None:
            layout = self._layouts[key] = _CallLayout.of(plans)
        sampled = sample_positions(channels, layout.sample_times)
        self._trunk = trunk_state
        self._feet = feet_after
        self._tick += len(layout.ticks)
        trajectory = self._assemble(layout, plans, sampled, executed, feet_after, interfered)
        self._last_call = (trajectory, plans, channels, layout)
        return trajectory

    def _leg_joints(self, trunk: np.ndarray, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """IK for both legs in one compiled call.  ``trunk``, ``left``, ``right``: (6, n) poses in a common frame."""
        return legs_ik(trunk, left, right, self.leg, self._limits)

    def _assemble(
        self,
        layout: _CallLayout,
        plans: list[_HalfStep],
        sampled: np.ndarray,
        executed,
        feet_after: FeetState,
        interfered: int,
    ) -> WalkTrajectory:
        dt = self.control_dt
        n_total = len(layout.ticks)
        # Local (support-frame) poses, stacked: 0 = left sole, 1 = right sole, 2 = trunk; the
        # support sole is the zero pose of its own frame, the roll channels stay zero.
        local = np.zeros((3, 6, n_total))
        local.put(layout.local, sampled.take(layout.sampled))
        support_pose = np.array([plan.support_pose for plan in plans]).T[:, layout.half_step]
        t = (self._tick - n_total + layout.ticks) * dt
        phase = layout.phase.copy()
        return WalkTrajectory(
            dt=dt,
            t=t,
            phase=phase,
            support=phase < 0.5,
            state=layout.state.copy(),
            executed=executed,
            feet=feet_after,
            interfered=interfered,
            local_poses=local,
            support_poses=support_pose,
            legs=self.ik_legs,
            half_step_ends=layout.half_step_ends,
        )

    def _empty_trajectory(self, executed: DoubleStep | None = None, interfered: int = 0) -> WalkTrajectory:
        t, phase, support, state, local, support_poses = _EMPTY
        return WalkTrajectory(
            dt=self.control_dt,
            t=t,
            phase=phase,
            support=support,
            state=state,
            executed=executed,
            feet=self._feet,
            interfered=interfered,
            local_poses=local,
            support_poses=support_poses,
        )
