"""What the MuJoCo servo options and the left/right symmetry rest on (docs/BACKENDS.md, "What the
servo gains rest on").

Expectations come from outside the code under test: MuJoCo's own MJCF ``ref`` attribute (compiled
from XML by MuJoCo), the spec's forward kinematics, the URDF effort limits (FACTS) and the
Bit-Bots' engine convention for ``trunk_y_offset`` (added in the support-foot frame, unmirrored).
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from footsim.robots.spec import Side
from footsim.robots.wolfgang import wolfgang

mujoco = pytest.importorskip("mujoco")

from footsim.backends.mujoco_family.mujoco_sim import MujocoSim  # noqa: E402
from footsim.robots.mjcf import build_mjcf, sole_site  # noqa: E402

PHYSICS_DT = 0.002
KNEE_REFS = {"RKnee": 0.15, "LKnee": -0.15}  # the Bit-Bots' MuJoCo model (FACTS)


@pytest.fixture(scope="module")
def spec():
    return wolfgang()


def _sim(spec, **options) -> MujocoSim:
    sim = MujocoSim(**options)
    sim.build(spec, PHYSICS_DT)
    return sim


def _soles(model, data) -> np.ndarray:
    """(2, 12): each sole site's position and rotation after forward kinematics."""
    mujoco.mj_kinematics(model, data)
    rows = []
    for side in ("left", "right"):
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, sole_site(side))
        rows.append(np.concatenate([data.site_xpos[site], data.site_xmat[site]]))
    return np.array(rows)


def test_joint_ref_is_mujocos_ref_attribute(spec):
    """The option on the compiled model equals MuJoCo compiling ``ref`` from the MJCF."""
    xml = ET.fromstring(build_mjcf(spec, timestep=PHYSICS_DT, rigid_upper_body=True).xml)
    for joint in xml.iter("joint"):
        if joint.get("name") in KNEE_REFS:
            joint.set("ref", str(KNEE_REFS[joint.get("name")]))
    reference = mujoco.MjModel.from_xml_string(ET.tostring(xml, encoding="unicode"))
    ref_data = mujoco.MjData(reference)
    sim = _sim(spec, joint_ref=KNEE_REFS)
    q = spec.walk_ready
    for name in sim.joint_names:
        ref_data.qpos[reference.jnt_qposadr[mujoco.mj_name2id(reference, mujoco.mjtObj.mjOBJ_JOINT, name)]] = q[name]
        sim.data.qpos[sim.joint_qpos[name]] = q[name]
    ref_data.qpos[3:7] = sim.data.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
    # The XML keeps 6 significant digits of every figure: agreement to 1e-5 (m, rotation entries).
    np.testing.assert_allclose(_soles(sim.model, sim.data), _soles(reference, ref_data), atol=1e-5)


def test_knee_ref_bends_the_knee_by_ref_more_than_its_angle(spec):
    """FACTS' reading of the Bit-Bots' knees: the knee sits 0.15 rad more flexed than commanded.
    The sole in the torso frame must be the spec's FK at the knee angles flexed by 0.15 rad."""
    sim = _sim(spec, joint_ref=KNEE_REFS)
    q = dict(spec.walk_ready)
    for name in sim.joint_names:
        sim.data.qpos[sim.joint_qpos[name]] = q[name]
    sim.data.qpos[:7] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)  # torso frame = world frame
    soles = _soles(sim.model, sim.data)
    flexed = {**q, "LKnee": q["LKnee"] + 0.15, "RKnee": q["RKnee"] - 0.15}  # left flexes +, right -
    assert q["LKnee"] > 0 > q["RKnee"]
    for row, side in zip(soles, (Side.LEFT, Side.RIGHT)):
        expected = spec.sole_transform(side, flexed)
        np.testing.assert_allclose(row[:3], expected[:3, 3], atol=1e-9)
        np.testing.assert_allclose(row[3:].reshape(3, 3), expected[:3, :3], atol=1e-9)
        plain = spec.sole_transform(side, q)
        assert np.linalg.norm(row[:3] - plain[:3, 3]) > 0.01  # the option does move the foot


