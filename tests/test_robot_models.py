"""The robot spec and the models generated from it (MJCF for MuJoCo/dm-control, URDF for PyBullet).

Expectations come from outside the code under test: the public Wolfgang-OP numbers (FACTS.md),
independent parsers (MuJoCo, dm_control, PyBullet, urdfdom's check_urdf), and a forward
kinematics written here from LegGeometry and the joint convention alone.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from footsim.robots.registry import get_robot, robot_from_config
from footsim.robots.spec import Box, Inertial, Joint, Link, RobotSpec, ServoParams, sole_frame_name
from footsim.robots.wolfgang import wolfgang
from footsim.walk.ik import LegGeometry

mujoco = pytest.importorskip("mujoco")

LEG = ("HipYaw", "HipRoll", "HipPitch", "Knee", "AnklePitch", "AnkleRoll")
EXPECTED_JOINTS = (
    {s + j for s in "LR" for j in LEG}
    | {s + j for s in "LR" for j in ("ShoulderPitch", "ShoulderRoll", "Elbow")}
    | {"HeadPan", "HeadTilt"}
)


@pytest.fixture(scope="module")
def spec():
    return wolfgang()


@pytest.fixture(scope="module")
def mj(spec):
    from footsim.robots.mjcf import build_mjcf

    return build_mjcf(spec)


@pytest.fixture(scope="module")
def urdf_text(spec):
    from footsim.robots.urdf import urdf_xml

    return urdf_xml(spec)


@pytest.fixture(scope="module")
def bullet(urdf_text, tmp_path_factory):
    pybullet = pytest.importorskip("pybullet")
    path = tmp_path_factory.mktemp("urdf") / "wolfgang.urdf"
    path.write_text(urdf_text)
    client = pybullet.connect(pybullet.DIRECT)
    body = pybullet.loadURDF(str(path), physicsClientId=client)
    yield pybullet, client, body
    pybullet.disconnect(client)


# ---- independent kinematics: LegGeometry + the convention, nothing from footsim.robots -----


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return {
        "x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def leg_fk(legs: LegGeometry, side: str, q6) -> tuple[np.ndarray, np.ndarray]:
    """Sole position and orientation in the base frame from LegGeometry (chain yaw z, roll x,
    pitch y, knee y, ankle pitch y, ankle roll x; segments straight down)."""
    yaw, roll, pitch, knee, ankle_pitch, ankle_roll = q6
    sign = 1.0 if side == "left" else -1.0
    pos = np.array([0.0, sign * legs.hip_offset_y, 0.0])
    rot = _rot("z", yaw)
    pos = pos + rot @ [0, 0, -legs.hip_offset_z]
    rot = rot @ _rot("x", roll) @ _rot("y", pitch)
    pos = pos + rot @ [0, 0, -legs.thigh]
    rot = rot @ _rot("y", knee)
    pos = pos + rot @ [0, 0, -legs.shin]
    rot = rot @ _rot("y", ankle_pitch) @ _rot("x", ankle_roll)
    return pos + rot @ [0, 0, -legs.ankle_to_sole], rot


def mujoco_sole(mj, spec, q: dict[str, float], side: str) -> tuple[np.ndarray, np.ndarray]:
    """Sole site pose relative to the torso frame, base placed at the origin."""
    from footsim.robots.mjcf import FREE_JOINT, sole_site

    model = mj.model
    data = mujoco.MjData(model)
    adr = model.jnt_qposadr[model.joint(FREE_JOINT).id]
    data.qpos[adr : adr + 7] = [0, 0, 0, 1, 0, 0, 0]
    for name, angle in q.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = angle
    mujoco.mj_kinematics(model, data)
    site = model.site(sole_site(side)).id
    return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()


def bullet_index(bullet) -> dict[str, int]:
    pybullet, client, body = bullet
    out = {}
    for i in range(pybullet.getNumJoints(body, physicsClientId=client)):
        info = pybullet.getJointInfo(body, i, physicsClientId=client)
        out[info[1].decode()] = i
        out["link:" + info[12].decode()] = i
    return out


def bullet_sole(bullet, spec, q: dict[str, float], side: str) -> tuple[np.ndarray, np.ndarray]:
    """Sole link frame relative to the torso URDF frame (PyBullet places the base by its COM)."""
    pybullet, client, body = bullet
    index = bullet_index(bullet)
    com_local = np.array(pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[3])
    pybullet.resetBasePositionAndOrientation(body, com_local.tolist(), [0, 0, 0, 1], physicsClientId=client)
    for name in spec.joint_names:  # every joint: the body keeps the previous call's angles
        pybullet.resetJointState(body, index[name], q.get(name, 0.0), physicsClientId=client)
    state = pybullet.getLinkState(
        body, index["link:" + sole_frame_name(side)], computeForwardKinematics=True, physicsClientId=client
    )
    rot = np.array(pybullet.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    return np.array(state[4]), rot


def random_configs(spec, n: int, seed: int) -> list[dict[str, float]]:
    rng = np.random.default_rng(seed)
    configs = []
    for _ in range(n):
        configs.append({j.name: float(rng.uniform(j.lower, j.upper)) for j in spec.joints})
    return configs


def leg_q(spec, q: dict[str, float], side: str) -> list[float]:
    return [q.get(name, 0.0) for name in spec.leg_joint_names(side)]


# ---- the spec -------------------------------------------------------------------------------


def test_wolfgang_has_the_real_robots_20_joints_and_mass(spec):
    assert spec.dof == 20
    assert set(spec.joint_names) == EXPECTED_JOINTS
    assert spec.total_mass == pytest.approx(6.117, abs=0.01)
    per_leg = sum(
        spec.link(f"l_{n}").inertial.mass for n in ("hip_1", "hip_2", "upper_leg", "lower_leg", "ankle", "foot")
    )
    assert per_leg == pytest.approx(1.307, abs=0.01)  # FACTS: each leg 1.307 kg (+ cleats)
    assert spec.link("torso").inertial.mass == pytest.approx(2.084)
    assert spec.link("torso").inertial.com[2] == pytest.approx(0.110)
    assert (spec.foot_length, spec.foot_width) == (0.154, 0.106)
    assert (spec.step_limits.x, spec.step_limits.y, spec.step_limits.theta) == (0.156, 0.103, 0.764)


def test_leg_geometry_is_the_public_chain(spec):
    legs = spec.leg_geometry
    assert (legs.hip_offset_y, legs.hip_offset_z, legs.thigh, legs.shin, legs.ankle_to_sole) == pytest.approx(
        (0.055, 0.0414, 0.169, 0.170, 0.0529)
    )
    assert spec.leg_joint_names("left") == tuple("L" + j for j in LEG)
    assert spec.leg_joint_names("R") == tuple("R" + j for j in LEG)
    assert spec.leg_limits("left").shape == (6, 2)
    assert spec.leg_limits("right")[1] == pytest.approx((spec.joint("RHipRoll").lower, spec.joint("RHipRoll").upper))
    with pytest.raises(ValueError, match="side"):
        spec.leg_joint_names("middle")
    # Straight legs: torso origin -> sole 0.433 m (FACTS).
    assert -spec.sole_transform("left")[2, 3] == pytest.approx(0.4333, abs=1e-6)


def test_right_leg_mirrors_the_left(spec):
    for joint in LEG + ("ShoulderPitch", "ShoulderRoll", "Elbow"):
        left, right = spec.joint("L" + joint), spec.joint("R" + joint)
        if joint in ("HipYaw", "HipRoll", "AnkleRoll", "ShoulderRoll"):
            assert (right.lower, right.upper) == pytest.approx((-left.upper, -left.lower))
        else:
            assert (right.lower, right.upper) == pytest.approx((left.lower, left.upper))
        assert right.effort == left.effort and right.servo == left.servo
    assert spec.joint("LKnee").effort == 12.9 and spec.joint("LHipPitch").effort == 10.0
    assert spec.joint("HeadPan").effort == 7.3 and spec.joint("LElbow").velocity == 8.17


def test_walk_ready_pose_stands_flat_at_walk_height(spec):
    q = spec.walk_ready
    assert set(q) == EXPECTED_JOINTS
    for side, sign in (("left", 1), ("right", -1)):
        pos, rot = leg_fk(spec.leg_geometry, side, leg_q(spec, q, side))
        assert pos[2] == pytest.approx(-0.3948, abs=1e-9)  # WalkParams.trunk_height
        assert pos[1] == pytest.approx(sign * 0.1799 / 2, abs=1e-9)  # WalkParams.foot_distance
        assert pos[0] == pytest.approx(0.0, abs=1e-9)
        np.testing.assert_allclose(rot, np.eye(3), atol=1e-9)  # foot flat
    # A crouch in our convention, close to the real robot's 5.8° hip roll.
    assert q["LHipPitch"] < 0 < q["LKnee"] and q["LAnklePitch"] < 0
    assert math.degrees(q["LHipRoll"]) == pytest.approx(5.8, abs=1.5)


def _solve_leg(spec, side: str, target_pos, target_rot, guess):
    from scipy.optimize import least_squares

    legs = spec.leg_geometry

    def residual(q6):
        pos, rot = leg_fk(legs, side, q6)
        return np.concatenate([pos - target_pos, 0.1 * (rot - target_rot).ravel()])

    sol = least_squares(residual, guess, xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert np.abs(residual(sol.x)).max() < 1e-7, "workspace sample not reachable"
    return sol.x


def test_joint_limits_contain_the_walking_workspace(spec):
    """Feet flat on the ground, trunk 0.36-0.43 m above the sole and pitched -0.2..0.3 rad,
    steps up to 0.156 m forward/back, 0.103 m sideways, ±0.764 rad yaw, flying foot lifted up to
    0.1 m: numerical IK (on the independent FK) must land inside the joint limits."""
    rng = np.random.default_rng(7)
    legs = spec.leg_geometry
    checked = 0
    for side, sign in (("left", 1.0), ("right", -1.0)):
        guess = np.array(leg_q(spec, spec.walk_ready, side))
        lows = np.array([spec.joint(n).lower for n in spec.leg_joint_names(side)])
        highs = np.array([spec.joint(n).upper for n in spec.leg_joint_names(side)])
        for _ in range(60):
            height = rng.uniform(0.36, 0.43)
            trunk_pitch = rng.uniform(-0.2, 0.3)
            lift = rng.choice([0.0, rng.uniform(0.0, 0.1)])
            foot_x = rng.uniform(-0.156, 0.156) * 0.6  # half a step each way + trunk offsets
            foot_y = sign * rng.uniform(0.06, 0.09 + 0.103 * 0.6)
            foot_yaw = rng.uniform(-0.764, 0.764) * 0.6
            # Foot pose in the trunk frame: rotate the world-frame foot pose by -trunk_pitch.
            world_pos = np.array([foot_x, foot_y, -(height - lift)])
            world_rot = _rot("z", foot_yaw)
            trunk_rot = _rot("y", trunk_pitch)
            # Poses beyond the leg's reach (trunk high, foot far) are the walk's problem, not
            # the limits': skip them (the hip pitch point is on the yaw axis, so yaw-free).
            ankle = trunk_rot.T @ (world_pos + world_rot @ [0, 0, legs.ankle_to_sole])
            hip = np.array([0.0, sign * legs.hip_offset_y, -legs.hip_offset_z])
            if np.linalg.norm(ankle - hip) > 0.995 * (legs.thigh + legs.shin):
                continue
            checked += 1
            q6 = _solve_leg(spec, side, trunk_rot.T @ world_pos, trunk_rot.T @ world_rot, guess)
            assert np.all(q6 >= lows) and np.all(q6 <= highs), (side, q6.round(3), lows, highs)
    assert checked >= 80  # most of the 120 samples are reachable


def test_bad_specs_are_rejected():
    servo = ServoParams(kp=1.0, damping=0.0, armature=0.0, frictionloss=0.0)
    link = Link("a", Inertial(1.0, inertia=(1e-3, 1e-3, 1e-3)))
    with pytest.raises(ValueError, match="mass"):
        Inertial(-1.0)
    with pytest.raises(ValueError, match="not a physical inertia"):
        Inertial(1.0, inertia=(1.0, 0.1, 0.1))
    with pytest.raises(ValueError, match="lower limit"):
        Joint("j", "a", "b", (0, 0, 1), 1.0, -1.0, 1.0, 1.0, servo)
    with pytest.raises(ValueError, match="axis"):
        Joint("j", "a", "b", (0, 0, 0), -1.0, 1.0, 1.0, 1.0, servo)
    with pytest.raises(ValueError, match="axis"):
        Joint("j", "a", "b", (0, float("nan"), 1), -1.0, 1.0, 1.0, 1.0, servo)
    with pytest.raises(ValueError, match="Box.size"):
        Box((0.1, -0.1, 0.1))
    joint = Joint("j", "a", "b", (0, 0, 1), -1.0, 1.0, 1.0, 1.0, servo)
    with pytest.raises(ValueError, match="does not exist"):
        RobotSpec("r", base_link="a", links=(link,), joints=(joint,))
    orphan = Link("c", Inertial(1.0, inertia=(1e-3, 1e-3, 1e-3)))
    with pytest.raises(ValueError, match="not connected"):
        RobotSpec("r", base_link="a", links=(link, orphan))
    b = Link("b", Inertial(1.0, inertia=(1e-3, 1e-3, 1e-3)))
    with pytest.raises(ValueError, match="outside"):
        RobotSpec("r", base_link="a", links=(link, b), joints=(joint,), walk_ready={"j": 2.0})
    with pytest.raises(ValueError, match="unknown joint"):
        RobotSpec("r", base_link="a", links=(link, b), joints=(joint,), walk_ready={"k": 0.0})
    with pytest.raises(ValueError, match="no kinematic model"):
        _ = RobotSpec("flat").leg_geometry
    with pytest.raises(ValueError, match="unknown joint"):
        wolfgang().link_transforms({"LToe": 0.1})
    with pytest.raises(ValueError, match="finite"):
        wolfgang().link_transforms({"LKnee": float("nan")})
    from footsim.robots.mjcf import build_mjcf
    from footsim.robots.urdf import build_urdf

    with pytest.raises(ValueError, match="timestep"):
        build_mjcf(wolfgang(), timestep=0.0)
    with pytest.raises(ValueError, match="no kinematic model"):
        build_urdf(RobotSpec("flat"))


def test_robot_config(spec):
    from footsim.config import load_preset

    cfg = load_preset("robot", "wolfgang")
    assert robot_from_config(cfg).total_mass == pytest.approx(spec.total_mass)
    assert robot_from_config("wolfgang").dof == 20
    with pytest.raises(ValueError, match="unknown robot config key"):
        robot_from_config({"name": "wolfgang", "mass": 7.0})
    with pytest.raises(ValueError, match="needs a 'name'"):
        robot_from_config({})
    with pytest.raises(ValueError, match="valid robots"):
        get_robot("nao")


# ---- MJCF -----------------------------------------------------------------------------------


def test_mujoco_compiles_the_mjcf_with_servos(spec, mj):
    from footsim.robots.mjcf import FREE_JOINT, IMU_SITE, sole_site

    model = mujoco.MjModel.from_xml_string(mj.xml)  # the XML alone, not just the spec
    assert model.nu == 20 and model.njnt == 21 and model.nq == 27
    assert model.jnt_type[model.joint(FREE_JOINT).id] == mujoco.mjtJoint.mjJNT_FREE
    assert model.body(model.jnt_bodyid[model.joint(FREE_JOINT).id]).name == "torso"
    assert float(model.body_mass.sum()) == pytest.approx(6.117, abs=0.01)
    for joint in spec.joints:
        act = model.actuator(joint.name)
        assert model.joint(act.trnid[0]).name == joint.name
        assert act.gainprm[0] == pytest.approx(joint.servo.kp)
        assert act.biasprm[1] == pytest.approx(-joint.servo.kp)
        assert tuple(act.forcerange) == pytest.approx((-joint.effort, joint.effort))
        mj_joint = model.joint(joint.name)
        assert tuple(mj_joint.range) == pytest.approx((joint.lower, joint.upper))
        assert mj_joint.armature[0] == pytest.approx(joint.servo.armature)
        assert mj_joint.damping[0] == pytest.approx(joint.servo.damping)
    for name in (sole_site("left"), sole_site("right"), IMU_SITE):
        model.site(name)
    for sensor in ("imu_gyro", "imu_accel", "imu_quat"):
        model.sensor(sensor)
    # Sole plate: the spec's foot size, bottom face on the sole frame.
    plate = model.geom("l_foot_collision0")
    assert 2 * plate.size[:2] == pytest.approx([0.154, 0.106])
    assert plate.pos[2] - plate.size[2] == pytest.approx(-0.0529)


def test_dm_control_parses_the_mjcf(mj):
    dm_mjcf = pytest.importorskip("dm_control.mjcf")
    root = dm_mjcf.from_xml_string(mj.xml)
    assert len(root.find_all("actuator")) == 20
    assert {j.name for j in root.find_all("joint") if j.type != "free"} == EXPECTED_JOINTS
    physics = dm_mjcf.Physics.from_mjcf_model(root)
    assert physics.model.nu == 20
    physics.step()


def test_mujoco_sole_matches_hand_kinematics(spec, mj):
    legs = spec.leg_geometry
    total = legs.hip_offset_z + legs.thigh + legs.shin + legs.ankle_to_sole
    # By hand: straight legs; thigh swung 90° forward; hip yaw 90° (hip roll axis -> -y... the
    # leg still hangs straight below the hip).
    cases = [
        ({}, "left", [0.0, 0.055, -total]),
        ({}, "right", [0.0, -0.055, -total]),
        ({"LHipPitch": -math.pi / 2}, "left", [legs.thigh + legs.shin + legs.ankle_to_sole, 0.055, -legs.hip_offset_z]),
        (
            {"RHipRoll": -0.5},
            "right",
            [
                0.0,
                -0.055 - (total - legs.hip_offset_z) * math.sin(0.5),
                -legs.hip_offset_z - (total - legs.hip_offset_z) * math.cos(0.5),
            ],
        ),
        ({"LKnee": math.pi / 2}, "left", [-(legs.shin + legs.ankle_to_sole), 0.055, -legs.hip_offset_z - legs.thigh]),
    ]
    for q, side, expected in cases:
        pos, _ = mujoco_sole(mj, spec, q, side)
        np.testing.assert_allclose(pos, expected, atol=1e-9, err_msg=str(q))
    # Random configurations against the independent chain (position and orientation).
    for q in random_configs(spec, 10, seed=1) + [spec.walk_ready]:
        for side in ("left", "right"):
            pos, rot = mujoco_sole(mj, spec, q, side)
            ref_pos, ref_rot = leg_fk(legs, side, leg_q(spec, q, side))
            np.testing.assert_allclose(pos, ref_pos, atol=1e-9)
            np.testing.assert_allclose(rot, ref_rot, atol=1e-9)


def test_walk_engine_ik_drives_the_mujoco_sole_where_asked(spec, mj):
    """The walk package's IK, with this spec's leg geometry and limits, lands MuJoCo's sole site
    on the target: the IK and the generated model share one convention."""
    ik = pytest.importorskip("footsim.walk.ik")
    if not hasattr(ik, "leg_ik"):
        pytest.skip("footsim.walk.ik has no leg_ik yet")
    rng = np.random.default_rng(11)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        for _ in range(10):
            target = np.array([rng.uniform(-0.08, 0.08), sign * rng.uniform(0.06, 0.13), -rng.uniform(0.33, 0.40)])
            rpy = np.array([0.0, 0.0, rng.uniform(-0.38, 0.38)])
            q6, reachable = ik.leg_ik(target[None], rpy[None], side, spec.leg_geometry, spec.leg_limits(side))
            assert reachable[0]
            q = dict(zip(spec.leg_joint_names(side), q6[0]))
            pos, rot = mujoco_sole(mj, spec, q, side)
            np.testing.assert_allclose(pos, target, atol=1e-6)
            np.testing.assert_allclose(rot, _rot("z", rpy[2]), atol=1e-6)


def test_mjcf_robot_stands_in_walk_ready_pose(mj):
    """3 s under position control at 2 ms on the floor: stays upright, barely moves."""
    from footsim.robots.mjcf import FREE_JOINT, WALK_READY_KEY

    model = mj.model
    assert model.opt.timestep == pytest.approx(0.002)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(WALK_READY_KEY).id)
    adr = model.jnt_qposadr[model.joint(FREE_JOINT).id]
    start = data.qpos[adr : adr + 3].copy()
    for _ in range(1500):
        mujoco.mj_step(model, data)
    up = np.zeros(9)
    mujoco.mju_quat2Mat(up, data.qpos[adr + 3 : adr + 7])
    tilt = math.degrees(math.acos(min(1.0, up[8])))
    assert tilt < 5.0
    assert abs(data.qpos[adr + 2] - start[2]) < 0.01
    assert np.linalg.norm(data.qpos[adr : adr + 2] - start[:2]) < 0.02
    assert np.abs(data.qvel).max() < 0.01  # at rest


# ---- URDF -----------------------------------------------------------------------------------


def test_urdf_has_every_link_and_joint(spec, urdf_text):
    robot = ET.fromstring(urdf_text)
    links = {e.get("name"): e for e in robot.findall("link")}
    joints = {e.get("name"): e for e in robot.findall("joint")}
    assert set(spec.link_names) | {"l_sole", "r_sole"} == set(links)
    assert {n for n, e in joints.items() if e.get("type") == "revolute"} == EXPECTED_JOINTS
    assert sum(float(e.find("inertial/mass").get("value")) for e in links.values()) == pytest.approx(6.117, abs=0.01)
    # Capsules become a cylinder plus two spheres.
    thigh = [g[0].tag for g in links["l_upper_leg"].findall("collision/geometry")]
    assert sorted(thigh) == ["cylinder", "sphere", "sphere"]


def test_check_urdf_accepts_the_urdf(urdf_text, tmp_path):
    tool = shutil.which("check_urdf")
    if tool is None:
        pytest.skip("check_urdf not installed (apt-get install -y liburdfdom-tools)")
    path = tmp_path / "wolfgang.urdf"
    path.write_text(urdf_text)
    result = subprocess.run([tool, str(path)], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Successfully Parsed XML" in result.stdout
    assert "root Link: torso" in result.stdout


def test_pybullet_loads_the_urdf_with_the_spec_numbers(spec, bullet):
    pybullet, client, body = bullet
    index = bullet_index(bullet)
    assert pybullet.getBodyInfo(body, physicsClientId=client)[0].decode() == "torso"
    total = pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[0]
    assert total == pytest.approx(spec.link("torso").inertial.mass)
    for link in spec.links:
        if link.name == spec.base_link:
            continue
        mass = pybullet.getDynamicsInfo(body, index["link:" + link.name], physicsClientId=client)[0]
        assert mass == pytest.approx(link.inertial.mass), link.name
        total += mass
    assert total == pytest.approx(6.117, abs=0.01)
    for joint in spec.joints:
        info = pybullet.getJointInfo(body, index[joint.name], physicsClientId=client)
        assert info[2] == pybullet.JOINT_REVOLUTE
        assert (info[8], info[9]) == pytest.approx((joint.lower, joint.upper))
        assert info[10] == pytest.approx(joint.effort) and info[11] == pytest.approx(joint.velocity)
        assert info[13] == pytest.approx(joint.axis)
        assert info[12].decode() == joint.child


def test_mujoco_and_pybullet_agree(spec, mj, bullet):
    """Per-link mass, joint axes and limits, and each leg's sole pose for random angles."""
    pybullet, client, body = bullet
    index = bullet_index(bullet)
    model = mj.model
    for link in spec.links:
        mj_mass = model.body_mass[model.body(link.name).id]
        pb_link = -1 if link.name == spec.base_link else index["link:" + link.name]
        assert mj_mass == pytest.approx(pybullet.getDynamicsInfo(body, pb_link, physicsClientId=client)[0])
    for joint in spec.joints:
        info = pybullet.getJointInfo(body, index[joint.name], physicsClientId=client)
        mj_joint = model.joint(joint.name)
        assert tuple(mj_joint.range) == pytest.approx((info[8], info[9]))
        assert tuple(mj_joint.axis) == pytest.approx(info[13])
    for q in random_configs(spec, 20, seed=3) + [spec.walk_ready, {}]:
        for side in ("left", "right"):
            mj_pos, mj_rot = mujoco_sole(mj, spec, q, side)
            pb_pos, pb_rot = bullet_sole(bullet, spec, q, side)
            assert np.linalg.norm(mj_pos - pb_pos) < 1e-3
            np.testing.assert_allclose(mj_rot, pb_rot, atol=1e-6)


