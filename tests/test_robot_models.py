"""The robot spec and the models generated from it (MJCF for MuJoCo/dm-control, URDF for PyBullet).

Expectations come from outside the code under test: the public Wolfgang-OP numbers (FACTS.md),
independent parsers (MuJoCo, dm_control, PyBullet, urdfdom's check_urdf), and the URDF table's
own forward kinematics (tests/urdf_table.py, read from FACTS.md).
"""

from __future__ import annotations

import math
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import urdf_table

from footsim.robots.registry import get_robot, robot_from_config
from footsim.robots.spec import Box, Inertial, Joint, Link, RobotSpec, ServoParams, sole_frame_name
from footsim.robots.wolfgang import wolfgang

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


# ---- independent kinematics: the URDF table of FACTS.md (tests/urdf_table.py) ---------------


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return {
        "x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def table_sole(q: dict[str, float], side: str) -> tuple[np.ndarray, np.ndarray]:
    """Sole frame pose in the torso frame by the URDF table's own kinematics."""
    frame = urdf_table.forward_kinematics(q)[f"{side[0]}_sole"]
    return frame[:3, 3], frame[:3, :3]


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


def test_wolfgang_has_the_urdf_links(spec):
    table = urdf_table.links()
    assert spec.dof == 20
    assert set(spec.joint_names) == EXPECTED_JOINTS
    # URDF total 6.1167 kg = the spec's links + base_link's 0.1 g (folded away).
    assert spec.total_mass == pytest.approx(sum(m for m, _, _ in table.values()) - 0.0001, abs=1e-6)
    for link in spec.links:
        mass, com, inertia = table[link.name]
        if link.name.endswith("_foot"):  # the four 1.66 g cleats are folded in
            assert link.inertial.mass == pytest.approx(mass + 4 * 0.00165976, abs=1e-8)
            assert np.linalg.norm(np.subtract(link.inertial.com, com)) < 2e-3
            continue
        assert link.inertial.mass == pytest.approx(mass), link.name
        np.testing.assert_allclose(link.inertial.com, com, atol=1e-12, err_msg=link.name)
        np.testing.assert_allclose(link.inertial.matrix, inertia, atol=1e-12, err_msg=link.name)
    assert (spec.foot_length, spec.foot_width) == (0.154, 0.106)
    assert (spec.step_limits.x, spec.step_limits.y, spec.step_limits.theta) == (0.156, 0.103, 0.764)


def test_wolfgang_has_the_urdf_joints_and_servo_classes(spec):
    table = urdf_table.joints()
    motors = {"Knee": (12.9, 3.87), "Shoulder": (7.3, 8.17), "Elbow": (7.3, 8.17), "Head": (7.3, 8.17)}
    for joint in spec.joints:
        row = table[joint.name]
        assert (joint.parent, joint.child) == (row.parent, row.child)
        np.testing.assert_allclose(joint.origin.xyz, row.xyz, atol=1e-12)
        np.testing.assert_allclose(joint.origin.rpy, row.rpy, atol=1e-12)
        np.testing.assert_allclose(joint.axis, row.axis / np.linalg.norm(row.axis), atol=1e-12)
        assert (joint.lower, joint.upper) == (row.lower, row.upper)
        assert (joint.effort, joint.velocity) == (row.effort, row.velocity)
        expected = next((v for k, v in motors.items() if k in joint.name), (10.0, 5.76))  # MX-106 otherwise
        assert (joint.effort, joint.velocity) == expected, joint.name


def test_model_kinematics_is_the_urdf_table_within_a_millimetre(spec, mj):
    """Sole poses at random joint angles: the spec's FK and the generated MJCF against the URDF
    table's own kinematics (the issue's bound is 1 mm; both agree to numerical precision)."""
    for q in random_configs(spec, 20, seed=3) + [{}, spec.walk_ready]:
        for side in ("left", "right"):
            ref_pos, ref_rot = table_sole(q, side)
            sole = spec.sole_transform(side, q)
            np.testing.assert_allclose(sole[:3, 3], ref_pos, atol=1e-9)
            np.testing.assert_allclose(sole[:3, :3], ref_rot, atol=1e-9)
            pos, rot = mujoco_sole(mj, spec, q, side)
            assert np.abs(pos - ref_pos).max() < 1e-3
            np.testing.assert_allclose(pos, ref_pos, atol=1e-9)
            np.testing.assert_allclose(rot, ref_rot, atol=1e-9)


def test_leg_geometry_is_read_from_the_joints(spec):
    legs = spec.leg_geometry
    for side, sign in (("left", 1.0), ("right", -1.0)):
        chain = legs.chain(side)
        # FACTS "Leg geometry derived from the joint origins": hip-yaw axes at y = ±0.055; hip
        # roll/pitch centre 23.1 mm in front of and 41.4 mm below the yaw point; thigh 0.169, shank
        # 0.170; ankle centre 52.9 mm above, 21.6 mm behind and 15.2 mm inboard of the sole frame.
        assert chain.hip_yaw == pytest.approx((0.0, sign * 0.055, 0.0), abs=1e-9)
        assert chain.hip_centre == pytest.approx((0.0231, 0.0, -0.0414), abs=1e-6)
        assert chain.thigh == pytest.approx(0.169, abs=3e-4) and chain.shin == pytest.approx(0.170, abs=1e-6)
        assert chain.ankle == pytest.approx((-0.0217, -sign * 0.0152, 0.0529), abs=2e-4)
    assert spec.leg_joint_names("left") == tuple("L" + j for j in LEG)
    assert spec.leg_joint_names("R") == tuple("R" + j for j in LEG)
    assert spec.leg_limits("right")[1] == pytest.approx((spec.joint("RHipRoll").lower, spec.joint("RHipRoll").upper))
    with pytest.raises(ValueError, match="side"):
        spec.leg_joint_names("middle")
    assert spec.sole_clearance("left") == pytest.approx(0.0029)  # cleat tips above the sole frame (FACTS)


def test_ik_lands_the_urdf_sole_where_asked(spec):
    """The walk engine's IK with this spec's legs: the URDF table's FK of its answer is the target."""
    from footsim.walk.ik import leg_ik

    rng = np.random.default_rng(11)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        targets = np.column_stack(
            [rng.uniform(-0.08, 0.10, 40), sign * rng.uniform(0.04, 0.14, 40), -rng.uniform(0.32, 0.40, 40)]
        )
        rpy = np.column_stack([rng.uniform(-0.15, 0.15, 40), rng.uniform(-0.25, 0.25, 40), rng.uniform(-0.5, 0.5, 40)])
        q6, reachable = leg_ik(targets, rpy, side, spec.leg_geometry, spec.leg_limits(side))
        assert reachable.all()
        for target, angles, q in zip(targets, rpy, q6):
            pos, rot = table_sole(dict(zip(spec.leg_joint_names(side), q)), side)
            assert np.abs(pos - target).max() < 5e-5  # URDF rounding (1.5708 for pi/2) leaves µm
            np.testing.assert_allclose(
                rot, _rot("z", angles[2]) @ _rot("y", angles[1]) @ _rot("x", angles[0]), atol=2e-4
            )


def test_walk_ready_pose_is_the_real_robots_stance(spec):
    q = spec.walk_ready
    assert {s + j for s in "LR" for j in LEG} <= set(q) <= EXPECTED_JOINTS
    for side, sign in (("left", 1), ("right", -1)):
        pos, rot = table_sole(q, side)
        assert pos[2] == pytest.approx(-0.3948, abs=5e-5)  # walk=bitbots_sim trunk_height
        assert pos[1] == pytest.approx(sign * 0.1799 / 2, abs=5e-5)  # foot_distance
        np.testing.assert_allclose(rot, np.eye(3), atol=2e-4)  # level
    # The Bit-Bots' walk-ready pose (FACTS, left, deg): HipPitch 16.9, Knee 63.8, AnklePitch −31.9,
    # HipRoll 5.8, AnkleRoll 5.8; ours is the same crouch at our stance height (signs and ±6°).
    real = {"LHipPitch": 16.9, "LKnee": 63.8, "LAnklePitch": -31.9, "LHipRoll": 5.8, "LAnkleRoll": 5.8}
    for name, degrees in real.items():
        assert math.degrees(q[name]) == pytest.approx(degrees, abs=6.0), name
        mirror = "R" + name[1:]
        assert q[mirror] == pytest.approx(-q[name], abs=0.01)


def test_joint_limits_contain_the_walking_workspace(spec):
    """Feet level on the ground, trunk 0.37-0.42 m above the sole and pitched -0.1..0.3 rad (the
    Bit-Bots' gaits: trunk_height 0.38-0.395, trunk_pitch 0.11-0.2), steps up to 0.156 m
    forward/back, 0.103 m sideways, ±0.764 rad yaw, flying foot lifted up to 0.09 m: every
    reachable pose (IK checked against the URDF table above) is inside the real joint limits.
    (A 0.36 m trunk pitched 0.3 rad with the foot lifted 0.1 m needs more than the real ankle's
    1.42 rad.)"""
    from footsim.walk.ik import leg_ik

    rng = np.random.default_rng(7)
    checked = 0
    for side, sign in (("left", 1.0), ("right", -1.0)):
        for _ in range(60):
            height, trunk_pitch = rng.uniform(0.37, 0.42), rng.uniform(-0.1, 0.3)
            lift = rng.choice([0.0, rng.uniform(0.0, 0.09)])
            world_pos = np.array(
                [rng.uniform(-0.156, 0.156) * 0.6, sign * rng.uniform(0.06, 0.09 + 0.103 * 0.6), -(height - lift)]
            )
            world_rot = _rot("z", rng.uniform(-0.764, 0.764) * 0.6)
            trunk_rot = _rot("y", trunk_pitch)
            target_rot = trunk_rot.T @ world_rot
            rpy = [math.atan2(target_rot[2, 1], target_rot[2, 2]), -math.asin(target_rot[2, 0]), 0.0]
            rpy[2] = math.atan2(target_rot[1, 0], target_rot[0, 0])
            q6, reachable = leg_ik((trunk_rot.T @ world_pos)[None], np.array([rpy]), side, spec.leg_geometry)
            if not reachable[0]:
                continue  # beyond the leg's reach: the walk's problem, not the limits'
            checked += 1
            limits = spec.leg_limits(side)
            assert np.all(q6[0] >= limits[:, 0]) and np.all(q6[0] <= limits[:, 1]), (side, q6.round(3))
    assert checked >= 80


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
    # Sole plate (FACTS): 0.154 × 0.106 m, bottom 13.4 mm above the sole frame (0.0529 below the
    # foot frame); the cleat spheres' bottoms 2.9 mm above it.
    plate = model.geom("l_foot_collision0")
    assert sorted(2 * plate.size[:2]) == pytest.approx([0.106, 0.154])
    assert plate.pos[2] - plate.size[2] == pytest.approx(-0.0529 + 0.0134)
    foot = model.body("l_foot").id
    spheres = [g for g in range(model.ngeom) if model.geom_bodyid[g] == foot and model.geom_type[g] == 2]
    assert len(spheres) == 4  # mjGEOM_SPHERE
    assert [model.geom_pos[g][2] - model.geom_size[g][0] for g in spheres] == pytest.approx([-0.0529 + 0.0029] * 4)


def test_dm_control_parses_the_mjcf(mj):
    dm_mjcf = pytest.importorskip("dm_control.mjcf")
    root = dm_mjcf.from_xml_string(mj.xml)
    assert len(root.find_all("actuator")) == 20
    assert {j.name for j in root.find_all("joint") if j.type != "free"} == EXPECTED_JOINTS
    physics = dm_mjcf.Physics.from_mjcf_model(root)
    assert physics.model.nu == 20
    physics.step()


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


# ---- planar footprints ----------------------------------------------------------------------


def _support(model, data, geom: int, direction: np.ndarray) -> float:
    """max over geom ``geom``'s collision shape of ``direction · p`` (world frame; MuJoCo's own
    placement of the geom, closed form per shape type)."""
    rotation, centre = data.geom_xmat[geom].reshape(3, 3), data.geom_xpos[geom]
    local, size, kind = rotation.T @ direction, model.geom_size[geom], model.geom_type[geom]
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return float(centre @ direction + np.abs(local) @ size)
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(centre @ direction + size[0])
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return float(centre @ direction + abs(local[2]) * size[1] + size[0])
    assert kind == mujoco.mjtGeom.mjGEOM_CYLINDER, f"geom {geom}: shape type {kind}"
    return float(centre @ direction + abs(local[2]) * size[1] + size[0] * math.hypot(local[0], local[1]))


def test_upper_body_footprint_bounds_the_standing_robots_torso_head_and_arms():
    """The robot's upper_body_footprint (the 2D backend's collision_model=upper_body), placed at the
    feet's mean pose, bounds the torso, head and arms of the MuJoCo robot standing at walk-ready to
    5 mm on each side."""
    from footsim.env import FootstepEnv
    from footsim.geometry import Pose2D, mean_pose
    from footsim.scene import Scene

    env = FootstepEnv(backend="mujoco", task="nav", robot="wolfgang")
    try:
        env.reset(seed=0, options={"scene": Scene(Pose2D(1.0, 0.0, 0.0))})
        model, data = env.unwrapped.backend.sim.mj_model_data()

        def sole(name):
            site = model.site(name).id
            heading = math.atan2(data.site_xmat[site][3], data.site_xmat[site][0])
            return Pose2D(data.site_xpos[site][0], data.site_xpos[site][1], heading)

        nav = mean_pose(sole("l_sole"), sole("r_sole"))
        ahead = np.array([math.cos(nav.theta), math.sin(nav.theta), 0.0])
        left = np.array([-math.sin(nav.theta), math.cos(nav.theta), 0.0])
        upper = [
            g
            for g in range(model.ngeom)
            if model.body(model.geom_bodyid[g]).name in ("torso", "neck", "head")
            or model.body(model.geom_bodyid[g]).name.endswith(("shoulder", "upper_arm", "lower_arm"))
        ]
        assert len(upper) >= 8
        origin = np.array([nav.x, nav.y, 0.0])
        front = max(_support(model, data, g, ahead) for g in upper) - origin @ ahead
        back = -max(_support(model, data, g, -ahead) for g in upper) + origin @ ahead
        side_left = max(_support(model, data, g, left) for g in upper) - origin @ left
        side_right = -max(_support(model, data, g, -left) for g in upper) + origin @ left
    finally:
        env.close()
    length, width, offset = wolfgang().upper_body_footprint
    assert front == pytest.approx(offset + length / 2, abs=0.005)  # the forearms, 0.164 m ahead
    assert back == pytest.approx(offset - length / 2, abs=0.005)  # the torso's back, 0.074 m behind
    assert side_left == pytest.approx(width / 2, abs=0.005)  # the forearms, 0.142 m to each side
    assert side_right == pytest.approx(-width / 2, abs=0.005)
    assert wolfgang().torso_footprint == (0.15, 0.15)  # FACTS' torso collision box, the default check's
