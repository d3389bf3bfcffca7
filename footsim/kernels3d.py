"""Compiled (numba) kernels of the 3D driver's per-tick hot path (``footsim.backends.physics3d``).

A MuJoCo env double step is ~122 control ticks, each one ``mj_step`` (~50 µs) plus the Python
around it: read the trunk tilt, add the stabilizer's correction, add the servo feed-forward,
write ``ctrl``.  As numpy calls on 12-vectors that was ~10 µs a tick; :func:`control_tick` does
it in one compiled call on the sim's live arrays (``PhysicsSim.control_arrays``).

Same contract as ``footsim.kernels2d``: the kernels do the float operations of the Python code
they replace in the same order (no fast-math, so no fused multiply-adds; ``math.asin`` is the C
library's, as in CPython), so the physics is bit-identical to the verb path
(``TrunkStabilizer.correct`` → ``PhysicsSim.set_leg_targets``).  ``tests/test_kernels3d.py``
checks that on random inputs and end to end.  Compiled code is cached on disk like
``footsim.kernels2d``'s.
"""

from __future__ import annotations

import math

import numpy as np

from footsim.compiled import compiled


@compiled
def _clamped_asin(s):
    """asin of ``s`` clamped into [-1, 1] (rounding can push a rotation entry past 1); a NaN
    passes through."""
    return math.asin(-1.0 if s < -1.0 else 1.0 if s > 1.0 else s)


@compiled
def _fused_roll_pitch(quat):
    """Fused (roll, pitch) of the unit quaternion ``quat`` (w, x, y, z): the rotation matrix's
    R[2,1] = 2 (yz + wx) and −R[2,0] = 2 (wy − xz), clamped as ``quat_fused_roll_pitch`` clamps
    them (a NaN passes through to asin)."""
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    s_pitch, s_roll = 2.0 * (w * y - x * z), 2.0 * (y * z + w * x)
    return _clamped_asin(s_roll), _clamped_asin(s_pitch)


@compiled
def _corrected(target, roll_gain, pitch_gain, roll_error, pitch_error):
    """One joint's target plus the stabilizer's correction, in ``TrunkStabilizer.correct``'s
    order of operations (every compiled control path uses it, so they stay bit-identical)."""
    return target + (roll_gain * roll_error + pitch_gain * pitch_error)


@compiled
def control_tick(targets, trunk, quat, gains, feed_forward, ctrl, leg_ids, k):
    """Write control tick ``k``'s leg commands into ``ctrl``.

    ``targets`` (n, 12) and ``trunk`` (n, 6) are the walk trajectory's joint targets and trunk
    poses (roll = column 3, pitch = column 4).  ``gains`` (2, 12): the stabilizer's per-joint
    roll and pitch gains, or None (open loop).  With gains the target becomes
    ``target + (roll_gain · (roll − planned roll) + pitch_gain · (pitch − planned pitch))``, the
    fused roll/pitch taken from ``quat`` (w, x, y, z) as ``quat_fused_roll_pitch`` does.
    ``feed_forward`` (2, 12): the servo feed-forward's gains and previous targets (updated in
    place), or None: ``ctrl = t + gain · (t − previous)``.  ``leg_ids``: ctrl index of each leg joint.
    (None arguments are resolved at compile time: each combination is its own specialisation.)
    """
    if gains is not None:
        roll, pitch = _fused_roll_pitch(quat)
        roll_error, pitch_error = roll - trunk[k, 3], pitch - trunk[k, 4]
    for j in range(targets.shape[1]):
        t = targets[k, j]
        if gains is not None:
            t = _corrected(t, gains[0, j], gains[1, j], roll_error, pitch_error)
        if feed_forward is not None:
            out = t + feed_forward[0, j] * (t - feed_forward[1, j])
            feed_forward[1, j] = t
            ctrl[leg_ids[j]] = out
        else:
            ctrl[leg_ids[j]] = t


