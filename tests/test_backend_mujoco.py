"""MuJoCo backend specifics: name mapping, welded upper body, servo feed-forward, faults, obstacle pool,
memory, rolling friction, obstacle inflation (the common contract: tests/test_backend_contract.py)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")


import footsim  # noqa: E402,F401  (registers the env)
from footsim.backends.mujoco_family.mujoco_sim import N_CYLINDERS, MujocoBackend  # noqa: E402
from footsim.calibration.walkcheck import make_backend  # noqa: E402
from footsim.env import FootstepEnv  # noqa: E402
from footsim.geometry import Pose2D  # noqa: E402
from footsim.scene import Obstacle, Scene  # noqa: E402
from footsim.tasks.nav import tilted_over  # noqa: E402
from footsim.walk.footsteps import DoubleStep  # noqa: E402
from footsim.walk.ik import LEG_JOINT_NAMES  # noqa: E402

EMPTY = Scene(goal=Pose2D(100.0, 0.0, 0.0))
FORWARD = np.array([0.5, 0.0, 0.0, 0.5, 0.0, 0.0])


# The tests share a module-scoped backend or env whose state one hands on to the next: under xdist
# they run on one worker, in file order (--dist loadgroup).
pytestmark = pytest.mark.xdist_group("test_backend_mujoco")


@pytest.fixture(scope="module")
def backend():
    b = make_backend("mujoco")
    yield b
    b.close()


def test_render_with_rendering_switched_off_names_mujoco_gl():
    # A fresh process: mujoco and dm_control choose their GL backend once, at import.
    import subprocess
    import sys

    script = (
        "from footsim.env import FootstepEnv\n"
        "for name in ('mujoco', 'dm_control'):\n"
        "    env = FootstepEnv(backend=name, render_mode='rgb_array')\n"
        "    env.reset(seed=0)\n"
        "    try:\n"
        "        env.render()\n"
        "    except RuntimeError as error:\n"
        "        print(name, error)\n"
        "    env.close()\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "MUJOCO_GL": "disable"},
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert [line.split()[0] for line in lines] == ["mujoco", "dm_control"]
    assert all("MUJOCO_GL=disable" in line for line in lines)


def test_joint_name_mapping(backend):
    sim = backend.sim
    m = sim.model
    robot = backend.robot
    upper = set(robot.upper_body_joint_names)
    assert upper and not upper & set(LEG_JOINT_NAMES)
    expected = [n for n in robot.joint_names if not (sim.rigid_upper_body and n in upper)]
    assert list(sim.joint_names) == expected and set(LEG_JOINT_NAMES) <= set(expected)
    assert m.nu == len(expected) and m.nv == 6 + len(expected)
    for name in robot.joint_names:
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        aid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if name not in expected:  # welded: neither joint nor actuator
            assert jid < 0 and aid < 0, name
            continue
        assert jid >= 0 and aid >= 0, name
        assert m.actuator_trnid[aid, 0] == jid
        assert sim.joint_qpos[name] == m.jnt_qposadr[jid]
    # targets reach the right joints: a distinct target per leg joint, held until converged
    backend.reset(EMPTY, np.random.default_rng(0))
    base = backend.engine.standing_joint_targets()
    targets = base + np.linspace(-0.06, 0.06, 12)
    sim.set_leg_targets(targets)
    sim.set_leg_targets(targets)  # twice: a held target has no velocity feed-forward (servo_kv) in ctrl
    for name, target in zip(LEG_JOINT_NAMES, targets):
        assert sim.data.ctrl[sim.actuator[name]] == target
    # lift the robot off the ground so gravity does not bias the joints
    sim.model.opt.gravity[:] = 0.0
    try:
        sim.data.qpos[2] += 0.3
        sim.advance(round(0.8 / backend.physics_dt))  # 0.8 s of simulated time
        reached = np.array([sim.data.qpos[sim.joint_qpos[n]] for n in LEG_JOINT_NAMES])
    finally:
        sim.model.opt.gravity[:] = (0.0, 0.0, -9.81)
    np.testing.assert_allclose(reached, targets, atol=0.03)
    assert np.argsort(reached).tolist() == np.argsort(targets).tolist()


@pytest.mark.parametrize("rigid", [True, False])
def test_upper_body_at_walk_ready_pose_matches_spec_kinematics(rigid):
    """Welded or held by its servos, every link sits where the spec's own forward kinematics
    (numpy, independent of MuJoCo) puts it at the walk-ready angles, relative to the torso."""
    from footsim import config as fconf

    backend = MujocoBackend(fconf.build_robot("wolfgang"), make_backend("mujoco").walk, rigid_upper_body=rigid)
    try:
        robot, sim = backend.robot, backend.sim
        assert sim.model.nv == (18 if rigid else 26)
        pose = dict(robot.walk_ready)
        backend.reset(EMPTY, np.random.default_rng(0))
        pose.update(zip(LEG_JOINT_NAMES, backend.engine.standing_joint_targets()))
        sim.reset_robot(np.array([0.0, 0.0, 1.0]), pose)  # kinematics only: no physics step
        expected = robot.link_transforms(pose)
        d, m = sim.data, sim.model
        torso = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, robot.base_link)
        base_rot, base_pos = d.xmat[torso].reshape(3, 3), d.xpos[torso]
        for link in robot.link_names:
            body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, link)
            position = base_rot.T @ (d.xpos[body] - base_pos)
            rotation = base_rot.T @ d.xmat[body].reshape(3, 3)
            np.testing.assert_allclose(position, expected[link][:3, 3], atol=1e-9, err_msg=link)
            np.testing.assert_allclose(rotation, expected[link][:3, :3], atol=1e-9, err_msg=link)
    finally:
        backend.close()


def test_servo_kv_feeds_the_target_velocity_forward(backend):
    """servo_kv: force = kp (q_t - q) + kv (qdot_t - qdot), qdot_t from consecutive targets."""
    sim = backend.sim
    if sim.servo_kv <= 0:
        pytest.skip("servo_kv is off in conf/backend/mujoco.yaml")
    backend.reset(EMPTY, np.random.default_rng(0))
    m, legs = sim.model, sim.state.leg_ids
    np.testing.assert_allclose(m.actuator_biasprm[legs, 2], -sim.servo_kv)
    base = backend.engine.standing_joint_targets()
    sim.set_leg_targets(base)
    np.testing.assert_allclose(sim.data.ctrl[legs], base)  # at rest after reset: no feed-forward
    ramp = base + 0.01  # 0.01 rad per control tick
    sim.set_leg_targets(ramp)
    velocity = 0.01 / backend.control_dt
    np.testing.assert_allclose(sim.data.ctrl[legs], ramp + sim.servo_kv / m.actuator_gainprm[legs, 0] * velocity)
    with pytest.raises(ValueError, match="servo_kv"):
        MujocoBackend(backend.robot, backend.walk, servo_kv=-1.0)


def test_blow_up_is_a_sim_error_with_finite_observation(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warnings to MUJOCO_LOG.TXT in the cwd
    env = FootstepEnv(backend="mujoco")
    try:
        env.reset(seed=1)
        env.backend.sim.data.qvel[:] = np.nan
        obs, reward, term, trunc, info = env.step(FORWARD)
        assert term and info["outcome"] == "sim_error" and "sim_error" in info
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
        env.reset(seed=2)  # and the env recovers on reset
        env.backend.sim.data.qvel[6:] = 1e12  # a huge velocity: MuJoCo's own instability warning
        obs, reward, term, trunc, info = env.step(FORWARD)
        assert term and info["outcome"] == "sim_error"
        assert np.all(np.isfinite(obs))
    finally:
        env.close()


def test_obstacle_pool_is_placed_and_parked(backend):
    sim = backend.sim
    scene = Scene(
        goal=Pose2D(3.0, 0.0, 0.0),
        obstacles=(Obstacle(1.0, 0.5, 0.2), Obstacle(2.0, -0.5, 0.3)),
        ball=Obstacle(1.5, 0.0, 0.075),
    )
    backend.reset(scene, np.random.default_rng(0))
    geoms = sim.obstacle_geoms
    body = sim.model.geom_bodyid  # one body per obstacle, placed by its position
    np.testing.assert_allclose(sim.model.body_pos[body[geoms[0]], :2], (1.0, 0.5))
    np.testing.assert_allclose(sim.model.geom_size[geoms[1], 0], 0.3)
    np.testing.assert_allclose(sim.model.body_pos[body[geoms[-1]]], (1.5, 0.0, 0.075))
    assert all(sim.model.geom_contype[g] == 0 for g in geoms[2:N_CYLINDERS])
    assert not sim.obstacle_contact()
    with pytest.raises(ValueError, match="at most"):
        sim.set_obstacles(Scene(goal=Pose2D(), obstacles=tuple(Obstacle(i, 5.0, 0.1) for i in range(N_CYLINDERS + 1))))


def _rss_mb():
    psutil = pytest.importorskip("psutil")
    return psutil.Process(os.getpid()).memory_info().rss / 2**20


@pytest.mark.memory
def test_many_resets_and_create_close_cycles_do_not_leak(backend):
    for _ in range(50):  # warm up allocators
        backend.reset(EMPTY, np.random.default_rng(0))
    before = _rss_mb()
    rng = np.random.default_rng(0)
    for i in range(1000):
        scene = Scene(
            goal=Pose2D(1.0, 0.0, 0.0),
            obstacles=(Obstacle(2.0, float(rng.uniform(-1, 1)), 0.2),),
            ball=Obstacle(1.2, 0.0, 0.075) if i % 2 else None,
        )
        backend.reset(scene, rng)
    after_resets = _rss_mb()
    for _ in range(10):
        MujocoBackend(backend.robot, backend.walk).close()
    mid = _rss_mb()
    for _ in range(60):
        MujocoBackend(backend.robot, backend.walk).close()
    end = _rss_mb()
    assert after_resets - before < 10.0
    assert end - mid < 20.0, f"RSS grew {end - mid:.1f} MB over 60 create/close cycles"


def test_v0_random_steps_do_not_fall_and_rolling_friction_is_why():
    """FootstepNav-v0 (the simplified robot, its tuned gait and MuJoCo settings): uniform random
    double steps over the full limits do not fall, and only because of the feet's rolling friction
    (0.15 m, twice the old sole's half length): without it seed 2008 falls (every one of 20 random
    sequences fell, session 5: git show 94a1e0b:docs/RESULTS.md).  FootstepNav-v1 has no such friction."""
    from footsim import config as fconf

    backend = fconf.build_backend(
        fconf.load_preset("backend", "mujoco_v0"),
        fconf.build_robot("wolfgang_simplified"),
        fconf.build_walk(fconf.load_preset("walk", "footsim_slow")),
    )

    def fall_step(b, seed, n):
        b.reset(EMPTY, np.random.default_rng(0))
        for i, action in enumerate(np.random.default_rng(seed).uniform(-1, 1, size=(n, 6))):
            result = b.execute(DoubleStep.from_action(action, b.robot.step_limits))
            assert result.sim_error is None
            if tilted_over(result):
                return i + 1
        return None

    try:
        assert backend.sim.rolling_friction == pytest.approx(0.15)
        assert [fall_step(backend, seed, 25) for seed in (2008, 2014)] == [None, None]
    finally:
        backend.close()
    options = {**fconf.load_preset("backend", "mujoco_v0"), "rolling_friction": None}
    options.pop("name")
    no_rolling = MujocoBackend(backend.robot, backend.walk, **options)
    try:
        assert no_rolling.sim.model.geom_condim.max() == 4  # feet: torsional friction only
        assert fall_step(no_rolling, 2008, 25) is not None
    finally:
        no_rolling.close()


def test_evaluation_counts_obstacle_contacts():
    """episodes.csv's contact_steps and the summary's contact share (3D contacts are not outcomes)."""
    from footsim.rl.evaluate import run_episode, summarize

    class Forward:
        def reset(self, scene, info, seed):
            pass

        def __call__(self, obs, info):
            return FORWARD

    blocked = Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.35, 0.0, 0.15),))
    clear = Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.35, 1.5, 0.15),))
    env = FootstepEnv(backend="mujoco", task={"name": "nav_obstacles", "max_steps": 4})
    try:
        records = [run_episode(env, Forward(), scene, seed=0)[0] for scene in (blocked, clear)]
    finally:
        env.close()
    assert records[0]["contact_steps"] >= 1 and records[1]["contact_steps"] == 0
    assert summarize(records)["contact"] == 0.5


def test_obstacle_inflation_widens_obstacles_in_the_physics_only():
    """backend.obstacle_inflation: an obstacle beside the path is touched only when inflated; the
    observation (rays from the scene's radius) is the same either way."""
    beside = Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.45, 0.32, 0.1),))

    def walk(inflation):
        env = FootstepEnv(backend={"name": "mujoco", "obstacle_inflation": inflation}, obstacles=True)
        try:
            obs, _ = env.reset(seed=0, options={"scene": beside})
            contacts = []
            for _ in range(4):
                _, _, term, _, info = env.step(FORWARD)
                contacts.append(info["collided"])
            return obs, contacts, env.backend.sim.model.geom_size[env.backend.sim.obstacle_geoms[0], 0]
        finally:
            env.close()

    obs, contacts, radius = walk(0.0)
    obs_inflated, contacts_inflated, radius_inflated = walk(0.1)
    assert not any(contacts) and any(contacts_inflated)
    assert radius == pytest.approx(0.1) and radius_inflated == pytest.approx(0.2)
    np.testing.assert_array_equal(obs, obs_inflated)
    with pytest.raises(ValueError, match="obstacle_inflation"):
        FootstepEnv(backend={"name": "mujoco", "obstacle_inflation": -0.1}, obstacles=True)


