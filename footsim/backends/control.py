"""The 3D driver's control law and state check, written once for every 3D backend.

Per control tick the driver (``footsim.backends.physics3d``) runs :func:`control_tick` on the
arrays of the sim's state contract (:class:`~footsim.backends.physics3d.SimState`): the fused
roll/pitch of the base from its orientation quaternion, the trunk stabilizer's correction of the
walk's joint targets, the control-latency line, the servo feed-forward and the write of the leg
commands.  With the walk node's options (an engine update rate, the trunk PID, the phase reset)
it runs :func:`node_tick` instead: the engine-update/hold rule, the trunk PID and the leg IK of
the shifted trunk, then :func:`control_tick`, in one call.  The driver calls either with its
arguments but the tick packed once per trajectory (:func:`control_tick_packed`,
:func:`node_tick_packed`).  Every ``contact_check_every`` ticks
:func:`state_ok` checks the same arrays (fatal warnings, finite state, speed and position bounds,
right side up) and records the tilt.

The laws, each one compiled function:

* fused roll and pitch (Allgeuer & Behnke): the angles between the world's vertical and the base's
  y–z plane (pitch) and x–z plane (roll), from the bottom row of the base rotation:
  ``roll = asin R[2,1]``, ``pitch = asin −R[2,0]`` (:func:`fused_tilt`).  Unlike Euler angles
  they do not depend on yaw or on the order of rotations.
* the stabilizer: ``target + (roll_gain · (roll − planned roll) + pitch_gain · (pitch − planned
  pitch))`` per leg joint (:func:`corrected`; gains from :class:`TrunkStabilizer`).
* the servo feed-forward: ``command = target + gain · (target − previous target)``
  (:class:`ServoFeedForward`), the servo's D term on the tracking error.
* the PID (:func:`pid_update`, for :class:`PID` and the trunk PID :class:`TrunkPID`):
  ``p · e + I + d · (e − e_previous) / dt``, ``I`` the clamped sum of ``i · e · dt``.

No fast-math (so no fused multiply-adds) and ``math.asin`` is the C library's, as in CPython: the
kernels compute what the same expressions compute in Python, bit for bit.  Compiled code is
cached on disk (``footsim.compiled``).
"""

from __future__ import annotations

import math

import numpy as np

from footsim.compiled import compiled
from footsim.walk.ik import legs_ik_tick

# -- rotation and tilt -------------------------------------------------------------------------


@compiled
def clamped_asin(s: float) -> float:
    """asin of ``s`` clamped into [-1, 1] (rounding can push a rotation entry past 1); a NaN
    passes through."""
    return math.asin(-1.0 if s < -1.0 else 1.0 if s > 1.0 else s)


@compiled
def fused_tilt(r20: float, r21: float) -> tuple[float, float]:
    """Fused (roll, pitch) from the bottom row (R[2,0], R[2,1]) of a body-to-world rotation."""
    return clamped_asin(r21), clamped_asin(-r20)


@compiled
def _components(quat, w_last):
    """(w, x, y, z) of ``quat``: (w, x, y, z) (MuJoCo) or, with ``w_last``, (x, y, z, w) (Bullet)."""
    if w_last:
        return quat[3], quat[0], quat[1], quat[2]
    return quat[0], quat[1], quat[2], quat[3]


@compiled
def _bottom_row(quat, w_last):
    """Bottom row of the rotation of the unit quaternion ``quat``."""
    w, x, y, z = _components(quat, w_last)
    return 2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)


@compiled
def _rows(quat, w_last, normalizes):
    """The three rows of the rotation of ``quat``; with ``normalizes`` divided by |q|² as Bullet's
    ``getMatrixFromQuaternion`` forms it (the bottom row otherwise as :func:`_bottom_row`)."""
    w, x, y, z = _components(quat, w_last)
    if normalizes:
        s = 2.0 / (x * x + y * y + z * z + w * w)
        xs, ys, zs = x * s, y * s, z * s
        wx, wy, wz = w * xs, w * ys, w * zs
        xx, xy, xz = x * xs, x * ys, x * zs
        yy, yz, zz = y * ys, y * zs, z * zs
        return (
            (1.0 - (yy + zz), xy - wz, xz + wy),
            (xy + wz, 1.0 - (xx + zz), yz - wx),
            (xz - wy, yz + wx, 1.0 - (xx + yy)),
        )
    return (
        (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
        (2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)),
        _bottom_row(quat, w_last),
    )