def test_servo_force_limit_caps_every_actuator(spec):
    """Default: each servo's URDF effort (FACTS: MX-106 10 N·m, XH540 12.9 N·m); with the option
    ±12 N·m on every joint, as in the Bit-Bots' MuJoCo model."""
    for options, expected in (({}, {"LHipPitch": 10.0, "LKnee": 12.9}), ({"servo_force_limit": 12.0}, None)):
        sim = _sim(spec, **options)
        m, d = sim.model, sim.data
        for name in sim.joint_names:
            d.qpos[sim.joint_qpos[name]] = 0.0
            d.ctrl[sim.actuator[name]] = m.actuator_ctrlrange[sim.actuator[name], 1]  # far from q: saturates
        mujoco.mj_forward(m, d)
        for name in ("LHipPitch", "LKnee", "RAnkleRoll"):
            force = abs(d.actuator_force[sim.actuator[name]])
            limit = 12.0 if expected is None else expected.get(name, 10.0)
            assert force == pytest.approx(limit), (name, options)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"servo_force_limit": -1.0}, "backend.servo_force_limit"),
        ({"servo_force_limit": float("nan")}, "backend.servo_force_limit"),
        ({"joint_ref": {"RKnee": float("inf")}}, "backend.joint_ref.RKnee"),
        ({"joint_ref": {"RKnee": "0.15"}}, "backend.joint_ref.RKnee"),
    ],
)
def test_bad_servo_options_are_refused(options, message):
    with pytest.raises(ValueError, match=message.replace(".", r"\.")):
        MujocoSim(**options)


def test_joint_ref_names_a_missing_joint(spec):
    with pytest.raises(ValueError, match="backend.joint_ref: the model has no joint 'LShoulderPitch'"):
        _sim(spec, joint_ref={"LShoulderPitch": 0.1})  # welded by the rigid upper body


def _in_place_halves(spec, trunk_y_offset: float):
    from footsim.config import load_preset
    from footsim.walk import DoubleStep, Footstep, QuinticWalk, WalkParams
    from footsim.walk.footsteps import FootstepGeometry

    params = dataclasses.replace(
        WalkParams.from_mapping(load_preset("walk", "bitbots_sim")), trunk_y_offset=trunk_y_offset
    )
    geometry = FootstepGeometry(spec.step_limits, spec.foot_length, spec.foot_width, params.foot_distance)
    limits = np.vstack([spec.leg_limits(Side.LEFT), spec.leg_limits(Side.RIGHT)])
    engine = QuinticWalk(params, geometry, spec.leg_geometry, 0.008, joint_limits=limits)
    still = DoubleStep(Footstep(0.0, 0.0, 0.0), Footstep(0.0, 0.0, 0.0))
    for _ in range(4):  # past the start movement and the first step: a steady in-place gait
        trajectory = engine.double_step(still)
    n = len(trajectory) // 2
    assert len(trajectory) == 2 * n
    return trajectory, n


def test_walking_in_place_is_mirror_symmetric_by_fk(spec):
    """Without the gait's lateral trunk offset, the right-support half of a steady in-place double
    step is the mirror image (y → −y) of the left-support half: each sole's pose in the torso
    frame, by the spec's FK of the engine's joint targets, against the other sole's mirrored pose
    one half step earlier.  Bound: the URDF's own left/right differences (≈ 1.6 mm, FACTS' joint
    table), far below the centimetres a sign error would give."""
    from footsim.walk.ik import LEG_JOINT_NAMES

    trajectory, n = _in_place_halves(spec, 0.0)
    mirror = np.diag([1.0, -1.0, 1.0])
    worst_position = worst_rotation = 0.0
    for k in range(n):
        first = dict(zip(LEG_JOINT_NAMES, trajectory.joint_targets[k]))
        second = dict(zip(LEG_JOINT_NAMES, trajectory.joint_targets[n + k]))
        for side in (Side.LEFT, Side.RIGHT):
            now = spec.sole_transform(side, second)
            before = spec.sole_transform(side.other, first)
            worst_position = max(worst_position, np.abs(now[:3, 3] - mirror @ before[:3, 3]).max())
            worst_rotation = max(worst_rotation, np.abs(now[:3, :3] - mirror @ before[:3, :3] @ mirror).max())
    assert worst_position < 0.002
    assert worst_rotation < 0.01


