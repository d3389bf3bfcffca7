"""The backend contract, once for every backend (``pymunk``, ``mujoco``, ``dm_control``,
``pybullet``): what ``Backend.reset`` / ``execute`` / ``render`` / ``close`` / ``capabilities``
promise, through ``gymnasium.make`` and the backend interface.  What only one simulator does
(its name mapping, its faults, its memory) is tested in ``tests/test_backend_<name>.py``."""

import importlib.util
import math
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import footsim  # noqa: E402,F401  (registers the env)
from footsim.backends.base import Backend, StepResult  # noqa: E402
from footsim.geometry import Pose2D  # noqa: E402
from footsim.randomization import TERMS  # noqa: E402
from footsim.scene import Obstacle, Scene  # noqa: E402
from footsim.tasks.nav import tilted_over
from footsim.walk.footsteps import DoubleStep  # noqa: E402

ENV_ID = "footsim/FootstepNav-v1"
BACKENDS = ["pymunk", "mujoco", "dm_control", "pybullet"]
SIMULATOR = {"pymunk": "pymunk", "mujoco": "mujoco", "dm_control": "dm_control", "pybullet": "pybullet"}
EMPTY = Scene(goal=Pose2D(100.0, 0.0, 0.0))
FORWARD = np.array([0.5, 0.0, 0.0, 0.5, 0.0, 0.0])


def _require(name: str) -> None:
    if importlib.util.find_spec(SIMULATOR[name]) is None:
        pytest.skip(f"{name} is not installed")


def _make(name: str, **kwargs):
    _require(name)
    return gym.make(ENV_ID, backend=name, **kwargs)


# The tests share a module-scoped backend or env whose state one hands on to the next: under xdist
# they run on one worker, in file order (--dist loadgroup).
pytestmark = pytest.mark.xdist_group("test_backend_contract")


@pytest.fixture(scope="module", params=BACKENDS)
def backend(request) -> Backend:
    env = _make(request.param)
    yield env.unwrapped.backend
    env.close()


def _walk(backend: Backend, scene: Scene, steps: int, seed: int = 0) -> tuple[Pose2D, list[StepResult]]:
    start = backend.reset(scene, np.random.default_rng(seed))
    return start, [backend.execute(DoubleStep.from_action(FORWARD, backend.robot.step_limits)) for _ in range(steps)]


def test_reset_places_the_robot_at_the_origin(backend):
    start = backend.reset(EMPTY, np.random.default_rng(0))
    assert isinstance(start, Pose2D)
    assert abs(start.x) < 0.05 and abs(start.y) < 0.05 and abs(start.theta) < 0.05


def test_walking_forward_moves_forward_and_reports_the_truth(backend):
    start, results = _walk(backend, EMPTY, 5)
    for result in results:
        assert not tilted_over(result) and result.sim_error is None and not result.collided
        assert result.duration_s > 0 and result.executed is not None and result.feet is not None
        assert max(abs(result.tilt[0]), abs(result.tilt[1])) <= result.max_tilt + 1e-12
        if backend.kind == "3d":
            assert 0 < result.max_tilt < 0.7  # walking tilts the trunk, but far from a fall
    pose = results[-1].pose
    assert pose.x - start.x > 0.4  # 5 double steps of ~0.16 m commanded (the first one shorter)
    assert abs(pose.y - start.y) < 0.25


def test_obstacle_contact_is_reported(backend):
    """An obstacle straight ahead: walking into it is reported as a contact (whether it ends the
    episode is the task's decision)."""
    _, results = _walk(backend, Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.35, 0.0, 0.15),)), 6)
    assert any(r.collided for r in results)
    _, results = _walk(backend, Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.35, 1.5, 0.15),)), 3)
    assert not any(r.collided for r in results)  # the same obstacle to the side: no contact


def test_capabilities_are_randomization_terms_the_backend_applies(backend):
    assert backend.capabilities and set(backend.capabilities) <= set(TERMS)
    if backend.kind == "3d":
        from footsim.backends.physics3d import DRIVER_TERMS, PHYSICS_TERMS

        assert backend.capabilities == DRIVER_TERMS | PHYSICS_TERMS


