"""Physics randomization on the 3D backends: every ``terms_3d`` term changes, measured in the
simulator, what it claims to; values are reproducible and never compound across episodes."""

import math
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from footsim.backends.base import backend_class  # noqa: E402
from footsim.env import FootstepEnv  # noqa: E402
from footsim.geometry import Pose2D  # noqa: E402
from footsim.scene import Scene  # noqa: E402
from footsim.tasks.nav import tilted_over  # noqa: E402
from footsim.walk.footsteps import DoubleStep  # noqa: E402
from footsim.walk.ik import LEG_JOINT_NAMES  # noqa: E402

BACKENDS = ["mujoco", "dm_control", "pybullet"]
SCENE = Scene(goal=Pose2D(3.0, 0.0, 0.0))
KNEE = LEG_JOINT_NAMES.index("l_knee") if "l_knee" in LEG_JOINT_NAMES else 3


def _available(name):
    try:
        backend_class(name)
    except ImportError:
        return False
    return True


OPEN_LOOP_WALK = {"trunk_pid_pitch_p": 0.0, "trunk_pid_pitch_d": 0.0, "phase_reset_foot_pressure_active": False}

# The tests share a module-scoped backend or env whose state one hands on to the next: under xdist
# they run on one worker, in file order (--dist loadgroup).
pytestmark = pytest.mark.xdist_group("test_randomization_3d")


@pytest.fixture(scope="module", params=BACKENDS)
def env(request):
    if not _available(request.param):
        pytest.skip(f"{request.param} is not installed")
    # The walk open loop (no trunk PID, no phase reset): the driver terms' tests compare joint
    # targets and step durations that the walk node's feedback would make state-dependent.
    e = FootstepEnv(backend=request.param, walk=OPEN_LOOP_WALK)
    yield e
    e.close()


def _fresh(b, values=None, seed=0):
    """Apply ``values`` (everything else nominal) and reset the backend."""
    b.clear_randomization()
    b.apply_randomization(values or {})
    b.reset(SCENE, np.random.default_rng(seed))
    return b


# -- what the simulator reports -------------------------------------------------------------
def _is_bullet(b):
    return b.name == "pybullet"


def _total_mass(b):
    if _is_bullet(b):
        import pybullet as p

        s = b.sim
        return sum(p.getDynamicsInfo(s.robot_id, link, physicsClientId=s.client)[0] for link in s.nominal_dynamics)
    model, _ = b.sim.mj_model_data()
    return float(model.body_mass[b.sim.mj_nominal().robot_bodies].sum())


def _floor_normal(b):
    if _is_bullet(b):
        import pybullet as p

        _, orn = p.getBasePositionAndOrientation(b.sim.floor_id, physicsClientId=b.sim.client)
        return np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)[:, 2]
    model, data = b.sim.mj_model_data()
    return np.asarray(data.geom_xmat[b.sim.mj_nominal().floor_geom]).reshape(3, 3)[:, 2]


def _foot_floor_friction(b):
    """The sliding friction coefficient of a foot–floor contact, as the engine combines it."""
    if _is_bullet(b):
        import pybullet as p

        s = b.sim
        floor = p.getDynamicsInfo(s.floor_id, -1, physicsClientId=s.client)[1]
        foot = p.getDynamicsInfo(s.robot_id, s.link_index["l_foot"], physicsClientId=s.client)[1]
        return floor * foot  # Bullet's combination rule
    model, data = b.sim.mj_model_data()
    nominal = b.sim.mj_nominal()
    feet = set(nominal.foot_geoms.tolist())
    mus = [
        data.contact.friction[i, 0]
        for i in range(data.ncon)
        if nominal.floor_geom in data.contact.geom[i] and feet & set(data.contact.geom[i].tolist())
    ]
    assert mus, "no foot-floor contact"
    return float(np.mean(mus))


def _foot_floor_rolling(b):
    """The rolling friction [m] of a foot–floor contact, as the engine combines it."""
    if _is_bullet(b):
        import pybullet as p

        s = b.sim
        floor = p.getDynamicsInfo(s.floor_id, -1, physicsClientId=s.client)
        foot = p.getDynamicsInfo(s.robot_id, s.link_index["l_foot"], physicsClientId=s.client)
        return floor[6] * foot[1] + foot[6] * floor[1]  # Bullet's combination rule (rolling · lateral)
    model, data = b.sim.mj_model_data()
    nominal = b.sim.mj_nominal()
    feet = set(nominal.foot_geoms.tolist())
    rolls = [
        data.contact.friction[i, 3]  # (slide, slide, torsional, roll, roll)
        for i in range(data.ncon)
        if nominal.floor_geom in data.contact.geom[i] and feet & set(data.contact.geom[i].tolist())
    ]
    assert rolls, "no foot-floor contact"
    return float(np.mean(rolls))