def test_trunk_y_offset_is_unmirrored_as_in_the_bitbots_engine(spec):
    """The Bit-Bots' engine adds trunk_y_offset in the support-foot frame on either foot, so the
    trunk sits 2 × offset closer to +y over a double step than the mirror image: the gait's one
    intended left/right asymmetry (bitbots_sim: 3.7 mm)."""
    offset = 0.00369752824507733
    symmetric, n = _in_place_halves(spec, 0.0)
    biased, _ = _in_place_halves(spec, offset)
    y0, y1 = symmetric.trunk_in_support[:, 1], biased.trunk_in_support[:, 1]
    assert y0[:n].mean() == pytest.approx(-y0[n:].mean(), abs=1e-9)
    assert y1[:n].mean() + y1[n:].mean() == pytest.approx(2 * offset, abs=1e-6)


def test_joint_ref_reproduces_the_old_right_ankle_origin(spec):
    """The docs' ``joint_ref={RAnkleRoll: -0.02247}`` is the pre-2026-03 URDF's RAnkleRoll origin
    pitch 1.54833 instead of 1.5708 (FACTS, "Foot, sole and cleats"), still in the Bit-Bots' MuJoCo
    model: the right sole by FK with that origin equals the sim's right sole with the option."""
    from scipy.spatial.transform import Rotation

    from footsim.robots.spec import Origin

    sim = _sim(spec, joint_ref={"RAnkleRoll": -(1.5708 - 1.54833)})
    q = dict(spec.walk_ready)
    for name in sim.joint_names:
        sim.data.qpos[sim.joint_qpos[name]] = q[name]
    sim.data.qpos[:7] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    right = _soles(sim.model, sim.data)[1]
    joint = spec.joint("RAnkleRoll")
    old_origin = Origin(joint.origin.xyz, (joint.origin.rpy[0], 1.54833, joint.origin.rpy[2])).matrix
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_rotvec(np.asarray(joint.axis, float) * q["RAnkleRoll"]).as_matrix()
    expected = spec.link_transforms(q)["r_ankle"] @ old_origin @ turn @ spec.sole(Side.RIGHT)[1].matrix
    np.testing.assert_allclose(right[:3], expected[:3, 3], atol=1e-9)
    np.testing.assert_allclose(right[3:].reshape(3, 3), expected[:3, :3], atol=1e-9)
    assert np.degrees(np.arcsin(expected[1, 2])) == pytest.approx(1.29, abs=0.01)  # FACTS: 1.29° roll