@compiled
def _in_frame(row, frame):
    """A row of a rotation times ``frame``ᵀ (3×3): the row of the rotation of the base link when
    ``quat`` is the orientation of a body whose frame is rotated by ``frame`` from the link's
    (Bullet's inertial frame); ``frame`` None: the link's own."""
    if frame is None:
        return row
    return (
        row[0] * frame[0, 0] + row[1] * frame[0, 1] + row[2] * frame[0, 2],
        row[0] * frame[1, 0] + row[1] * frame[1, 1] + row[2] * frame[1, 2],
        row[0] * frame[2, 0] + row[1] * frame[2, 1] + row[2] * frame[2, 2],
    )


@compiled
def base_tilt(quat: np.ndarray, w_last: bool, frame: np.ndarray | None) -> tuple[float, float]:
    """Fused (roll, pitch) of the base link from its orientation quaternion (see :func:`_in_frame`)."""
    r = _in_frame(_bottom_row(quat, w_last), frame)
    return fused_tilt(r[0], r[1])


def fused_roll_pitch(rotation: np.ndarray) -> tuple[float, float]:
    """Fused (roll, pitch) of a body-to-world rotation matrix.  Valid for the upper hemisphere;
    an upside-down body (R[2,2] < 0) is fallen anyway."""
    return fused_tilt(float(rotation[2, 0]), float(rotation[2, 1]))


# -- the control tick --------------------------------------------------------------------------


@compiled
def corrected(target: float, roll_gain: float, pitch_gain: float, roll_error: float, pitch_error: float) -> float:
    """One joint's target plus the stabilizer's correction."""
    return target + (roll_gain * roll_error + pitch_gain * pitch_error)


@compiled
def send(target: float, j: int, feed_forward: np.ndarray | None, command: np.ndarray, leg_ids: np.ndarray) -> None:
    """Leg joint ``j``'s command: ``target`` through the servo feed-forward (``feed_forward``
    (2, 12) [gain, previous target], updated in place; None: none) into ``command[leg_ids[j]]``."""
    if feed_forward is not None:
        command[leg_ids[j]] = target + feed_forward[0, j] * (target - feed_forward[1, j])
        feed_forward[1, j] = target
    else:
        command[leg_ids[j]] = target


@compiled
def control_tick(
    targets: np.ndarray,
    trunk: np.ndarray,
    k: int,
    gains: np.ndarray | None,
    quat: np.ndarray,
    w_last: bool,
    frame: np.ndarray | None,
    delay: np.ndarray | None,
    delay_slot: np.ndarray,
    feed_forward: np.ndarray | None,
    command: np.ndarray,
    leg_ids: np.ndarray,
) -> None:
    """Write control tick ``k``'s leg commands into ``command``.

    ``targets`` (n, 12) and ``trunk`` (n, 6) are the walk trajectory's joint targets and trunk
    poses (roll = column 3, pitch = column 4).  ``gains`` (2, 12): the stabilizer's per-joint
    roll and pitch gains, or None (open loop); the tilt is :func:`base_tilt` of ``quat``
    (``w_last``, ``frame``).  ``delay`` (latency, 12): the last targets not yet sent, oldest at
    row ``delay_slot[0]``, filled with this tick's targets first if ``delay_slot[1]`` (control
    latency), or None.  ``feed_forward`` (2, 12): the servo
    feed-forward's gains and previous targets (updated in place), or None.  ``leg_ids``:
    ``command``'s index of each leg joint.  (None arguments are resolved at compile time: each
    combination is its own specialisation.)
    """
    if gains is not None:
        roll, pitch = base_tilt(quat, w_last, frame)
        roll_error, pitch_error = roll - trunk[k, 3], pitch - trunk[k, 4]
    slot, fill = 0, False
    if delay is not None:
        slot, fill = delay_slot[0], delay_slot[1] != 0
        delay_slot[0], delay_slot[1] = (slot + 1) % delay.shape[0], 0
    for j in range(targets.shape[1]):
        t = targets[k, j]
        if gains is not None:
            t = corrected(t, gains[0, j], gains[1, j], roll_error, pitch_error)
        if delay is not None:
            if fill:  # a new line starts full of this tick's targets
                delay[:, j] = t
            t, delay[slot, j] = delay[slot, j], t
        send(t, j, feed_forward, command, leg_ids)