@compiled
def stabilized_targets(targets, trunk, gains, k, roll, pitch):
    """Tick ``k``'s joint targets corrected for the measured fused ``roll`` and ``pitch``, as a new
    array: ``TrunkStabilizer.correct(targets[k], (roll, pitch), trunk[k, 3], trunk[k, 4])`` in one
    call, for the sims the driver commands through the verbs (PyBullet; ~4 µs of numpy on
    12-vectors there).  ``gains`` (2, 12) as in :func:`control_tick`."""
    roll_error, pitch_error = roll - trunk[k, 3], pitch - trunk[k, 4]
    out = np.empty(targets.shape[1])
    for j in range(targets.shape[1]):
        out[j] = _corrected(targets[k, j], gains[0, j], gains[1, j], roll_error, pitch_error)
    return out


@compiled
def all_finite(a):
    """``np.isfinite(a).all()`` without numpy's per-call overhead (~4 µs on a small array)."""
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


@compiled
def quick_status(root_q, qpos, qvel, warnings, warning_ids, out_of_bounds, tilt):
    """The driver's periodic check when all is well, in one call: True, with the base's fused
    (roll, pitch) written into ``tilt``, when no fatal warning is set, the state is finite, the
    base is within ``out_of_bounds`` and right side up.  False otherwise: the driver then runs
    its full check, which names the problem (``Physics3DBackend._full_status``).

    ``root_q`` is the free joint's (x, y, z, w, qx, qy, qz) view of ``qpos``.  The tilt is
    ``fused_roll_pitch`` of the base rotation (:func:`_fused_roll_pitch`: the products MuJoCo's
    ``mju_quat2Mat`` and ``quat_to_matrix`` form).  Right side up is R[2,2] ≥ 0 in both of
    their forms.
    """
    for i in warning_ids:
        if warnings[i] != 0:
            return False
    for v in qpos:
        if not math.isfinite(v):
            return False
    for v in qvel:
        if not math.isfinite(v):
            return False
    for i in range(3):
        if abs(root_q[i]) > out_of_bounds:
            return False
    w, x, y, z = root_q[3], root_q[4], root_q[5], root_q[6]
    if 1 - 2 * (x * x + y * y) < 0.0 or w * w - x * x - y * y + z * z < 0.0:
        return False
    tilt[0], tilt[1] = _fused_roll_pitch(root_q[3:7])
    return True


@compiled
def _times_transpose(row, m):
    """The 3-vector ``row`` times ``m``ᵀ (3×3), as three floats."""
    return (
        row[0] * m[0, 0] + row[1] * m[0, 1] + row[2] * m[0, 2],
        row[0] * m[1, 0] + row[1] * m[1, 1] + row[2] * m[1, 2],
        row[0] * m[2, 0] + row[1] * m[2, 1] + row[2] * m[2, 2],
    )


@compiled
def bullet_base_ok(position, quat, linear, angular, com_pos, com_rot, out_of_bounds, max_speed, tilt):
    """PyBullet's periodic check while all is well (``PybulletSim.status_ok``), in one call on the
    tuples Bullet returns for the base: its inertial frame's ``position`` and ``quat`` (x, y, z, w),
    ``linear`` and ``angular`` velocity.  ``com_pos`` / ``com_rot``: the inertial frame in the
    base link frame.  True, with the link frame's fused (roll, pitch) written into ``tilt``, when
    every value is finite, the speeds are within ``max_speed`` (angular 6×), the link origin is
    within ``out_of_bounds`` and the base is right side up.  The same quantities as
    ``sim_error`` + ``base_pose`` + ``fused_roll_pitch`` (the rotation as Bullet's
    ``getMatrixFromQuaternion`` forms it, times ``com_rot``ᵀ)."""
    for i in range(3):
        if not (math.isfinite(position[i]) and math.isfinite(linear[i]) and math.isfinite(angular[i])):
            return False
    for i in range(4):
        if not math.isfinite(quat[i]):
            return False
    if math.hypot(linear[0], math.hypot(linear[1], linear[2])) > max_speed:
        return False
    if math.hypot(angular[0], math.hypot(angular[1], angular[2])) > 6.0 * max_speed:
        return False
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    rows = (
        (1.0 - (yy + zz), xy - wz, xz + wy),
        (xy + wz, 1.0 - (xx + zz), yz - wx),
        (xz - wy, yz + wx, 1.0 - (xx + yy)),
    )
    for i in range(3):  # row i of the link frame's rotation, r @ com_rot.T, then its origin
        l0, l1, l2 = _times_transpose(rows[i], com_rot)
        origin = position[i] - (l0 * com_pos[0] + l1 * com_pos[1] + l2 * com_pos[2])
        if abs(origin) > out_of_bounds:
            return False
    # l0, l1, l2: the last row (i = 2), which the tilt needs
    if l2 < 0.0:
        return False
    tilt[0] = _clamped_asin(l1)
    tilt[1] = _clamped_asin(-l0)
    return True


