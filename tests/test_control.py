"""The 3D control law and state check (``footsim.backends.control``) against independent
expectations: rotation matrices from scipy, the stabilizer, latency and feed-forward formulas
written out in numpy.  The kernels are the only implementation every 3D backend runs."""

import math

import numpy as np
import pytest

from footsim.backends.control import (
    ServoFeedForward,
    TrunkStabilizer,
    all_finite,
    control_tick,
    control_tick_packed,
    fused_roll_pitch,
    state_ok,
    state_ok_packed,
    write_targets,
)

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

GAINS = {"hip_roll": 0.5228, "hip_pitch": -0.1629, "ankle_roll": 0.0798, "ankle_pitch": -0.0843}


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


def _link_tilt(quat, w_last, frame):
    """Fused roll/pitch of the base link: scipy's matrix of the body quaternion, times frameᵀ."""
    xyzw = quat if w_last else np.roll(quat, -1)
    r = Rotation.from_quat(xyzw).as_matrix()
    if frame is not None:
        r = r @ frame.T
    return math.asin(np.clip(r[2, 1], -1, 1)), math.asin(np.clip(-r[2, 0], -1, 1))


@pytest.mark.parametrize("bullet", [False, True], ids=["mujoco-layout", "bullet-layout"])
@pytest.mark.parametrize("stabilized", [True, False])
@pytest.mark.parametrize("feed_forward", [True, False])
def test_control_tick_is_the_stabilizer_and_servo_law(bullet, stabilized, feed_forward):
    rng = np.random.default_rng(0)
    gains = TrunkStabilizer(**GAINS).gains
    gains[:] = rng.normal(scale=0.3, size=(2, 12))  # every joint: the formula's full order of operations
    frame = np.ascontiguousarray(Rotation.random(random_state=rng).as_matrix()) if bullet else None
    leg_ids = rng.permutation(20)[:12].astype(np.intp)  # the command array is larger than the legs
    n = 25
    targets, trunk = rng.normal(scale=0.5, size=(n, 12)), rng.normal(scale=0.2, size=(n, 6))
    ff = np.vstack([rng.uniform(0.0, 0.05, 12), rng.normal(scale=0.5, size=12)]) if feed_forward else None
    previous = None if ff is None else ff[1].copy()
    command = rng.normal(size=20)
    untouched = np.setdiff1d(np.arange(20), leg_ids)
    before = command[untouched].copy()
    slot = np.zeros(2, dtype=np.int64)
    for k in range(n):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        control_tick(
            targets, trunk, k, gains if stabilized else None, quat, bullet, frame, None, slot, ff, command, leg_ids
        )
        expected = targets[k].copy()
        if stabilized:
            roll, pitch = _link_tilt(quat, bullet, frame)
            expected += gains[0] * (roll - trunk[k, 3]) + gains[1] * (pitch - trunk[k, 4])
        if feed_forward:
            expected, previous = expected + ff[0] * (expected - previous), expected
            np.testing.assert_allclose(ff[1], previous, atol=1e-12)
        np.testing.assert_allclose(command[leg_ids], expected, atol=1e-12)
    np.testing.assert_array_equal(command[untouched], before)


@pytest.mark.parametrize("latency", [1, 3])
def test_the_latency_line_sends_each_target_latency_ticks_late(latency):
    rng = np.random.default_rng(1)
    n = 12
    targets, trunk = rng.normal(size=(n, 12)), np.zeros((n, 6))
    standing = rng.normal(size=12)
    ids = np.arange(12, dtype=np.intp)
    for fill in (False, True):  # a line from reset (standing), or a new one full of its first target
        delay = np.tile(standing, (latency, 1))
        slot = np.array([0, int(fill)], dtype=np.int64)
        command = np.zeros(12)
        for k in range(n):
            control_tick(targets, trunk, k, None, np.zeros(4), False, None, delay, slot, None, command, ids)
            if k >= latency:
                expected = targets[k - latency]
            else:
                expected = targets[0] if fill else standing
            np.testing.assert_array_equal(command, expected)