@pytest.mark.parametrize("name", BACKENDS)
def test_same_seed_same_trajectory(name):
    def trajectory():
        env = _make(name, obstacles=True)
        try:
            env.reset(seed=7)
            rng = np.random.default_rng(7)
            rows = []
            for _ in range(4):
                obs, reward, _, _, info = env.step(rng.uniform(-0.5, 0.5, 6).astype(np.float32))
                rows.append(np.concatenate([info["pose"], obs, [reward]]))
            return np.array(rows)
        finally:
            env.close()

    np.testing.assert_array_equal(trajectory(), trajectory())  # bit-identical


@pytest.mark.parametrize("name", BACKENDS)
def test_render_gives_an_rgb_frame(name):
    backend_cfg = name if name == "pymunk" else {"name": name, "render_size": [160, 120]}
    _require(name)
    env = gym.make(ENV_ID, backend=backend_cfg, obstacles=True, render_mode="rgb_array")
    try:
        env.reset(seed=3)
        frame = env.render()
    finally:
        env.close()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    if name != "pymunk":
        assert frame.shape == (120, 160, 3)
    assert frame.std() > 5.0  # not blank
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 20


@pytest.mark.parametrize("name", BACKENDS)
def test_env_checkers_pass(name):
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = _make(name, obstacles=True)
    try:
        gym_check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.parametrize("name", BACKENDS)
def test_close_twice_is_harmless(name):
    env = _make(name)
    env.reset(seed=0)
    backend = env.unwrapped.backend
    env.close()
    backend.close()


@pytest.mark.parametrize("name", BACKENDS)
def test_a_closed_env_refuses_step_reset_and_render_naming_close(name):
    _require(name)
    env = gym.make(ENV_ID, backend=name, obstacles=True, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(FORWARD)
    env.close()
    for verb, call in (
        ("step", lambda: env.step(FORWARD)),
        ("reset", lambda: env.reset(seed=1)),
        ("render", env.render),
    ):
        with pytest.raises(RuntimeError, match=rf"^{verb}\(\) called after close\(\): this env's {name} backend"):
            call()
    env.close()  # still harmless


@pytest.mark.parametrize("name", BACKENDS)
def test_an_unknown_option_is_named(name):
    _require(name)
    with pytest.raises(ValueError, match=rf"backend {name}: unknown key\(s\) \['no_such_option'\]; valid: \[.*'name'"):
        gym.make(ENV_ID, backend={"name": name, "no_such_option": 1.0})


@pytest.mark.parametrize("name", BACKENDS)
def test_an_unsupported_randomization_term_is_refused_naming_the_backend(name):
    """A term the backend cannot apply fails at start, never a silent no-op."""
    section, term = ("terms_2d", "push_force") if name == "pymunk" else ("terms_3d", "footstep_noise_x")
    _require(name)
    with pytest.raises(ValueError, match=rf"backend '{name}' cannot apply randomization term\(s\) \['{term}'\]"):
        gym.make(ENV_ID, backend=name, randomization={section: {term: {"dist": "constant", "value": 0.01}}})


def test_the_3d_backends_share_one_fall_rule():
    """Every 3D backend reports a fall by the same fused-tilt threshold (``fall_threshold``, a
    constructor argument of the shared driver) and a tilt that is finite and bounded."""
    for name in ("mujoco", "dm_control", "pybullet"):
        if importlib.util.find_spec(SIMULATOR[name]) is None:
            continue
        env = gym.make(ENV_ID, backend=name)
        try:
            backend = env.unwrapped.backend
            assert 0 < backend.fall_threshold < math.pi / 2
            backend.reset(EMPTY, np.random.default_rng(0))
            result = backend.execute(DoubleStep.from_action(FORWARD, backend.robot.step_limits))
            assert all(math.isfinite(v) for v in result.tilt) and result.max_tilt < backend.fall_threshold
        finally:
            env.close()