def test_a_push_in_the_first_double_step_moves_the_robot_in_proportion_and_is_cleared(backend):
    """``run_sequence(push=F)``: F on the torso during the first double step, cleared after it.  A
    zero push changes nothing (the simulation is deterministic); small pushes move the final pose,
    a four times larger push (within the linear response, no fall) about four times as far."""
    from footsim.calibration.walkcheck import Sequence, run_sequence

    in_place = Sequence("in place", np.zeros((3, 6)), "translation")
    plain = run_sequence(backend, in_place)["pose"]
    zero = run_sequence(backend, in_place, push=np.zeros(3))["pose"]
    assert (zero.x, zero.y, zero.theta) == (plain.x, plain.y, plain.theta)
    moved = []
    for force in (0.5, 2.0):
        pushed = run_sequence(backend, in_place, push=np.array([force, 0.0, 0.0]))
        assert not pushed["fell"]
        moved.append(abs(pushed["pose"].x - plain.x))
        _, data = backend.sim.mj_model_data()
        assert not data.xfrc_applied.any()  # cleared after the first double step
    assert moved[0] > 1e-3 and 2.0 < moved[1] / moved[0] < 6.0


def test_the_default_contact_options_are_mujocos_own():
    """The preset's friction cone and impratio are MuJoCo's defaults (a model compiled from an
    empty MJCF), as in the Bit-Bots' model, so setting them leaves the physics as it was."""
    backend = make_backend("mujoco")
    try:
        empty = mujoco.MjModel.from_xml_string("<mujoco/>").opt
        assert backend.sim.model.opt.cone == empty.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
        assert backend.sim.model.opt.impratio == empty.impratio == 1.0
    finally:
        backend.close()