def test_write_targets_is_the_servo_law_for_given_targets():
    rng = np.random.default_rng(2)
    ff = ServoFeedForward(2.0, rng.uniform(5, 50, 12), 0.01)
    ff.reset(np.zeros(12))
    command = np.zeros(12)
    ids = np.arange(12, dtype=np.intp)
    previous = np.zeros(12)
    for _ in range(5):
        t = rng.normal(size=12)
        write_targets(t, ff.state, command, ids)
        np.testing.assert_allclose(command, t + ff.gain * (t - previous), atol=1e-12)
        previous = t
    write_targets(t, None, command, ids)
    np.testing.assert_array_equal(command, t)
    with pytest.raises(ValueError, match="servo_kv"):
        ServoFeedForward(-1.0, np.ones(12), 0.01)


def test_the_compiled_tick_equals_its_python_function_bit_for_bit():
    """``NUMBA_DISABLE_JIT=1`` runs ``control_tick.py_func``: the same results, to the bit."""
    rng = np.random.default_rng(3)
    targets, trunk = rng.normal(size=(10, 12)), rng.normal(scale=0.2, size=(10, 6))
    targets[rng.random((10, 12)) < 0.05] = -0.0  # signed zeros survive as in Python
    gains = TrunkStabilizer(**GAINS).gains
    ids = np.arange(12, dtype=np.intp)
    ff_a = np.vstack([rng.uniform(0.0, 0.05, 12), np.zeros(12)])
    ff_b = ff_a.copy()
    a, b = np.zeros(12), np.zeros(12)
    slot_a, slot_b = np.zeros(2, dtype=np.int64), np.zeros(2, dtype=np.int64)
    delay_a, delay_b = np.zeros((2, 12)), np.zeros((2, 12))
    for k in range(10):
        quat = rng.normal(size=4) * rng.uniform(0.9, 1.1)  # off unit: the clamp
        control_tick(targets, trunk, k, gains, quat, False, None, delay_a, slot_a, ff_a, a, ids)
        control_tick.py_func(targets, trunk, k, gains, quat, False, None, delay_b, slot_b, ff_b, b, ids)
        np.testing.assert_array_equal(_bits(a), _bits(b))


def test_typed_entry_is_the_compiled_kernel_without_dispatch():
    from footsim.compiled import typed_entry

    rng = np.random.default_rng(4)
    targets, trunk = rng.normal(size=(4, 12)), rng.normal(size=(4, 6))
    gains, ids, slot = TrunkStabilizer(**GAINS).gains, np.arange(12, dtype=np.intp), np.zeros(2, dtype=np.int64)
    quat = np.array([0.0, 0.0, 0.1, 0.99])
    args = (targets, trunk, 0, gains, quat, True, None, None, slot, None, np.zeros(12), ids)
    entry = typed_entry(control_tick, *args)
    assert entry is not control_tick and callable(entry)
    a, b = np.zeros(12), np.zeros(12)
    for k in range(4):
        entry(targets, trunk, k, gains, quat, True, None, None, slot, None, a, ids)
        control_tick(targets, trunk, k, gains, quat, True, None, None, slot, None, b, ids)
        np.testing.assert_array_equal(_bits(a), _bits(b))


@pytest.mark.parametrize("jit", [True, False], ids=["compiled", "python"])
def test_packed_kernels_are_the_kernels_on_the_same_arrays(jit):
    """``pack`` holds the arrays themselves (the kernels' writes land in them) and the packed
    kernels give the direct calls' results to the bit; ``python``: the objects and functions that
    ``NUMBA_DISABLE_JIT=1`` runs (``_PythonPacked``, ``py_func``)."""
    from footsim.compiled import _PythonPacked, pack, typed_entry

    rng = np.random.default_rng(7)
    targets, trunk = rng.normal(size=(6, 12)), rng.normal(scale=0.2, size=(6, 6))
    gains, ids = TrunkStabilizer(**GAINS).gains, np.arange(12, dtype=np.intp)
    quat = rng.normal(size=4)
    laws = [(np.zeros((2, 12)), np.zeros(2, dtype=np.int64), np.vstack([rng.uniform(0, 0.05, 12), np.zeros(12)]))]
    laws.append(tuple(a.copy() for a in laws[0]))
    (delay_a, slot_a, ff_a), (delay_b, slot_b, ff_b) = laws
    a, b = np.zeros(12), np.zeros(12)
    args = (targets, trunk, gains, quat, False, None, delay_a, slot_a, ff_a, a, ids)
    packed = pack(args) if jit else _PythonPacked(args)
    tick = typed_entry(control_tick_packed, 0, packed) if jit else control_tick_packed.py_func
    for k in range(6):
        tick(k, packed)
        control_tick(targets, trunk, k, gains, quat, False, None, delay_b, slot_b, ff_b, b, ids)
        for x, y in ((a, b), (delay_a, delay_b), (ff_a, ff_b)):
            np.testing.assert_array_equal(_bits(x), _bits(y))
        np.testing.assert_array_equal(slot_a, slot_b)
    state, tilt_a, tilt_b = np.array([0.1, 0.2, 0.3]), np.zeros(2), np.zeros(2)
    unit = quat / np.linalg.norm(quat)
    check = (np.zeros(1, dtype=np.int8), np.zeros(2, dtype=np.int32), np.array([1], dtype=np.intp), (state,))
    check_a = (*check, None, math.inf, state, unit, False, False, None, None, 50.0, tilt_a)
    packed = pack(check_a) if jit else _PythonPacked(check_a)
    ok = (typed_entry(state_ok_packed, packed) if jit else state_ok_packed.py_func)(packed)
    assert ok == state_ok(*check, None, math.inf, state, unit, False, False, None, None, 50.0, tilt_b)
    np.testing.assert_array_equal(_bits(tilt_a), _bits(tilt_b))


