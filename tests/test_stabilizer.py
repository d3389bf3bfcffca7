"""The shared driver's IMU trunk stabilizer: arithmetic, config checks, and its effect in MuJoCo."""

import math

import numpy as np
import pytest

from footsim.backends.control import TrunkStabilizer, base_tilt, fused_roll_pitch
from footsim.calibration.walkcheck import make_backend
from footsim.walk.ik import LEG_JOINT_NAMES


def rotation(roll: float, pitch: float) -> np.ndarray:
    """R = Ry(pitch) @ Rx(roll): for this order the fused angles equal roll and pitch exactly
    (R[2, 0] = -sin(pitch), R[2, 1] = cos(pitch) sin(roll) ... see below)."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return ry @ rx


def test_correction_adds_gain_times_error_to_the_named_joints():
    stab = TrunkStabilizer(hip_roll=0.5, hip_pitch=-0.25, ankle_roll=0.1, ankle_pitch=0.2)
    targets = np.linspace(-0.3, 0.3, 12)
    roll, pitch = 0.1, 0.2
    tilt = fused_roll_pitch(rotation(roll, pitch))
    # Fused roll of Ry(p) Rx(r) is asin(cos p sin r), fused pitch is p (hand-derived).
    e_roll, e_pitch = math.asin(math.cos(pitch) * math.sin(roll)), pitch - 0.15
    assert tilt == pytest.approx((e_roll, pitch), abs=1e-12)
    out = stab.correct(targets, tilt, planned_roll=0.0, planned_pitch=0.15)
    expected = dict(zip(LEG_JOINT_NAMES, targets))
    for side in "LR":
        expected[f"{side}HipRoll"] += 0.5 * e_roll
        expected[f"{side}HipPitch"] += -0.25 * e_pitch
        expected[f"{side}AnkleRoll"] += 0.1 * e_roll
        expected[f"{side}AnklePitch"] += 0.2 * e_pitch
    np.testing.assert_allclose(out, [expected[n] for n in LEG_JOINT_NAMES], atol=1e-12)
    np.testing.assert_array_equal(targets, np.linspace(-0.3, 0.3, 12))  # input untouched


def test_zero_gains_are_inactive_and_bad_config_is_named():
    assert not TrunkStabilizer.from_config(None).active
    assert not TrunkStabilizer.from_config({}).active
    assert TrunkStabilizer.from_config({"hip_roll": 0.3}).active
    with pytest.raises(ValueError, match="unknown key.*knee"):
        TrunkStabilizer.from_config({"knee": 1.0})
    with pytest.raises(ValueError, match="stabilizer.hip_pitch"):
        TrunkStabilizer.from_config({"hip_pitch": float("nan")})


def test_mujoco_hip_roll_feedback_reduces_roll_under_a_side_push():
    """Physical sign check: with a positive hip-roll gain the trunk rolls less under the same
    lateral push than open loop (a wrong sign would amplify the lean)."""
    pytest.importorskip("mujoco")
    from footsim import config as fconf
    from footsim.geometry import Pose2D
    from footsim.scene import Scene
    from footsim.walk.footsteps import DoubleStep

    def max_roll(gain: float) -> float:
        cfg = fconf.load_preset("backend", {"name": "mujoco", "stabilizer": {"hip_roll": gain}})
        backend = fconf.build_backend(
            cfg, fconf.build_robot("wolfgang"), fconf.build_walk(fconf.load_preset("walk", "mujoco"))
        )
        try:
            backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
            backend.sim.apply_base_force(np.array([0.0, 6.0, 0.0]))
            rolls = []
            advance = backend.sim.advance

            def watched(n):
                advance(n)
                rolls.append(abs(fused_roll_pitch(backend.sim.base_pose()[1])[0]))

            backend.sim.advance = watched
            backend.execute(DoubleStep.from_action(np.zeros(6), backend.robot.step_limits))
            return max(rolls)
        finally:
            backend.close()

    assert max_roll(0.6) < max_roll(0.0)


def test_step_result_reports_the_trunk_tilt():
    """The driver reports the fused roll/pitch at the end of a double step and the largest tilt
    seen during it, from its own checks of the base (independent check: the sim's base pose)."""
    pytest.importorskip("mujoco")
    from footsim.geometry import Pose2D
    from footsim.scene import Scene
    from footsim.walk.footsteps import DoubleStep

    backend = make_backend("mujoco")
    try:
        backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
        result = backend.execute(DoubleStep.from_action(np.array([1.0, 0, 0, 1.0, 0, 0]), backend.robot.step_limits))
        assert result.max_tilt < 0.7  # no fall (the default fall threshold)
        np.testing.assert_allclose(result.tilt, fused_roll_pitch(backend.sim.base_pose()[1]), atol=1e-12)
        assert max(abs(result.tilt[0]), abs(result.tilt[1])) <= result.max_tilt < backend.fall_threshold
        assert result.max_tilt > 0.01  # walking at max step does tilt the trunk
    finally:
        backend.close()


def test_quaternion_tilt_matches_the_rotation_matrix_route():
    """The control law reads the tilt straight from the base quaternion; compare with MuJoCo's
    own quaternion → matrix conversion followed by the fused angles."""
    mujoco = pytest.importorskip("mujoco")

    rng = np.random.default_rng(0)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, q)
        assert base_tilt(q, False, None) == pytest.approx(fused_roll_pitch(mat.reshape(3, 3)), abs=1e-12)


def test_quaternion_tilt_of_a_body_in_another_frame():
    """Bullet's quaternion (x, y, z, w) is the orientation of the base's inertial frame; the tilt
    is the link frame's: R_link = R_body @ frameᵀ (scipy's independent conversion)."""
    rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    rng = np.random.default_rng(1)
    for _ in range(200):
        body = rotation.random(random_state=rng)
        frame = rotation.random(random_state=rng).as_matrix()
        link = body.as_matrix() @ frame.T
        expected = fused_roll_pitch(link)
        assert base_tilt(body.as_quat(), True, np.ascontiguousarray(frame)) == pytest.approx(expected, abs=1e-12)
