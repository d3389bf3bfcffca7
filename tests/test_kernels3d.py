"""The compiled 3D control tick (``footsim.kernels3d``) against the verbs it replaces.

The reference for ``control_tick`` is the driver's verb path: ``quat_fused_roll_pitch`` →
``TrunkStabilizer.correct`` → ``ServoFeedForward.ctrl`` → the fancy-index write into ``ctrl``
(numpy, kept in the package for the sims without numpy state and for the latency line).  The
contract is bit-for-bit equality, on random inputs and end to end (the same ``qpos`` after
several env double steps with the compiled tick on and off).
"""

import math

import numpy as np
import pytest

from footsim.backends.physics3d import TrunkStabilizer
from footsim.kernels3d import all_finite, control_tick, quick_status, stabilized_targets

GAINS = {"hip_roll": 0.5228, "hip_pitch": -0.1629, "ankle_roll": 0.0798, "ankle_pitch": -0.0843}


def _quat_fused_roll_pitch(quat):
    """``footsim.backends.mujoco_backend.quat_fused_roll_pitch`` (copied: that module needs mujoco)."""
    w, x, y, z = quat.tolist()
    s_pitch, s_roll = 2.0 * (w * y - x * z), 2.0 * (y * z + w * x)
    return (
        math.asin(-1.0 if s_roll < -1.0 else 1.0 if s_roll > 1.0 else s_roll),
        math.asin(-1.0 if s_pitch < -1.0 else 1.0 if s_pitch > 1.0 else s_pitch),
    )


def _reference_tick(targets, trunk, quat, stabilizer, ff_state, k):
    """The verb path for tick ``k``: the 12 values written to ctrl (and ff_state updated)."""
    target = targets[k]
    if stabilizer is not None:
        row = trunk[k]
        target = stabilizer.correct(target, _quat_fused_roll_pitch(quat), row[3], row[4])
    if ff_state is None:
        return np.array(target)
    gain, previous = ff_state  # ServoFeedForward.ctrl
    out = target + gain * (target - previous)
    previous[:] = target
    return out


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


def _random_case(rng, n):
    targets = rng.normal(scale=0.5, size=(n, 12))
    targets[rng.random((n, 12)) < 0.05] = -0.0  # signed zeros must survive as they do in numpy
    trunk = rng.normal(scale=0.2, size=(n, 6))
    return targets, trunk


@pytest.mark.parametrize("stabilized", [True, False])
@pytest.mark.parametrize("feed_forward", [True, False])
def test_control_tick_is_bit_identical_to_the_verb_path(stabilized, feed_forward):
    rng = np.random.default_rng(0)
    stabilizer = TrunkStabilizer(**GAINS)
    leg_ids = rng.permutation(20)[:12].astype(np.intp)  # ctrl is larger than the legs
    for case in range(40):
        n = 30
        targets, trunk = _random_case(rng, n)
        if case % 2:  # the trajectory's trunk is a transposed view in the engine
            trunk = np.ascontiguousarray(trunk.T).T
        if case % 4 >= 2:  # every joint with roll and pitch gains: the formula's full order of operations
            stabilizer.gains[:] = rng.normal(scale=0.3, size=(2, 12))
        ff_kernel = ff_reference = None
        if feed_forward:
            ff_kernel = np.vstack([rng.uniform(0.0, 0.05, 12), rng.normal(scale=0.5, size=12)])
            ff_reference = ff_kernel.copy()
        ctrl = rng.normal(size=20)
        untouched = np.setdiff1d(np.arange(20), leg_ids)
        before = ctrl[untouched].copy()
        for k in range(n):
            # Quaternions: unit, slightly off unit (|s| > 1 clamps), now and then extreme or NaN.
            quat = rng.normal(size=4)
            quat *= (1.0 if k % 3 else rng.uniform(0.9, 1.1)) / np.linalg.norm(quat)
            if k == 7:
                quat[:] = (0.0, 1.0, 0.0, 0.0)  # upside down: s_roll = 0, boundaries of the clamp
            if k == 11:
                quat[1] = np.nan
            expected = _reference_tick(targets, trunk, quat, stabilizer if stabilized else None, ff_reference, k)
            control_tick(targets, trunk, quat, stabilizer.gains if stabilized else None, ff_kernel, ctrl, leg_ids, k)
            np.testing.assert_array_equal(_bits(ctrl[leg_ids]), _bits(expected))
            if feed_forward:
                np.testing.assert_array_equal(_bits(ff_kernel), _bits(ff_reference))
        np.testing.assert_array_equal(ctrl[untouched], before)


