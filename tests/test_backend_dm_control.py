"""dm-control backend specifics: overlay drawing, reset levelling, name mapping, model options, faults,
obstacle pool, mjcf idiom, memory, deferred GL (the common contract: tests/test_backend_contract.py)."""

import gc
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

pytest.importorskip("dm_control")

import mujoco  # noqa: E402
from dm_control import mjcf  # noqa: E402

import footsim  # noqa: E402,F401  (registers the env)
from footsim.backends.mujoco_family.dm_control_sim import N_CYLINDERS, DmControlBackend  # noqa: E402
from footsim.calibration.walkcheck import make_backend  # noqa: E402
from footsim.env import FootstepEnv  # noqa: E402
from footsim.geometry import Pose2D  # noqa: E402
from footsim.robots.mjcf import sole_site  # noqa: E402
from footsim.scene import Obstacle, Scene  # noqa: E402
from footsim.walk.ik import LEG_JOINT_NAMES  # noqa: E402

EMPTY = Scene(goal=Pose2D(100.0, 0.0, 0.0))
FORWARD = np.array([0.5, 0.0, 0.0, 0.5, 0.0, 0.0])


# The tests share a module-scoped backend or env whose state one hands on to the next: under xdist
# they run on one worker, in file order (--dist loadgroup).
pytestmark = pytest.mark.xdist_group("test_backend_dm_control")


@pytest.fixture(scope="module")
def backend():
    b = make_backend("dm_control")
    yield b
    b.close()


def test_render_rgb_frame_shows_the_goal_marker():
    env = FootstepEnv(
        backend={"name": "dm_control", "render_size": [160, 120]}, obstacles=True, render_mode="rgb_array"
    )
    try:
        env.reset(seed=3)
        frame = env.render()
        bare = env.backend.sim.render(None, 160, 120)
    finally:
        env.close()
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 5.0  # not blank
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 50
    assert bare.shape == frame.shape


def test_goal_marker_and_obstacles_are_drawn(backend):
    from footsim.backends.base import RenderOverlay

    # The camera looks back at the robot from in front-left: a goal and an obstacle behind it are in view.
    scene = Scene(goal=Pose2D(-1.0, -0.5, 0.5), obstacles=(Obstacle(-1.0, 0.8, 0.2),))
    backend.reset(EMPTY, np.random.default_rng(0))
    empty = backend.render()
    backend.reset(scene, np.random.default_rng(0))
    bare = backend.render()
    marked = backend.render(RenderOverlay(goal=scene.goal))
    assert (bare != empty).any(axis=2).sum() > 500  # the obstacle
    changed = (marked != bare).any(axis=2)
    assert changed.sum() > 100  # the goal disc and arrow
    assert (marked[changed][:, 0].astype(int) - marked[changed][:, 1]).mean() > 30  # red (goal not reached)


def test_reset_levels_the_soles_on_the_floor(backend):
    backend.reset(EMPTY, np.random.default_rng(0))
    backend.sim.reset_robot(
        np.array([0.0, 0.0, backend.walk.trunk_height]),
        dict(backend.robot.walk_ready) | dict(zip(LEG_JOINT_NAMES, backend.engine.standing_joint_targets().tolist())),
    )
    model = backend.sim.mjcf_model  # found by name through dm_control's own API
    soles = backend.sim.physics.bind([model.find("site", sole_site(s)) for s in ("left", "right")])
    # The feet's lowest points (the cleat tips) on the floor: the sole frames that far below it.
    np.testing.assert_allclose(soles.xpos[:, 2].min(), -backend.robot.sole_clearance("left"), atol=1e-9)
    np.testing.assert_allclose(soles.xmat[0].reshape(3, 3)[2], (0.0, 0.0, 1.0), atol=1e-9)  # left sole level