def bullet_control_state(targets, trunk, gains, com_rows):
    """The inputs of :func:`bullet_control_tick` packed in one (n + 4, 14) array: one array
    argument is cheaper to pass to a compiled function than six (Bullet leaves the caches cold
    between ticks, so each argument's conversion costs µs).  Rows 0..n-1: tick k's 12 joint
    targets, then its planned trunk roll and pitch (``trunk[k, 3:5]``); row n, n+1: the
    stabilizer's roll and pitch gains; rows n+2, n+3: ``com_rows`` (the inertial frame's
    rotation rows 0 and 1 in the base link frame, in columns 0-2)."""
    n = targets.shape[0]
    state = np.zeros((n + 4, 14))
    state[:n, :12] = targets
    state[:n, 12:14] = trunk[:, 3:5]
    state[n : n + 2, :12] = gains
    state[n + 2 : n + 4, :3] = com_rows
    return state


@compiled
def _joint_command(state, k, j, roll_error, pitch_error):
    """Joint ``j``'s corrected target at tick ``k`` (``state``: :func:`bullet_control_state`)."""
    n = state.shape[0] - 4
    return _corrected(state[k, j], state[n, j], state[n + 1, j], roll_error, pitch_error)


@compiled
def bullet_control_tick(state, k, quat):
    """PyBullet's stabilized control tick (``PybulletSim.stabilized_ticks``) in one compiled
    call: tick ``k``'s 12 joint targets, corrected for the tilt of Bullet's base quaternion
    ``quat`` (x, y, z, w).  The same float operations in the same order as
    ``PybulletSim.base_tilt`` then :func:`stabilized_targets`; ``state`` from
    :func:`bullet_control_state`.  Returns a tuple, which Bullet takes as it is (no array to
    fill and convert to a list each tick)."""
    n = state.shape[0] - 4
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    r0, r1, r2 = 2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)
    s_pitch = -(r0 * state[n + 2, 0] + r1 * state[n + 2, 1] + r2 * state[n + 2, 2])
    s_roll = r0 * state[n + 3, 0] + r1 * state[n + 3, 1] + r2 * state[n + 3, 2]
    re = _clamped_asin(s_roll) - state[k, 12]
    pe = _clamped_asin(s_pitch) - state[k, 13]
    return (
        _joint_command(state, k, 0, re, pe),
        _joint_command(state, k, 1, re, pe),
        _joint_command(state, k, 2, re, pe),
        _joint_command(state, k, 3, re, pe),
        _joint_command(state, k, 4, re, pe),
        _joint_command(state, k, 5, re, pe),
        _joint_command(state, k, 6, re, pe),
        _joint_command(state, k, 7, re, pe),
        _joint_command(state, k, 8, re, pe),
        _joint_command(state, k, 9, re, pe),
        _joint_command(state, k, 10, re, pe),
        _joint_command(state, k, 11, re, pe),
    )