def _pitch(b):
    _, rot = b.sim.base_pose()
    return math.asin(-rot[2, 0])


def _base_x(b):
    return float(b.sim.base_pose()[0][0])


def _feet_x(b):
    """Mean x of the two foot links (they slide; the base also leans)."""
    if _is_bullet(b):
        import pybullet as p

        s = b.sim
        return float(
            np.mean(
                [
                    p.getLinkState(s.robot_id, s.link_index[f], physicsClientId=s.client)[0][0]
                    for f in ("l_foot", "r_foot")
                ]
            )
        )
    _, data = b.sim.mj_model_data()
    model, _ = b.sim.mj_model_data()
    import mujoco

    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, b.robot.foot_link(s)) for s in ("left", "right")]
    return float(np.mean(data.xpos[ids, 0]))


# -- sim terms ------------------------------------------------------------------------------
def test_link_mass_scale_scales_the_total_mass_and_does_not_compound(env):
    b = env.backend
    nominal = _total_mass(_fresh(b))
    for _ in range(3):  # three episodes at 1.2: still 1.2 x nominal
        _fresh(b, {"link_mass_scale": 1.2})
        assert _total_mass(b) == pytest.approx(1.2 * nominal, rel=1e-6)
    _fresh(b)
    assert _total_mass(b) == pytest.approx(nominal, rel=1e-9)


def test_friction_scales_the_contact_friction_and_the_sliding_under_a_push(env):
    b = env.backend
    mu = _foot_floor_friction(_fresh(b))
    _fresh(b, {"floor_friction": 0.5, "foot_friction": 0.8})
    b.hold(0.02)
    assert _foot_floor_friction(b) == pytest.approx(0.4 * mu, rel=1e-6)
    slides = {}
    for term in (None, "floor_friction", "foot_friction"):
        _fresh(b, {term: 0.02} if term else {})
        b.hold(0.05)
        x0 = _feet_x(b)
        b.sim.apply_base_force(np.array([6.0, 0.0, 0.0]))  # μ m g: ~70 N nominal, ~1.5 N at 0.02
        b.hold(0.4)
        b.sim.apply_base_force(np.zeros(3))
        slides[term] = _feet_x(b) - x0
    assert abs(slides[None]) < 0.01, slides  # the feet (nearly) stick
    assert slides["floor_friction"] > 0.03 and slides["foot_friction"] > 0.03, slides


def test_rolling_friction_scale_scales_the_contacts_rolling_friction(env):
    b = env.backend
    nominal = _foot_floor_rolling(_fresh(b))
    assert nominal == pytest.approx(0.1 if _is_bullet(b) else 1e-4, rel=1e-6)  # the backends' presets
    for _ in range(2):  # does not compound
        _fresh(b, {"rolling_friction_scale": 0.25})
        b.hold(0.02)
        assert _foot_floor_rolling(b) == pytest.approx(0.25 * nominal, rel=1e-6)
    _fresh(b)
    b.hold(0.02)
    assert _foot_floor_rolling(b) == pytest.approx(nominal, rel=1e-9)


