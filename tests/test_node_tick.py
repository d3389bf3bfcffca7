"""The walk node's compiled tick (``footsim.backends.control.node_tick``) and its pieces: the PID
law (``pid_update``), the trunk PID (``trunk_pid_shift``) and the IK of the shifted trunk
(``footsim.walk.ik.legs_ik_tick``), each against an independent expectation: the PID law written
out in plain Python, forward kinematics of the IK's answer, and the node's update/hold rule
written out in numpy with scipy's rotation of the base quaternion."""

import math

import numpy as np
import pytest

from footsim.backends.control import (
    PID,
    TrunkPID,
    contact_watch,
    node_tick,
    node_tick_packed,
    pid_update,
    trunk_pid_shift,
)
from footsim.walk import DoubleStep, Footstep, FootstepGeometry, LegGeometry, QuinticWalk, StepLimits, WalkParams
from footsim.walk.engine import WalkState
from footsim.walk.ik import ik_legs, leg_fk, legs_ik, legs_ik_tick, rotation_from_rpy

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

LEG = LegGeometry()
LIMITS = StepLimits(0.156, 0.103, 0.764)


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


class PythonPID:
    """The PID law as the docstring states it, in plain Python floats."""

    def __init__(self, p, i, d, i_min, i_max):
        self.p, self.i, self.d, self.i_min, self.i_max = p, i, d, i_min, i_max
        self.integral, self.previous = 0.0, None

    def update(self, error, dt):
        self.integral = min(self.i_max, max(self.i_min, self.integral + self.i * error * dt))
        derivative = 0.0 if self.previous is None or not dt > 0 else (error - self.previous) / dt
        self.previous = error
        return self.p * error + self.integral + self.d * derivative


def _walk_trajectory(seed: int = 0):
    """A real double step of the quintic engine (Wolfgang-like legs, 8 ms ticks)."""
    params = WalkParams()
    engine = QuinticWalk(params, FootstepGeometry(LIMITS, foot_distance=params.foot_distance), LEG, 0.008)
    engine.double_step(DoubleStep(Footstep(0.04), Footstep(0.04)))  # the start movement
    rng = np.random.default_rng(seed)
    step = DoubleStep(Footstep(*rng.uniform(-0.03, 0.03, 3)), Footstep(*rng.uniform(-0.03, 0.03, 3)))
    return engine, engine.double_step(step)


# --- the PID law -----------------------------------------------------------------------------------


def test_pid_update_is_the_python_law_bit_for_bit_with_clamps_and_odd_intervals():
    rng = np.random.default_rng(0)
    gains = (0.0035, 0.5, 0.004, -0.001, 0.001)
    reference, compiled = PythonPID(*gains), PID(*gains)
    clamped = set()
    for n in range(200):
        error = float(rng.normal(scale=0.2))
        dt = float(rng.choice([0.008, 0.002, 0.0, -0.004, rng.uniform(0.0, 0.02)]))
        if n % 50 == 49:
            reference, _ = PythonPID(*gains), compiled.reset()
        expected = reference.update(error, dt)
        assert _bits(compiled.update(error, dt)) == _bits(expected), n
        assert compiled.integral == reference.integral and compiled.previous == reference.previous
        if abs(reference.integral) == 0.001:
            clamped.add(reference.integral)
    assert clamped == {-0.001, 0.001}  # the clamp was hit both ways
    # a zero interval: the I term unchanged, no D term
    pid = PID(*gains)
    pid.update(0.1, 0.01)
    assert pid.update(0.3, 0.0) == pytest.approx(0.0035 * 0.3 + 0.0005, abs=1e-15)  # I unchanged, no D


def test_pid_update_clamps_as_min_max_does_with_nan():
    state = np.zeros(3)
    gains = np.array([1.0, 1.0, 0.0, -0.5, 0.5])
    # a NaN integrand fails both comparisons: Python's max(i_min, nan) is i_min, then min(i_max, i_min)
    assert math.isnan(pid_update(gains, state, math.nan, 0.1))
    assert state[0] == min(0.5, max(-0.5, math.nan)) == -0.5