@pytest.mark.parametrize("capped", [False, True])
def test_pybullet_motor_max_velocity_caps_at_the_urdf_velocity(spec, capped):
    """``backend.motor_max_velocity`` passes each joint's URDF velocity limit as the position motor's
    maxVelocity, as the Bit-Bots' PyBullet setup does: a 1 rad target step of the right hip yaw then
    moves the joint no faster than the MX-106's 5.76 rad/s (FACTS); uncapped it moves faster."""
    pb = pytest.importorskip("pybullet")
    from footsim.backends.bullet.sim import PybulletSim
    from footsim.walk.ik import LEG_JOINT_NAMES

    sim = PybulletSim(motor_max_velocity=capped, armature_scale=1.0, solver_iterations=10)
    sim.build(spec, 1 / 240)
    try:
        q = dict(spec.walk_ready)
        sim.reset_robot(np.array([0.0, 0.0, 0.5]), q)
        leg = LEG_JOINT_NAMES.index("RHipYaw")
        for i, name in enumerate(LEG_JOINT_NAMES):
            sim.state.command[sim.state.leg_ids[i]] = q[name] + (1.0 if i == leg else 0.0)
        sim.write_command()
        fastest = 0.0
        for _ in range(24):  # 0.1 s
            sim.advance(1)
            state = pb.getJointState(sim.robot_id, sim.leg_indices[leg], physicsClientId=sim.client)
            fastest = max(fastest, abs(state[1]))
        limit = spec.joint("RHipYaw").velocity
        assert limit == 5.76
        if capped:
            assert fastest == pytest.approx(limit, rel=0.01)
        else:
            assert fastest > 1.2 * limit
    finally:
        sim.close()


def test_pybullet_motor_max_velocity_must_be_a_bool():
    pytest.importorskip("pybullet")
    from footsim.backends.bullet.sim import PybulletSim

    with pytest.raises(ValueError, match=r"backend\.motor_max_velocity must be true or false"):
        PybulletSim(motor_max_velocity="yes")


def _first_tick_velocity(spec, error: float, **options) -> float:
    """The right hip yaw's velocity one Bullet tick after its target moves by ``error`` rad."""
    pb = pytest.importorskip("pybullet")
    from footsim.backends.bullet.sim import PybulletSim
    from footsim.walk.ik import LEG_JOINT_NAMES

    sim = PybulletSim(armature_scale=1.0, solver_iterations=10, **options)
    sim.build(spec, 1 / 240)
    try:
        q = dict(spec.walk_ready)
        sim.reset_robot(np.array([0.0, 0.0, 0.5]), q)
        leg = LEG_JOINT_NAMES.index("RHipYaw")
        for i, name in enumerate(LEG_JOINT_NAMES):
            sim.state.command[sim.state.leg_ids[i]] = q[name] + (error if i == leg else 0.0)
        sim.write_command()
        sim.advance(1)
        return pb.getJointState(sim.robot_id, sim.leg_indices[leg], physicsClientId=sim.client)[1]
    finally:
        sim.close()


def test_pybullet_position_gain_is_bullets_velocity_constraint(spec):
    """``backend.position_rate`` r sets Bullet's positionGain to r · dt on every joint: its position
    motor targets the velocity positionGain / dt · (q* − q) = r · (q* − q) (Bullet's velocity-constraint
    form, velocityGain 1 from rest), so at r = 24 /s (positionGain 0.1 at 1/240 s) a 0.01 rad step
    moves the hip yaw at 0.24 rad/s after one tick; the
    servo mapping (position_rate null, scale 1) gives positionGain kp · dt / kd = 45 / 1.7 / 240 and so
    kp / kd · 0.01 = 0.265 rad/s.  (At much smaller gains the solver's 10 iterations fall short of the
    target: 0.05 reaches 0.10, not 0.12.)"""
    assert _first_tick_velocity(spec, 0.01, position_rate=24.0) == pytest.approx(24.0 * 0.01, rel=0.02)
    mapped = _first_tick_velocity(spec, 0.01, position_rate=None, position_gain_scale=1.0)
    assert mapped == pytest.approx(45 / 1.7 * 0.01, rel=0.02)


@pytest.mark.parametrize("rate", [0.0, -24.0, float("nan")])
def test_pybullet_position_rate_out_of_range_is_refused(rate):
    pytest.importorskip("pybullet")
    from footsim.backends.bullet.sim import PybulletSim

    with pytest.raises(ValueError, match=r"backend\.position_rate must be a positive rate \[1/s\] or null"):
        PybulletSim(position_rate=rate)