@compiled
def node_tick(
    k: int,
    rate: float,
    times: np.ndarray,
    node: np.ndarray,
    held: np.ndarray,
    targets: np.ndarray,
    trunk: np.ndarray,
    pid: tuple[np.ndarray, ...] | None,
    local: np.ndarray,
    legs: tuple,
    gains: np.ndarray | None,
    quat: np.ndarray,
    w_last: bool,
    frame: np.ndarray | None,
    delay: np.ndarray | None,
    delay_slot: np.ndarray,
    feed_forward: np.ndarray | None,
    command: np.ndarray,
    leg_ids: np.ndarray,
) -> None:
    """The walk node's control tick ``k`` (``Physics3DBackend._node_ticks``), then :func:`control_tick`.

    An engine update is due when tick ``k``'s update index ``floor(times[k] · rate)`` (``times``:
    the ticks' engine times) differs from the last one's, ``node[0]`` (``node`` (2,): that index
    and its engine time, updated in place); ``rate`` 0 (no engine rate): at every tick (index
    ``k + 1``).  At an update the trunk PID (``pid``: :attr:`TrunkPID.arrays`, or None: off) turns
    the planned − measured fused (roll, pitch) of the base (:func:`base_tilt`) over the engine
    time since the last update (``times[k] − node[1]``) into the trunk's shift, and the leg IK of
    the shifted trunk (``footsim.walk.ik.legs_ik_tick`` of the trajectory's support-frame poses
    ``local``, with ``legs`` = ``QuinticWalk.ik_legs``) overwrites ``targets[k]``; the tick's
    targets and trunk pose are then held (``held`` (18,)).  Between updates tick ``k`` takes the
    held ones.  ``targets`` and ``trunk`` are the trajectory's copies (written in place); the other
    arguments are :func:`control_tick`'s.
    """
    every = rate == 0.0
    update = float(k + 1) if every else float(math.floor(times[k] * rate + 1e-9))
    if every or update != node[0]:
        if pid is not None:
            roll, pitch = base_tilt(quat, w_last, frame)
            dx, dy = trunk_pid_shift(pid, trunk[k, 3] - roll, trunk[k, 4] - pitch, times[k] - node[1])
            legs_ik_tick(local, k, dx, dy, legs[0], legs[1], legs[2], legs[3], targets[k])
        node[0], node[1] = update, times[k]
        held[:12] = targets[k]
        held[12:] = trunk[k]
    else:
        targets[k] = held[:12]
        trunk[k] = held[12:]
    control_tick(targets, trunk, k, gains, quat, w_last, frame, delay, delay_slot, feed_forward, command, leg_ids)


@compiled
def control_tick_packed(k: int, packed) -> None:
    """:func:`control_tick` of tick ``k``, its other arguments (targets, trunk, gains, quat, …, in
    order) from ``packed`` (``footsim.compiled.pack``): the driver's per-tick call, one argument
    to unbox instead of each array."""
    args = packed.args
    control_tick(args[0], args[1], k, *args[2:])


@compiled
def node_tick_packed(k: int, packed) -> None:
    """:func:`node_tick` of tick ``k``, its other arguments (rate, times, …, in order) from
    ``packed`` (``footsim.compiled.pack``): the driver's per-tick call, one argument to unbox
    instead of each array."""
    node_tick(k, *packed.args)