def test_stabilized_targets_is_bit_identical_to_correct():
    """The verb path's compiled correction (PyBullet) against ``TrunkStabilizer.correct``."""
    rng = np.random.default_rng(2)
    stabilizer = TrunkStabilizer(**GAINS)
    for case in range(40):
        targets, trunk = _random_case(rng, 20)
        if case % 2:
            trunk = np.ascontiguousarray(trunk.T).T
        if case % 4 >= 2:
            stabilizer.gains[:] = rng.normal(scale=0.3, size=(2, 12))
        for k in range(20):
            tilt = tuple(rng.normal(scale=0.3, size=2).tolist())
            if k == 5:
                tilt = (math.nan, 0.1)
            if k == 6:
                tilt = (float(trunk[k, 3]), float(trunk[k, 4]))  # zero error: signed zeros of the targets survive
            out = stabilized_targets(targets, trunk, stabilizer.gains, k, *tilt)
            expected = stabilizer.correct(targets[k], tilt, trunk[k, 3], trunk[k, 4])
            np.testing.assert_array_equal(_bits(out), _bits(expected))
            assert out is not stabilized_targets(targets, trunk, stabilizer.gains, k, *tilt)  # a new array each call


def test_control_tick_python_function_matches_the_compiled_one():
    """``NUMBA_DISABLE_JIT=1`` runs ``control_tick.py_func``: the same results."""
    rng = np.random.default_rng(1)
    targets, trunk = _random_case(rng, 10)
    gains = TrunkStabilizer(**GAINS).gains
    ff = np.vstack([rng.uniform(0.0, 0.05, 12), np.zeros(12)])
    leg_ids = np.arange(12, dtype=np.intp)
    a, b, ff_b = np.zeros(12), np.zeros(12), ff.copy()
    for k in range(10):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        control_tick(targets, trunk, quat, gains, ff, a, leg_ids, k)
        control_tick.py_func(targets, trunk, quat, gains, ff_b, b, leg_ids, k)
        np.testing.assert_array_equal(_bits(a), _bits(b))


def test_typed_entry_is_the_compiled_kernel_without_dispatch():
    """``footsim.compiled.typed_entry``: the compiled code itself (not the dispatcher), returning what
    the dispatcher returns; and the plain function where there is nothing compiled."""
    from footsim.compiled import typed_entry
    from footsim.kernels3d import bullet_control_state, bullet_control_tick

    rng = np.random.default_rng(2)
    targets, trunk = _random_case(rng, 8)
    state = bullet_control_state(targets, trunk, TrunkStabilizer(**GAINS).gains, np.eye(3)[:2])
    entry = typed_entry(bullet_control_tick, state, 0, (0.0, 0.0, 0.0, 1.0))
    assert entry is not bullet_control_tick and callable(entry)
    for k in range(8):
        quat = rng.normal(size=4)
        quat = tuple((quat / np.linalg.norm(quat)).tolist())
        assert (
            entry(state, k, quat) == bullet_control_tick(state, k, quat) == bullet_control_tick.py_func(state, k, quat)
        )

    def plain(x):
        return x + 1

    assert typed_entry(plain, 1) is plain


def test_all_finite_matches_numpy():
    rng = np.random.default_rng(2)
    for shape in [(0,), (3,), (3, 3), (7, 5)]:
        for bad in [None, np.nan, np.inf, -np.inf]:
            a = rng.normal(size=shape)
            if bad is not None and a.size:
                a.flat[rng.integers(a.size)] = bad
            for view in (a, a.T, a[..., ::2]):
                assert all_finite(view) == bool(np.isfinite(view).all())


# -- end to end: the same physics with the compiled tick on and off ------------------------------
def _walk(name, compiled, overrides=None, randomization=None, steps=4):
    from footsim import config as fconf
    from footsim.geometry import Pose2D
    from footsim.scene import Scene
    from footsim.walk.footsteps import DoubleStep

    walk = fconf.build_walk(fconf.load_preset("walk", backend=name))
    backend = fconf.build_backend(
        fconf.load_preset("backend", {"name": name, **(overrides or {})}), fconf.build_robot("wolfgang"), walk
    )
    try:
        backend.compiled_ticks = compiled
        sim = backend.sim
        if randomization:
            backend.apply_randomization(randomization)
        backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(3))
        if compiled and "control_latency" not in (randomization or {}):

            def refuse(*_):  # the compiled path must not fall back to the verbs
                raise AssertionError("compiled tick fell back to set_leg_targets / base_tilt")

            sim.set_leg_targets = sim.base_tilt = refuse
        actions = np.random.default_rng(7).uniform(-0.6, 0.6, size=(steps, 6))
        results = [backend.execute(DoubleStep.from_action(a, backend.robot.step_limits)) for a in actions]
        data = sim.data if name == "mujoco" else sim.physics.data
        return np.array(data.qpos), np.array(data.ctrl), [(r.pose, r.tilt, r.max_tilt, r.fell) for r in results]
    finally:
        backend.close()