def test_actuator_kp_and_torque_limit_and_damping_change_the_servos(env):
    b = env.backend
    if _is_bullet(b):
        s = _fresh(b).sim
        gains, forces = np.array(s.leg_gains), np.array(s.leg_forces)
        _fresh(b, {"actuator_kp_scale": 1.2, "torque_limit_scale": 0.7, "joint_damping_scale": 1.5})
        assert np.allclose(s.leg_gains, np.minimum(1.0, gains * 1.2 / 1.5))
        assert np.allclose(s.leg_forces, forces * 0.7)
        # Measured: a big target error saturates the motor at the scaled max force.
        import pybullet as p

        target = np.array([p.getJointState(s.robot_id, i, physicsClientId=s.client)[0] for i in s.leg_indices])
        target[KNEE] += 1.0
        s.set_leg_targets(target)
        s.advance(1)
        torque = p.getJointState(s.robot_id, s.leg_indices[KNEE], physicsClientId=s.client)[3]
        assert abs(torque) == pytest.approx(forces[KNEE] * 0.7, rel=1e-3)
        _fresh(b)
        assert np.allclose(s.leg_gains, gains) and np.allclose(s.leg_forces, forces)
        return
    import mujoco

    def servo(values, error, qvel=0.0):
        _fresh(b, values)
        model, data = b.sim.mj_model_data()
        n = b.sim.mj_nominal()
        act, dof = int(n.actuators[0]), int(n.dofs[0])
        qadr = int(model.jnt_qposadr[model.dof_jntid[dof]])
        data.qvel[:] = 0.0
        data.qvel[dof] = qvel
        data.ctrl[act] = data.qpos[qadr] + error
        mujoco.mj_forward(model, data)
        return float(data.actuator_force[act]), float(data.qfrc_passive[dof]), float(model.actuator_forcerange[act, 1])

    f0, _, limit0 = servo({}, 1e-3)
    f1, _, _ = servo({"actuator_kp_scale": 1.3}, 1e-3)
    assert f1 == pytest.approx(1.3 * f0, rel=1e-6) and abs(f0) > 0
    big, _, limit = servo({"torque_limit_scale": 0.6}, 3.0)
    assert limit == pytest.approx(0.6 * limit0) and big == pytest.approx(limit, rel=1e-9)
    _, d0, _ = servo({}, 0.0, qvel=1.0)
    _, d1, _ = servo({"joint_damping_scale": 1.5}, 0.0, qvel=1.0)
    assert d0 < 0 and d1 == pytest.approx(1.5 * d0, rel=1e-6)


def test_torso_com_offset_leans_the_standing_robot(env):
    b = env.backend
    pitch = {}
    for dx in (-0.03, 0.03):
        _fresh(b, {"torso_com_offset_x": dx})
        b.hold(0.3)
        pitch[dx] = _pitch(b)
    # COM forward: leans forward (positive fused pitch); Bullet applies the offset as a torque its
    # position motors, solved to convergence at 50 iterations, almost fully hold (0.05 mrad
    # measured), MuJoCo moves the COM (several mrad).
    assert pitch[0.03] > pitch[-0.03] + (2e-5 if _is_bullet(b) else 1e-3), pitch
    if not _is_bullet(b):
        model, _ = b.sim.mj_model_data()
        n = b.sim.mj_nominal()
        assert np.allclose(model.body_ipos[n.torso] - n.torso_ipos, [0.03, 0.0, 0.0])
        _fresh(b)
        assert np.allclose(model.body_ipos[n.torso], n.torso_ipos)


def test_terrain_slope_tilts_the_floor_normal_by_the_value(env):
    b = env.backend
    _fresh(b, {"terrain_slope": 0.05}, seed=7)
    normal = _floor_normal(b)
    assert math.acos(min(1.0, normal[2])) == pytest.approx(0.05, abs=1e-6)
    direction = b.randomization_detail["terrain_slope_direction"]
    assert math.atan2(normal[1], normal[0]) == pytest.approx(direction, abs=1e-6)  # descends that way
    _fresh(b, {"terrain_slope": 0.05}, seed=7)
    assert b.randomization_detail["terrain_slope_direction"] == direction  # backend rng: reproducible
    _fresh(b)
    assert _floor_normal(b)[2] == pytest.approx(1.0, abs=1e-12)


# -- driver terms ---------------------------------------------------------------------------
def _recorded_targets(b, values):
    _fresh(b, values)
    sent = []
    original = b.sim.advance  # each tick's commanded targets, read from the state contract before its physics
    b.sim.advance = lambda n: (sent.append(b.sim.state.last_targets()), original(n))
    try:
        b.execute(DoubleStep.from_action(np.array([0.3, 0, 0, 0.3, 0, 0]), b.robot.step_limits))
    finally:
        del b.sim.advance
    return np.array(sent)


def test_control_latency_delays_the_joint_targets_by_the_rounded_ticks(env):
    from footsim.backends.control import TrunkStabilizer

    b = env.backend
    stabilizer, b.stabilizer = b.stabilizer, TrunkStabilizer()  # open loop: targets independent of the state
    try:
        plain = _recorded_targets(b, {})
        late = _recorded_targets(b, {"control_latency": 2.4})  # rounds to 2
    finally:
        b.stabilizer = stabilizer
    n = min(len(plain), len(late))
    assert n > 20
    assert np.allclose(late[2:n], plain[: n - 2])
    assert np.allclose(late[0], late[1]) and not np.allclose(late[2:n], plain[2:n])