def test_joint_name_mapping(backend):
    sim, physics = backend.sim, backend.sim.physics
    upper = set(backend.robot.upper_body_joint_names)
    assert set(sim.joint_names) == set(backend.robot.joint_names) - (upper if sim.rigid_upper_body else set())
    for name in backend.robot.joint_names:
        joint, actuator = sim.mjcf_model.find("joint", name), sim.mjcf_model.find("actuator", name)
        if name not in sim.joint_names:  # welded upper body: neither joint nor actuator
            assert joint is None and actuator is None, name
            continue
        assert sim.joints[name] is joint and sim.actuators[name] is actuator
        assert physics.bind(actuator).trnid[0] == physics.bind(joint).element_id
        assert physics.named.model.jnt_qposadr[name] == physics.bind(joint).qposadr
    # targets reach the right joints: a distinct target per leg joint, held until converged
    backend.reset(EMPTY, np.random.default_rng(0))
    targets = backend.engine.standing_joint_targets() + np.linspace(-0.06, 0.06, 12)
    sim.set_leg_targets(targets)
    sim.set_leg_targets(targets)  # twice: a held target has no velocity feed-forward (servo_kv) in ctrl
    np.testing.assert_array_equal(physics.named.data.ctrl[list(LEG_JOINT_NAMES)], targets)
    physics.model.opt.gravity[:] = 0.0  # lift the robot and drop gravity: nothing biases the joints
    try:
        physics.named.data.qpos["root"][2] += 0.3
        sim.advance(round(0.8 / backend.physics_dt))  # 0.8 s of simulated time
        reached = physics.named.data.qpos[list(LEG_JOINT_NAMES)]
    finally:
        physics.model.opt.gravity[:] = (0.0, 0.0, -9.81)
    np.testing.assert_allclose(reached, targets, atol=0.03)
    assert np.argsort(reached).tolist() == np.argsort(targets).tolist()


def test_model_options_match_the_mujoco_backend(backend):
    """Same engine, same options: the compiled models agree (XML rounding aside)."""
    from footsim.backends.mujoco_family.mujoco_sim import MujocoBackend
    from footsim.config import load_preset

    backend.reset(EMPTY, np.random.default_rng(0))  # the obstacle pool parked, as in a fresh model
    # FootstepNav-v0's preset: every model option set (rolling and torsional friction included).
    cfg = load_preset("backend", "dm_control_v0")
    options = {
        k: cfg[k]
        for k in (
            "torsional_friction",
            "rolling_friction",
            "contact_solref",
            "servo_kp_scale",
            "servo_damping_scale",
            "servo_kv",
            "physics_dt",
            "control_dt",
            "integrator",
        )
    }
    options.update(friction_cone="elliptic", impratio=10.0)  # not in any preset: set here
    mine = DmControlBackend(backend.robot, backend.walk, **options)
    ours = mine.sim.physics.model.ptr
    theirs = MujocoBackend(backend.robot, backend.walk, **options)  # the MuJoCo backend given the same options
    try:
        ref = theirs.sim.model
        for field in (
            "geom_condim",
            "geom_friction",
            "geom_solref",
            "actuator_gainprm",
            "actuator_biasprm",
            "dof_damping",
            "body_mass",
            "geom_contype",
            "geom_conaffinity",
        ):
            np.testing.assert_allclose(getattr(ours, field), getattr(ref, field), rtol=1e-5, err_msg=field)
        assert ours.opt.integrator == ref.opt.integrator and ours.opt.timestep == ref.opt.timestep
        for opt in (ours.opt, ref.opt):
            assert opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and opt.impratio == 10.0
        feet = [
            mine.sim.physics.bind(g).element_id
            for s in ("left", "right")
            for g in mine.sim.mjcf_model.find("body", backend.robot.foot_link(s)).get_children("geom")
        ]
        assert feet and all(ours.geom_condim[g] == 6 for g in feet)  # torsional and rolling friction
        assert all(ours.geom_friction[g, 1] == pytest.approx(cfg["torsional_friction"]) for g in feet)
        assert all(ours.geom_friction[g, 2] == pytest.approx(cfg["rolling_friction"]) for g in feet)
    finally:
        theirs.close()
        mine.close()
    with pytest.raises(ValueError, match="servo_kp_scale"):
        DmControlBackend(backend.robot, backend.walk, servo_kp_scale=0.0)
    with pytest.raises(ValueError, match="integrator"):
        DmControlBackend(backend.robot, backend.walk, integrator="leapfrog")
    with pytest.raises(ValueError, match="friction_cone"):
        DmControlBackend(backend.robot, backend.walk, friction_cone="conical")
    with pytest.raises(ValueError, match="impratio"):
        DmControlBackend(backend.robot, backend.walk, impratio=0.5)