def test_all_finite_matches_numpy():
    rng = np.random.default_rng(5)
    for shape in [(0,), (3,), (3, 3), (7, 5)]:
        for bad in [None, np.nan, np.inf, -np.inf]:
            a = rng.normal(size=shape)
            if bad is not None and a.size:
                a.flat[rng.integers(a.size)] = bad
            for view in (a, a.T, a[..., ::2]):
                assert all_finite(view) == bool(np.isfinite(view).all())


@pytest.mark.parametrize("bullet", [False, True], ids=["mujoco-layout", "bullet-layout"])
def test_state_ok_checks_what_the_full_check_checks(bullet):
    """True with the link's fused tilt exactly when: no fault or fatal warning, all finite, speeds
    and the link origin within bounds, right side up (expectations from scipy's matrices)."""
    rng = np.random.default_rng(6)
    frame = np.ascontiguousarray(Rotation.random(random_state=rng).as_matrix()) if bullet else None
    offset = rng.normal(scale=0.05, size=3) if bullet else None
    bounds, max_speed = 50.0, 10.0
    seen = set()
    for case in range(400):
        state = np.zeros(13)
        state[0:3] = rng.uniform(-60, 60, 3) if case % 10 == 0 else rng.normal(size=3)
        state[3:7] = Rotation.random(random_state=rng).as_quat()
        if not bullet:
            state[3:7] = np.roll(state[3:7], 1)  # (w, x, y, z)
        state[7:13] = rng.normal(scale=4.0, size=6)
        fault, warnings = np.zeros(1, dtype=np.int8), np.zeros(4, dtype=np.int32)
        if case % 17 == 1:
            state[rng.integers(13)] = np.nan
        if case % 23 == 2:
            warnings[2] = 1
        if case % 29 == 3:
            fault[0] = 1
        velocity = state[7:13] if bullet else None
        tilt = np.zeros(2)
        ok = state_ok(
            fault,
            warnings,
            np.array([1, 2], dtype=np.intp),
            (state,),
            velocity,
            max_speed if bullet else math.inf,
            state[0:3],
            state[3:7],
            bullet,
            bullet,
            frame,
            offset,
            bounds,
            tilt,
        )
        expected = not fault[0] and not warnings[2] and bool(np.isfinite(state).all())
        if expected:
            quat = state[3:7]
            r = Rotation.from_quat(quat if bullet else np.roll(quat, -1)).as_matrix()
            link = r if frame is None else r @ frame.T
            origin = state[0:3] - (link @ offset if bullet else 0.0)
            expected = bool(np.abs(origin).max() <= bounds and link[2, 2] >= 0.0)
            if bullet:
                expected &= bool(np.linalg.norm(state[7:10]) <= max_speed and np.linalg.norm(state[10:13]) <= 60.0)
            if expected:
                np.testing.assert_allclose(tilt, fused_roll_pitch(link), atol=1e-12)
        assert ok == expected, case
        seen.add(ok)
    assert seen == {True, False}