@compiled
def contact_watch(
    state: np.ndarray, phase: np.ndarray, support: np.ndarray, stepping: tuple[int, int], start: float, out: np.ndarray
) -> None:
    """The phase reset's reads of a trajectory, into ``out`` (n,): the flying foot's index in
    ``sole_forces()`` (0 left, 1 right; ``support`` True = left support) at the ticks of a
    stepping half step (``state`` one of ``stepping``) whose ``phase`` lies in the contact
    window (``start`` < phase < 0.5 or phase > 0.5 + ``start``), else -1."""
    for k in range(state.shape[0]):
        p = phase[k]
        if (state[k] == stepping[0] or state[k] == stepping[1]) and (start < p < 0.5 or p > 0.5 + start):
            out[k] = 1 if support[k] else 0
        else:
            out[k] = -1


@compiled
def write_targets(
    targets: np.ndarray, feed_forward: np.ndarray | None, command: np.ndarray, leg_ids: np.ndarray
) -> None:
    """``targets`` (12,) as leg commands (:func:`send`), outside the control ticks."""
    for j in range(targets.shape[0]):
        send(targets[j], j, feed_forward, command, leg_ids)


# -- the state check ---------------------------------------------------------------------------


@compiled
def all_finite(a: np.ndarray) -> bool:
    """``np.isfinite(a).all()`` without numpy's per-call overhead (~4 µs on a small array)."""
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


@compiled
def state_ok(
    fault: np.ndarray,
    warnings: np.ndarray,
    warning_ids: np.ndarray,
    finite: tuple[np.ndarray, ...],
    velocity: np.ndarray | None,
    max_speed: float,
    position: np.ndarray,
    quat: np.ndarray,
    w_last: bool,
    normalizes: bool,
    frame: np.ndarray | None,
    offset: np.ndarray | None,
    out_of_bounds: float,
    tilt: np.ndarray,
) -> bool:
    """The driver's periodic check while all is well, in one call: True, with the base link's
    fused (roll, pitch) written into ``tilt``, when the sim holds no fault of its own
    (``fault[0]``), no fatal warning (``warnings`` at ``warning_ids``), every value of the
    arrays in ``finite`` is finite, the base's linear and angular speed (``velocity`` (6,), or None) stay within
    ``max_speed`` and 6 × ``max_speed``, the base link's origin is within ``out_of_bounds`` and
    the base is right side up.  False otherwise: the driver then runs its full check, which names
    the problem.

    ``position``, ``quat``: the position and orientation of the body the sim integrates;
    ``frame`` (3×3) and ``offset`` (3,): that body's frame in the base link's (None: the link
    itself).  The rotation is formed as the sim's own ``base_pose`` forms it (``normalizes``: see
    :func:`_rows`), so the check agrees with the full check.
    """
    if fault[0] != 0:
        return False
    for i in warning_ids:
        if warnings[i] != 0:
            return False
    for values in finite:
        if not all_finite(values):
            return False
    if velocity is not None:
        if math.hypot(velocity[0], math.hypot(velocity[1], velocity[2])) > max_speed:
            return False
        if math.hypot(velocity[3], math.hypot(velocity[4], velocity[5])) > 6.0 * max_speed:
            return False
    rows = _rows(quat, w_last, normalizes)
    for i in range(3):
        origin = position[i]
        if offset is not None:
            link = _in_frame(rows[i], frame)
            origin = position[i] - (link[0] * offset[0] + link[1] * offset[1] + link[2] * offset[2])
        if abs(origin) > out_of_bounds:
            return False
    bottom = _in_frame(rows[2], frame)
    if bottom[2] < 0.0:
        return False
    tilt[0], tilt[1] = fused_tilt(bottom[0], bottom[1])
    return True


@compiled
def state_ok_packed(packed) -> bool:
    """:func:`state_ok` of the arguments in ``packed`` (``footsim.compiled.pack``): the driver's
    periodic call, one argument to unbox instead of each array."""
    return state_ok(*packed.args)