CASES = {
    "preset": ({}, None),  # stabilizer and servo feed-forward on
    "open_loop": ({"stabilizer": None}, None),
    "no_feed_forward": ({"servo_kv": 0.0}, None),
    "pushes": ({}, {"push_force": 15.0, "push_interval": 0.4, "push_duration": 0.1}),
    "latency_and_pushes": ({}, {"control_latency": 2.0, "push_force": 15.0, "push_interval": 0.5}),
}


@pytest.mark.parametrize("name", ["mujoco", "dm_control"])
@pytest.mark.parametrize("case", list(CASES))
def test_compiled_tick_walks_bit_identically(name, case):
    pytest.importorskip("mujoco")
    if name == "dm_control":
        pytest.importorskip("dm_control")
    overrides, randomization = CASES[case]
    qpos_c, ctrl_c, results_c = _walk(name, True, overrides, randomization)
    qpos_v, ctrl_v, results_v = _walk(name, False, overrides, randomization)
    np.testing.assert_array_equal(_bits(qpos_c), _bits(qpos_v))
    np.testing.assert_array_equal(_bits(ctrl_c), _bits(ctrl_v))
    assert results_c == results_v


@pytest.mark.parametrize("name", ["mujoco", "dm_control"])
def test_quick_status_equals_the_full_check(name):
    """The compiled periodic check (``quick_status``) gives the full check's verdict and tilt bit
    for bit while all is well, and hands every problem to the full check (which names it)."""
    pytest.importorskip("mujoco")
    if name == "dm_control":
        pytest.importorskip("dm_control")
    from footsim.calibration.walkcheck import make_backend
    from footsim.geometry import Pose2D
    from footsim.scene import Scene

    backend = make_backend(name)
    try:
        backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
        sim = backend.sim
        root_q, qpos, qvel, warnings, warning_ids = sim.status_arrays()
        saved_q, saved_v = qpos.copy(), qvel.copy()
        rng = np.random.default_rng(3)
        quick_used = 0
        cases = (
            [("upright", None)]
            + [("tilted", i) for i in range(200)]
            + [
                ("upside down", None),
                ("nan qvel", None),
                ("inf qpos", None),
                ("out of bounds", None),
                ("warning", None),
            ]
        )
        for kind, _ in cases:
            qpos[:], qvel[:] = saved_q, saved_v
            warnings[:] = 0
            if kind == "tilted":  # any orientation, most of them beyond the fall threshold
                quat = rng.normal(size=4)
                root_q[3:7] = quat / np.linalg.norm(quat)
                root_q[:3] = rng.uniform(-60, 60, 3) if rng.random() < 0.1 else rng.normal(0, 1, 3)
            elif kind == "upside down":
                root_q[3:7] = (0.0, 1.0, 0.0, 0.0)
            elif kind == "nan qvel":
                qvel[-1] = np.nan
            elif kind == "inf qpos":
                qpos[-1] = np.inf
            elif kind == "out of bounds":
                root_q[1] = backend.out_of_bounds + 1.0
            elif kind == "warning":
                warnings[warning_ids[0]] = 1
            backend._tilt, backend._max_tilt = (9.0, 9.0), 0.0
            quick = backend._status()
            quick_tilt, quick_max = backend._tilt, backend._max_tilt
            backend._tilt, backend._max_tilt = (9.0, 9.0), 0.0
            full = backend._full_status()
            assert quick == full, kind
            assert quick_tilt == backend._tilt and quick_max == backend._max_tilt, kind
            if kind in ("nan qvel", "inf qpos", "out of bounds", "warning"):
                assert quick[0] is not None, kind  # a named sim error
            if kind == "upside down":
                assert quick == (None, True) and quick_tilt == (math.pi / 2, math.pi / 2)
            tilt = np.zeros(2)
            quick_used += quick_status(*sim.status_arrays(), backend.out_of_bounds, tilt)
        assert quick_used >= 50  # the compiled path did the common case (half the random quaternions are upside down)
    finally:
        qpos[:], qvel[:] = saved_q, saved_v
        warnings[:] = 0
        backend.close()