def test_pushes_follow_the_schedule_and_move_the_base(env):
    b = env.backend
    forces = []
    original = b.sim.apply_base_force
    b.sim.apply_base_force = lambda f: (forces.append((b.tick, np.array(f))), original(f))
    try:
        _fresh(b, {"push_force": 25.0, "push_duration": 0.1, "push_interval": 0.3})
        forces.clear()
        b.execute(DoubleStep.from_action(np.zeros(6), b.robot.step_limits))
    finally:
        del b.sim.apply_base_force
    dt = b.control_dt
    on = [(t, f) for t, f in forces if np.linalg.norm(f) > 0]
    off = [t for t, f in forces if np.linalg.norm(f) == 0]
    assert on and on[0][0] == round(0.3 / dt)
    assert np.linalg.norm(on[0][1]) == pytest.approx(25.0) and on[0][1][2] == 0.0
    assert off[0] == on[0][0] + round(0.1 / dt)
    # Measured: a push changes the base velocity along the force.
    moved = []
    for force in (0.0, 30.0):
        _fresh(b)
        b.hold(0.05)
        x0 = b.sim.base_pose()[0][:2]
        b.sim.apply_base_force(np.array([0.0, force, 0.0]))
        b.hold(0.15)
        b.sim.apply_base_force(np.zeros(3))
        moved.append(b.sim.base_pose()[0][1] - x0[1])
    assert moved[1] - moved[0] > 0.005, moved


def test_walk_freq_scale_changes_the_double_step_duration(env):
    b = env.backend
    step = DoubleStep.from_action(np.array([0.2, 0, 0, 0.2, 0, 0]), b.robot.step_limits)
    base = _fresh(b).execute(step)
    fast = _fresh(b, {"walk_freq_scale": 1.25, "walk_trunk_height_scale": 0.98}).execute(step)
    assert not tilted_over(base) and not tilted_over(fast)
    assert fast.duration_s == pytest.approx(base.duration_s / 1.25, abs=2 * b.control_dt)
    assert b.walk_current.trunk_height == pytest.approx(0.98 * b.walk_nominal.trunk_height)
    _fresh(b)
    assert b.walk_current == b.walk_nominal


# -- through the env ------------------------------------------------------------------------
@pytest.mark.parametrize("name", BACKENDS)
def test_presets_run_reproducibly_and_do_not_compound(name):
    if not _available(name):
        pytest.skip(f"{name} is not installed")
    env = FootstepEnv(backend=name, randomization="strong")
    try:
        b = env.backend
        nominal = b.sim.nominal_dynamics if _is_bullet(b) else None
        _, info = env.reset(seed=3)
        first = dict(info["randomization"])
        mass = _total_mass(b)
        for _ in range(3):
            _, _, term, trunc, info = env.step(np.array([0.5, 0, 0, 0.5, 0, 0]))
            assert "randomization" in info and "push_force" in info["randomization"]
        env.reset(seed=4)
        _, info = env.reset(seed=3)
        again = {k: v for k, v in info["randomization"].items() if k != "push_force"}
        assert again == {k: v for k, v in first.items() if k != "push_force"}
        assert _total_mass(b) == pytest.approx(mass, rel=1e-9)  # nominal x the same draw, not compounded
        if nominal is not None:
            assert b.sim.nominal_dynamics == nominal
    finally:
        env.close()
    env = FootstepEnv(backend=name, randomization="default")
    try:
        _, info = env.reset(seed=0)
        assert set(info["randomization"]) >= {"foot_friction", "link_mass_scale", "control_latency"}
        for _ in range(2):
            _, _, _, _, info = env.step(np.array([0.5, 0, 0, 0.5, 0, 0]))
        assert info["randomization"] and info["outcome"] in ("running", "fall", "success")
    finally:
        env.close()


@pytest.mark.parametrize("name", BACKENDS)
def test_unsupported_term_fails_at_start_naming_term_and_backend(name):
    if not _available(name):
        pytest.skip(f"{name} is not installed")
    with pytest.raises(
        ValueError, match=f"backend '{name}' cannot apply randomization term\\(s\\) \\['footstep_noise_x'\\]"
    ):
        FootstepEnv(backend=name, randomization={"terms_3d": {"footstep_noise_x": {"dist": "constant", "value": 0.01}}})


def test_a_sim_without_a_term_makes_the_driver_refuse_it():
    from footsim.backends.physics3d import DRIVER_TERMS, PhysicsSim

    class Bare(PhysicsSim):
        build = set_obstacles = reset_robot = advance = base_pose = obstacle_contact = None

    assert Bare.capabilities == frozenset()
    with pytest.raises(ValueError, match="cannot apply"):
        Bare().apply_physics_randomization({"floor_friction": 1.0})
    assert "terrain_slope" not in DRIVER_TERMS