# -- the laws' parameters ----------------------------------------------------------------------


class TrunkStabilizer:
    """IMU feedback on the trunk orientation, in joint space (the Bit-Bots' walk has the same
    idea as PID controllers on the fused trunk pitch and roll).

    Each control tick the error between the measured fused roll/pitch of the base and the
    engine's planned trunk roll/pitch is multiplied by a gain [rad/rad] and added to the hip
    and ankle roll/pitch targets of both legs (:func:`corrected`).  The gains are in the leg IK's
    chain convention (``footsim.walk.ik``; the driver multiplies them by each joint's sign): with
    the legs' +x (roll) and +y (pitch) axes, a positive hip gain turns the trunk back towards its planned
    orientation relative to the legs; an ankle gain tilts the soles against the lean.  All gains
    0 = open loop (the engine's targets untouched, no base reads).
    """

    GAINS = ("hip_roll", "hip_pitch", "ankle_roll", "ankle_pitch")
    HIP_ROLL, HIP_PITCH, ANKLE_PITCH, ANKLE_ROLL = [1, 7], [2, 8], [4, 10], [5, 11]  # in LEG_JOINT_NAMES

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
        #: Per-joint gains in LEG_JOINT_NAMES order: row 0 on the roll error, row 1 on the pitch error.
        self.gains = np.zeros((2, 12))
        self.gains[0, self.HIP_ROLL], self.gains[0, self.ANKLE_ROLL] = self.hip_roll, self.ankle_roll
        self.gains[1, self.HIP_PITCH], self.gains[1, self.ANKLE_PITCH] = self.hip_pitch, self.ankle_pitch

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
        roll_error, pitch_error = tilt[0] - planned_roll, tilt[1] - planned_pitch
        g = self.gains
        return np.array([corrected(float(t), g[0, j], g[1, j], roll_error, pitch_error) for j, t in enumerate(targets)])


class ServoFeedForward:
    """The servo D term on the tracking error, for position servos with velocity gain ``kv``.

    A position servo gives ``kp (command − q) − kv q̇``; feeding the target velocity forward as
    ``command = q_t + kv/kp · q̇_t`` makes it ``kp (q_t − q) + kv (q̇_t − q̇)`` (a Dynamixel's PID,
    not a speed-capping damper).  ``q̇_t`` is the backward difference of consecutive targets,
    which arrive every ``control_dt``, so the gain is ``kv / kp / control_dt`` per joint.
    """

    def __init__(self, servo_kv: float, kp: np.ndarray, control_dt: float):
        if not (math.isfinite(servo_kv) and servo_kv >= 0):
            raise ValueError(f"backend.servo_kv must be >= 0, got {servo_kv!r}")
        if not (math.isfinite(control_dt) and control_dt > 0):
            raise ValueError(f"control_dt must be > 0, got {control_dt!r}")
        gain = float(servo_kv) / np.asarray(kp, dtype=float) / float(control_dt)
        #: (2, n) [gain, previous targets]: the control tick reads and updates it in place.
        self.state = np.zeros((2, len(gain)))
        self.state[0] = gain
        self.gain, self.previous = self.state  # views

    def reset(self, targets) -> None:
        """Start from rest at ``targets`` (no feed-forward until they change)."""
        self.previous[:] = targets


@compiled
def pid_update(gains: np.ndarray, state: np.ndarray, error: float, dt: float) -> float:
    """One update of a PID controller (:class:`PID`): ``gains`` (5,) [p, i, d, i_min, i_max],
    ``state`` (3,) [I, previous error, 1 if there is one] (updated in place).  The clamp compares
    as Python's ``min(i_max, max(i_min, ·))`` does."""
    raw = state[0] + gains[1] * error * dt
    above = raw if raw > gains[3] else gains[3]
    integral = above if above < gains[4] else gains[4]
    derivative = 0.0 if state[2] == 0.0 or not dt > 0 else (error - state[1]) / dt
    state[0], state[1], state[2] = integral, error, 1.0
    return gains[0] * error + integral + gains[2] * derivative