def test_trunk_pid_maps_pitch_to_x_and_roll_to_y_with_separate_state():
    pid = TrunkPID(PID(p=0.01, i=1.0, i_min=-1.0, i_max=1.0), PID(p=-0.02, d=0.001))
    dx, dy = trunk_pid_shift(pid.arrays, 0.1, 0.2, 0.01)  # roll error 0.1, pitch error 0.2
    assert (dx, dy) == pytest.approx((0.01 * 0.2 + 1.0 * 0.2 * 0.01, -0.02 * 0.1))
    # the second update: pitch I accumulates, roll gets its D term on its own previous error
    dx, dy = pid.shift(roll_error=0.3, pitch_error=0.2, dt=0.01)
    assert (dx, dy) == pytest.approx((0.002 + 0.004, -0.006 + 0.001 * (0.3 - 0.1) / 0.01))


# --- the IK of the shifted trunk --------------------------------------------------------------------


@pytest.mark.parametrize("with_limits", [False, True])
def test_legs_ik_tick_solves_the_soles_seen_from_the_shifted_trunk(with_limits):
    engine, trajectory = _walk_trajectory()
    local = trajectory.local_poses
    limits = np.tile([-0.6, 2.0], (12, 1)) if with_limits else None  # clips some hip and ankle angles
    rng = np.random.default_rng(1)
    clipped = 0
    for k in range(0, local.shape[2], 5):
        dx, dy = rng.uniform(-0.02, 0.02, 2)
        q = np.empty(12)
        ok = legs_ik_tick(local, k, dx, dy, *ik_legs(LEG, limits), q)
        trunk = local[2, :, k] + np.array([dx, dy, 0.0, 0.0, 0.0, 0.0])
        Rt = rotation_from_rpy(trunk[3:])
        if not with_limits:
            assert ok
            for side, foot in (("left", 0), ("right", 1)):  # FK of the answer: the sole as the moved trunk sees it
                sole = local[foot, :, k]
                pos, rot = leg_fk(q[None, 6 * foot : 6 * foot + 6], side, LEG)
                np.testing.assert_allclose(pos[0], Rt.T @ (sole[:3] - trunk[:3]), atol=1e-9)
                np.testing.assert_allclose(rot[0], Rt.T @ rotation_from_rpy(sole[3:]), atol=1e-9)
        # the batch IK of a shifted copy: the same bits
        copy = local[:, :, k : k + 1].copy()
        copy[2, 0] += dx
        copy[2, 1] += dy
        expected, reachable = legs_ik(copy[2], copy[0], copy[1], LEG, limits)
        np.testing.assert_array_equal(_bits(q), _bits(expected[0]))
        assert ok == reachable[0]
        clipped += not ok
    assert clipped > 0 if with_limits else clipped == 0


def test_trunk_shifted_targets_without_a_shift_are_the_planned_targets():
    engine, trajectory = _walk_trajectory(2)
    for k in range(len(trajectory)):
        np.testing.assert_array_equal(
            _bits(engine.trunk_shifted_targets(trajectory, k, 0.0, 0.0)), _bits(trajectory.joint_targets[k])
        )


# --- the node tick ----------------------------------------------------------------------------------


def _tilt(quat):
    """Fused (roll, pitch) of a (w, x, y, z) quaternion, from scipy's rotation matrix."""
    r = Rotation.from_quat(np.roll(quat, -1)).as_matrix()
    return math.asin(np.clip(r[2, 1], -1, 1)), math.asin(np.clip(-r[2, 0], -1, 1))