def test_servo_kv_feeds_the_target_velocity_forward(backend):
    """servo_kv: force = kp (q_t - q) + kv (qdot_t - qdot), qdot_t from consecutive targets."""
    sim = backend.sim
    if sim.servo_kv <= 0:
        pytest.skip("servo_kv is off in conf/backend/dm_control.yaml")
    backend.reset(EMPTY, np.random.default_rng(0))
    legs = sim.physics.bind([sim.mjcf_model.find("actuator", n) for n in LEG_JOINT_NAMES])
    np.testing.assert_allclose(legs.biasprm[:, 2], -sim.servo_kv)
    base = backend.engine.standing_joint_targets()
    sim.set_leg_targets(base)
    np.testing.assert_allclose(legs.ctrl, base)  # at rest after reset: no feed-forward
    ramp = base + 0.01  # 0.01 rad per control tick
    sim.set_leg_targets(ramp)
    np.testing.assert_allclose(legs.ctrl, ramp + sim.servo_kv / legs.gainprm[:, 0] * 0.01 / backend.control_dt)
    with pytest.raises(ValueError, match="servo_kv"):
        DmControlBackend(backend.robot, backend.walk, servo_kv=-1.0)


def test_blow_up_is_a_sim_error_with_finite_observation(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo may write its warnings to MUJOCO_LOG.TXT in the cwd
    env = FootstepEnv(backend="dm_control")
    try:
        env.reset(seed=1)
        env.backend.sim.physics.data.qvel[:] = np.nan
        obs, reward, term, trunc, info = env.step(FORWARD)
        assert term and info["outcome"] == "sim_error" and "PhysicsError" in info["sim_error"]
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
        env.reset(seed=2)  # and the env recovers on reset
        assert env.backend.sim.sim_error() is None
        env.backend.sim.physics.data.qvel[6:] = 1e12  # a huge velocity: MuJoCo's instability warning
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
    names = [f"obstacle{i}" for i in range(N_CYLINDERS)] + ["ball"]
    pool = sim.physics.bind([sim.mjcf_model.find("geom", n) for n in names])
    bodies = sim.physics.bind([sim.mjcf_model.find("body", n) for n in names])  # one body per obstacle
    np.testing.assert_allclose(bodies.pos[0, :2], (1.0, 0.5))
    np.testing.assert_allclose(pool.size[1, 0], 0.3)
    np.testing.assert_allclose(bodies.pos[-1], (1.5, 0.0, 0.075))
    assert all(pool.contype[2:N_CYLINDERS] == 0) and all(pool.rgba[2:N_CYLINDERS, 3] == 0)
    assert not sim.obstacle_contact()
    backend.reset(EMPTY, np.random.default_rng(0))  # everything parked again
    assert (pool.contype == 0).all() and (bodies.pos[:, 2] < -50).all()
    with pytest.raises(ValueError, match="at most"):
        sim.set_obstacles(Scene(goal=Pose2D(), obstacles=tuple(Obstacle(i, 5.0, 0.1) for i in range(N_CYLINDERS + 1))))


def test_mjcf_model_is_dm_control_idiom(backend):
    sim = backend.sim
    assert isinstance(sim.mjcf_model, mjcf.RootElement)
    assert isinstance(sim.physics, mjcf.Physics)
    assert sim.physics.model.opt.timestep == pytest.approx(backend.physics_dt)


def _rss_mb():
    psutil = pytest.importorskip("psutil")
    gc.collect()
    return psutil.Process(os.getpid()).memory_info().rss / 2**20


@pytest.mark.memory
def test_many_resets_and_create_close_cycles_do_not_leak(backend):
    sim = backend.sim
    joints = dict(backend.robot.walk_ready) | dict(
        zip(LEG_JOINT_NAMES, backend.engine.standing_joint_targets().tolist())
    )
    base = np.array([0.0, 0.0, backend.walk.trunk_height])

    def reset(scene):  # the sim's reset verbs (the driver's settling ticks are plain physics.step calls)
        sim.set_obstacles(scene)
        sim.reset_robot(base, joints)
        sim.advance(2)
        sim.obstacle_contact()

    for _ in range(50):  # warm up allocators
        backend.reset(EMPTY, np.random.default_rng(0))
    before = _rss_mb()
    rng = np.random.default_rng(0)
    for i in range(1000):
        reset(
            Scene(
                goal=Pose2D(1.0, 0.0, 0.0),
                obstacles=(Obstacle(2.0, float(rng.uniform(-1, 1)), 0.2),),
                ball=Obstacle(1.2, 0.0, 0.075) if i % 2 else None,
            )
        )
    after_resets = _rss_mb()
    assert after_resets - before < 10.0, f"RSS grew {after_resets - before:.1f} MB over 1000 resets"

    for _ in range(3):
        DmControlBackend(backend.robot, backend.walk).close()
    start = _rss_mb()
    for _ in range(20):  # a backend left open holds ~1.7 MB (model, data, mjcf tree)
        DmControlBackend(backend.robot, backend.walk).close()
    grown = _rss_mb() - start
    assert grown < 10.0, f"RSS grew {grown:.1f} MB over 20 create/close cycles"

    for _ in range(2):
        b = DmControlBackend(backend.robot, backend.walk, render_size=(64, 48))
        b.render()
        b.close()
    start = _rss_mb()
    for _ in range(5):  # one whose rendering context is not freed holds ~130 MB; the GL driver
        b = DmControlBackend(backend.robot, backend.walk, render_size=(64, 48))  # warms up for a few more
        b.render()
        b.close()
    grown = _rss_mb() - start
    assert grown < 60.0, f"RSS grew {grown:.1f} MB over 5 create/render/close cycles"


@pytest.mark.slow
def test_headless_gl_opens_at_the_first_frame_not_at_import():
    """dm_control's EGL backend (53 MB resident) is opened only when something renders; then
    footsim's frames and dm_control's own rendering both work in the same process."""
    import subprocess
    import sys

    code = """
import sys
import gymnasium as gym
import footsim
EGL = "dm_control._render.pyopengl.egl_renderer"
env = gym.make("footsim/FootstepNav-v1", backend="dm_control")
env.reset(seed=0)
env.step(env.action_space.sample())
env.close()
print("egl before rendering:", EGL in sys.modules)
env = gym.make("footsim/FootstepNav-v1", backend="dm_control", render_mode="rgb_array")
env.reset(seed=0)
frame = env.render()
env.close()
print("frame:", frame.shape, float(frame.std()) > 1.0, "egl after:", EGL in sys.modules)
from dm_control import suite
print("suite frame:", float(suite.load("cartpole", "swingup").physics.render(48, 64).std()) > 1.0)
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env={**os.environ, "MUJOCO_GL": "egl"}
    ).stdout
    assert "egl before rendering: False" in out
    assert "frame: (480, 480, 3) True egl after: True" in out
    assert "suite frame: True" in out