@compiled
def trunk_pid_shift(
    pid: tuple[np.ndarray, ...], roll_error: float, pitch_error: float, dt: float
) -> tuple[float, float]:
    """The trunk PID's (x, y) shift (:meth:`TrunkPID.shift`); ``pid`` = :attr:`TrunkPID.arrays`."""
    return pid_update(pid[0], pid[1], pitch_error, dt), pid_update(pid[2], pid[3], roll_error, dt)


class PID:
    """One PID controller on an error signal, updated at irregular intervals ``dt``.

    ``command = p · e + I + d · (e − e_previous) / dt`` with ``I`` the running sum of
    ``i · e · dt``, clamped to [``i_min``, ``i_max``] (both 0: no I term).  The first update after
    :meth:`reset` has no previous error and no D term.  The law is :func:`pid_update` (compiled,
    so the 3D driver's tick runs it too); the gains and the state are its arrays.
    """

    def __init__(self, p: float = 0.0, i: float = 0.0, d: float = 0.0, i_min: float = 0.0, i_max: float = 0.0):
        self.p, self.i, self.d = float(p), float(i), float(d)
        self.i_min, self.i_max = float(i_min), float(i_max)
        self.active = any(g != 0.0 for g in (self.p, self.i, self.d))
        #: [p, i, d, i_min, i_max] and [I, previous error, 1 if there is one]: :func:`pid_update`'s.
        self.gains = np.array([self.p, self.i, self.d, self.i_min, self.i_max])
        self.state = np.zeros(3)

    def reset(self) -> None:
        self.state[:] = 0.0

    @property
    def integral(self) -> float:
        return float(self.state[0])

    @property
    def previous(self) -> float | None:
        """The last error (None before the first update after a reset)."""
        return float(self.state[1]) if self.state[2] != 0.0 else None

    def update(self, error: float, dt: float) -> float:
        return pid_update(self.gains, self.state, float(error), float(dt))


class TrunkPID:
    """The Bit-Bots' walk stabilizer: PID controllers on the fused trunk pitch and roll whose
    outputs move the trunk in the support sole's frame (``WalkParams.trunk_pid_*``).

    The error of each axis is planned − measured fused angle [rad] (the planned trunk orientation
    in the support frame has fused roll 0 and fused pitch = its pitch, as the engine's trunk never
    rolls); the pitch controller's output is the trunk's x shift, the roll controller's its y
    shift [m].  The 3D driver turns the shift into joint targets by the engine's leg IK of the
    shifted trunk at every engine update (:func:`node_tick`; from Python:
    ``QuinticWalk.trunk_shifted_targets``).  All gains 0 = off.
    """

    def __init__(self, pitch: PID, roll: PID):
        self.pitch, self.roll = pitch, roll
        self.active = pitch.active or roll.active
        #: The controllers' arrays (pitch gains, pitch state, roll gains, roll state), as
        #: :func:`trunk_pid_shift` takes them.
        self.arrays = (pitch.gains, pitch.state, roll.gains, roll.state)

    @classmethod
    def from_walk(cls, walk) -> TrunkPID:
        """From a ``WalkParams``'s ``trunk_pid_{pitch,roll}_{p,i,d,i_clamp_min,i_clamp_max}``."""

        def axis(name: str) -> PID:
            g = {key: getattr(walk, f"trunk_pid_{name}_{key}") for key in ("p", "i", "d", "i_clamp_min", "i_clamp_max")}
            return PID(g["p"], g["i"], g["d"], g["i_clamp_min"], g["i_clamp_max"])

        return cls(axis("pitch"), axis("roll"))

    def reset(self) -> None:
        self.pitch.reset()
        self.roll.reset()

    def shift(self, roll_error: float, pitch_error: float, dt: float) -> tuple[float, float]:
        """The trunk's (x, y) shift [m] for these errors (planned − measured fused roll, pitch [rad])."""
        return trunk_pid_shift(self.arrays, float(roll_error), float(pitch_error), float(dt))