# ---- CLI ------------------------------------------------------------------------------------


def test_cli_writes_models(tmp_path, capsys):
    from footsim.tools.model import main

    out = tmp_path / "w.xml"
    assert main(["robot=wolfgang", "format=mjcf", f"out={out}"]) == 0
    assert mujoco.MjModel.from_xml_path(str(out)).nu == 20
    out = tmp_path / "sub" / "w.urdf"
    assert main(["format=urdf", f"out={out}"]) == 0
    assert ET.parse(out).getroot().get("name") == "wolfgang"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["format=mjcf"], "missing out="),
        (["out=x.xml"], "missing format="),
        (["format=sdf", "out=x"], "format must be one of mjcf, urdf"),
        (["robot=nao", "format=mjcf", "out=x"], "unknown robot 'nao'"),
        (["colour=red", "format=mjcf", "out=x"], "unknown key 'colour'"),
        (["format", "out=x"], "expected key=value"),
        (["format=mjcf", "format=urdf", "out=x"], "given twice"),
    ],
)
def test_cli_rejects_bad_arguments(argv, message, capsys):
    from footsim.tools.model import main

    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_missing_mujoco_names_the_extra(monkeypatch, spec):
    import builtins

    from footsim.robots import mjcf

    real_import = builtins.__import__

    def no_mujoco(name, *args, **kwargs):
        if name == "mujoco" or name.startswith("mujoco."):
            raise ImportError("No module named 'mujoco'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_mujoco)
    with pytest.raises(ImportError, match=r"pip install 'footsim\[mujoco\]'"):
        mjcf.build_mjcf(spec)