@pytest.mark.parametrize("every", [True, False])
@pytest.mark.parametrize("with_pid", [True, False])
def test_node_tick_updates_shifts_and_holds_as_the_walk_node_does(every, with_pid):
    engine, trajectory = _walk_trajectory(3)
    n = len(trajectory)
    times = trajectory.t
    rate = 50.0  # every ~2.5 ticks of 8 ms
    updates = [k + 1 if every else math.floor(t * rate + 1e-9) for k, t in enumerate(times.tolist())]
    gains = (0.004, 0.3, 0.001, -0.002, 0.002)
    pid = TrunkPID(PID(*gains), PID(*gains)) if with_pid else None
    ref_pitch, ref_roll = PythonPID(*gains), PythonPID(*gains)
    targets, trunk = trajectory.joint_targets.copy(), trajectory.trunk_in_support.copy()
    node, held = np.array([updates[0] - 1.0, times[0] - 0.008]), np.arange(18.0)
    last_update, last_time = node
    held_ref = held.copy()
    command, ids, slot = np.zeros(12), np.arange(12, dtype=np.intp), np.zeros(2, dtype=np.int64)
    rng = np.random.default_rng(4)
    sent_updates = 0
    for k in range(n):
        quat = Rotation.from_rotvec(rng.normal(scale=0.05, size=3)).as_quat()
        quat = np.ascontiguousarray(np.roll(quat, 1))  # (w, x, y, z)
        arrays = pid.arrays if pid is not None else None
        node_tick(
            k, 0.0 if every else rate, times, node, held, targets, trunk, arrays, trajectory.local_poses,
            engine.ik_legs, None, quat, False, None, None, slot, None, command, ids,
        )  # fmt: skip
        # the reference: an update when the index moved on (or every tick), else the held targets
        if every or updates[k] != last_update:
            expected = trajectory.joint_targets[k]
            if with_pid:
                roll, pitch = _tilt(quat)
                dt = times[k] - last_time
                dx = ref_pitch.update(trajectory.trunk_in_support[k, 4] - pitch, dt)
                dy = ref_roll.update(trajectory.trunk_in_support[k, 3] - roll, dt)
                shifted = trajectory.local_poses[:, :, k : k + 1].copy()
                shifted[2, 0] += dx
                shifted[2, 1] += dy
                expected = legs_ik(shifted[2], shifted[0], shifted[1], LEG)[0][0]
            last_update, last_time = updates[k], times[k]
            held_ref = np.concatenate([expected, trajectory.trunk_in_support[k]])
            sent_updates += 1
        np.testing.assert_allclose(command, held_ref[:12], atol=1e-9, err_msg=str(k))
        np.testing.assert_allclose(trunk[k], held_ref[12:], atol=0, err_msg=str(k))
        np.testing.assert_allclose(node, [last_update, last_time], atol=0)
    assert sent_updates == (n if every else len(set(updates)))
    assert every or sent_updates < n


def test_the_packed_node_tick_is_the_node_tick_bit_for_bit():
    """The driver's call (``node_tick_packed`` of ``footsim.compiled.pack``) writes what the direct
    call writes, into the packed arrays themselves, and reads the packed base orientation as it is
    at each tick (a live view, written in place between the ticks)."""
    from footsim.compiled import pack, typed_entry

    engine, trajectory = _walk_trajectory(6)
    gains = (0.004, 0.3, 0.001, -0.002, 0.002)
    runs = []
    for packed in (True, False):
        pid = TrunkPID(PID(*gains), PID(*gains))
        targets, trunk = trajectory.joint_targets.copy(), trajectory.trunk_in_support.copy()
        node, held, quat, command = np.zeros(2), np.zeros(18), np.zeros(4), np.zeros(12)
        ids, slot = np.arange(12, dtype=np.intp), np.zeros(2, dtype=np.int64)
        args = (
            50.0, trajectory.t, node, held, targets, trunk, pid.arrays, trajectory.local_poses,
            engine.ik_legs, None, quat, False, None, None, slot, None, command, ids,
        )  # fmt: skip
        packed_args = pack(args)
        tick = typed_entry(node_tick_packed, 0, packed_args)
        rng, sent = np.random.default_rng(8), []
        for k in range(len(trajectory)):
            quat[:] = np.roll(Rotation.from_rotvec(rng.normal(scale=0.05, size=3)).as_quat(), 1)  # (w, x, y, z)
            if packed:
                tick(k, packed_args)
            else:
                node_tick(k, *args)
            sent.append(command.copy())
        runs.append((np.array(sent), targets, trunk, node, held, pid.pitch.state.copy()))
    for a, b in zip(*runs):
        np.testing.assert_array_equal(_bits(a), _bits(b))


def test_contact_watch_is_the_phase_reset_window_of_the_stepping_half_steps():
    engine, trajectory = _walk_trajectory(5)
    start = 0.5 * 0.2
    out = np.empty(len(trajectory), dtype=np.int64)
    stepping = (int(WalkState.START_STEP), int(WalkState.WALKING))
    contact_watch(trajectory.state, trajectory.phase, trajectory.support, stepping, start, out)
    for k, (state, phase, left_support) in enumerate(
        zip(trajectory.state.tolist(), trajectory.phase.tolist(), trajectory.support.tolist())
    ):
        in_window = state in stepping and (start < phase < 0.5 or phase > 0.5 + start)
        assert out[k] == ((1 if left_support else 0) if in_window else -1), k
    assert {-1, 0, 1} <= set(out.tolist())  # both feet fly in a double step, and both windows have gaps
