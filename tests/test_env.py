import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import footsim  # noqa: F401  (registers the env)
from footsim.config import load_preset
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.scene import Obstacle, Scene


@pytest.mark.parametrize("kwargs", [{}, {"obstacles": True}, {"obstacles": True, "noise": "localization"}])
def test_env_checkers_pass(kwargs):
    env = gym.make("footsim/FootstepNav-v1", **kwargs)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(FootstepEnv(**kwargs))


def test_info_keys_and_spaces():
    env = FootstepEnv(obstacles=True, noise="localization")
    assert env.observation_space.shape == (53,) and env.action_space.shape == (6,)
    obs, info = env.reset(seed=0)
    for key in ("pose", "pose_estimate", "outcome", "time_s", "reward_terms"):
        assert key in info
    obs, r, term, trunc, info = env.step(np.zeros(6))
    assert set(info["reward_terms"]) == {"distance", "angle", "orientation", "obstacle", "continuity", "contact"}
    assert info["time_s"] == pytest.approx(1 / 1.9633)
    assert not np.allclose(info["pose"], info["pose_estimate"])  # noise is applied


def _rollout(env, seed, n=30):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for _ in range(n):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6))
        out += [obs, np.array([r]), info["pose"]]
        if term or trunc:
            obs, _ = env.reset()
    return np.concatenate([np.ravel(x) for x in out])


def test_same_seed_same_episode():
    a = _rollout(FootstepEnv(obstacles=True, noise="localization"), seed=5)
    b = _rollout(FootstepEnv(obstacles=True, noise="localization"), seed=5)
    c = _rollout(FootstepEnv(obstacles=True, noise="localization"), seed=6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_episode_streams_are_integers_draws_of_the_env_rng():
    # The per-episode seeds come from the raw stream; they must stay what integers(2**63) draws
    # (the streams of earlier footsim versions, so recorded results reproduce).
    env = FootstepEnv()
    env.reset(seed=11)
    reference = np.random.default_rng(11)  # gymnasium's np_random for seed 11
    reference.standard_normal(3)  # the scene: goal x, y, theta
    seeds = [int(reference.integers(2**63)) for _ in range(3)]
    assert [env.episode_seeds[k] for k in ("noise", "backend", "randomization")] == seeds


def test_success_adds_the_remaining_steps():
    # goal exactly where one forward double step puts the robot
    env = FootstepEnv()
    env.reset(seed=0, options={"scene": Scene(Pose2D(0.234, 0.0, 0.0))})
    obs, r, term, trunc, info = env.step(np.array([1, 0, 0, 1, 0, 0.0]))
    assert info["outcome"] == "success" and term
    # all terms 1 except distance and continuity
    base = 0.3 * 1 + 0.3 * 1 + 0.2 * 1 + 0.2 * (2 * math.exp(-3) + 4) / 6
    assert r == pytest.approx(base + 99.0)
    # task.success_bonus scales what each remaining step pays (thesis: 1)
    env = FootstepEnv(task={"name": "nav", "success_bonus": 2.5})
    env.reset(seed=0, options={"scene": Scene(Pose2D(0.234, 0.0, 0.0))})
    obs, r, term, trunc, info = env.step(np.array([1, 0, 0, 1, 0, 0.0]))
    assert info["outcome"] == "success" and r == pytest.approx(base + 2.5 * 99.0)
    with pytest.raises(ValueError, match="success_bonus"):
        FootstepEnv(task={"name": "nav", "success_bonus": -1.0})
    # null (the preset's): the maximum step reward, here 1 + 0.5 with the contact term weighted 0.5
    task = load_preset("task", "nav")
    task["reward"]["contact"] = {"weight": 0.5}
    assert task["success_bonus"] is None
    env = FootstepEnv(task=task)
    env.reset(seed=0, options={"scene": Scene(Pose2D(0.234, 0.0, 0.0))})
    obs, r, term, trunc, info = env.step(np.array([1, 0, 0, 1, 0, 0.0]))
    assert info["outcome"] == "success" and r == pytest.approx(base + 0.5 + 1.5 * 99.0)


def test_timeout_after_100_double_steps():
    env = FootstepEnv()
    env.reset(seed=0, options={"scene": Scene(Pose2D(5.0, 5.0, 0.0))})
    for _ in range(100):
        obs, r, term, trunc, info = env.step(np.zeros(6))
        assert not term
    assert trunc and info["outcome"] == "timeout" and info["steps"] == 100


def test_collision_ends_the_2d_episode():
    env = FootstepEnv(obstacles=True)
    scene = Scene(Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.45, 0.0, 0.15),), ball=Obstacle(2.2, 0, 0.075))
    env.reset(seed=0, options={"scene": scene})
    obs, r, term, trunc, info = env.step(np.array([1, 0, 0, 1, 0, 0.0]))  # left foot lands at x=0.312
    assert term and info["outcome"] == "collision"


def test_walking_past_an_obstacle_is_not_a_collision():
    env = FootstepEnv(obstacles=True)
    scene = Scene(Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.45, 0.5, 0.15),), ball=Obstacle(2.2, 0, 0.075))
    env.reset(seed=0, options={"scene": scene})
    for _ in range(3):
        obs, r, term, trunc, info = env.step(np.array([1, 0, 0, 1, 0, 0.0]))
        assert not term


def test_a_given_scene_blocking_the_start_or_the_goal_is_refused_naming_it(tmp_path):
    """The sampler keeps obstacles off a circle of task.scenes.robot_radius (0.2 m) around the start
    and the goal, and the ball off the start; a scene given from outside must keep the same rule."""
    from footsim.planners.controllers import make_controller
    from footsim.rl.evaluate import evaluate
    from footsim.tasks.scenes import load_scenes, save_scenes

    goal = Pose2D(2.0, 0.0, 0.0)
    fine = Scene(goal, obstacles=(Obstacle(0.35, 0.0, 0.15),))  # touching the start footprint: allowed
    on_start = Scene(goal, obstacles=(Obstacle(1.0, 1.0, 0.1), Obstacle(0.1, 0.0, 0.2)))
    on_goal = Scene(goal, obstacles=(Obstacle(2.1, 0.2, 0.15),))
    ball_on_start = Scene(goal, ball=Obstacle(0.2, 0.0, 0.075))
    env = FootstepEnv(obstacles=True)
    env.reset(seed=0, options={"scene": fine})
    with pytest.raises(ValueError, match=r"obstacle 1 \(x=0.1, y=0, r=0.2\) overlaps the robot's start footprint"):
        env.reset(seed=0, options={"scene": on_start})
    with pytest.raises(
        ValueError, match=r"obstacle 0 \(x=2.1, y=0.2, r=0.15\) overlaps the robot's footprint at the goal"
    ):
        env.reset(seed=0, options={"scene": on_goal})
    with pytest.raises(ValueError, match=r"the ball \(x=0.2, y=0, r=0.075\) overlaps the robot's start footprint"):
        env.reset(seed=0, options={"scene": ball_on_start})
    with pytest.raises(ValueError, match=r"^scenes: scene 2: obstacle 0 .* at the goal"):
        FootstepEnv(obstacles=True, scenes=[fine, fine, on_goal])
    # a scene file as footsim-eval reads it: refused before any episode runs, naming the scene's index
    path = tmp_path / "scenes.json"
    save_scenes(path, [fine, on_start, fine])
    controller = make_controller(env, {"name": "velocity"})
    with pytest.raises(ValueError, match=r"^scene 1: obstacle 1 .* start footprint"):
        evaluate(env, controller, load_scenes(path), progress=False)
    env.close()


_WITHOUT_PACKAGES = """
import importlib.abc, sys
BLOCKED = set(sys.argv[2].split(","))

class Missing(importlib.abc.MetaPathFinder):  # as if these packages were not installed
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, Missing())
import gymnasium as gym
import footsim
try:
    gym.make("footsim/FootstepNav-v1", backend=sys.argv[1])
except ImportError as err:
    print("ImportError:", err)
"""


@pytest.mark.parametrize(
    "backend, missing, extra",
    [
        ("mujoco", "mujoco", "mujoco"),
        ("dm_control", "dm_control", "dm_control"),
        ("dm_control", "dm_control,mujoco", "dm_control"),
        ("pybullet", "pybullet", "pybullet"),
    ],
)
def test_missing_simulator_names_the_extra_to_install(backend, missing, extra):
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", _WITHOUT_PACKAGES, backend, missing],
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    ).stdout
    assert out.startswith("ImportError:") and f"pip install 'footsim[{extra}]'" in out
    assert f"{missing.split(',')[0]} package" in out.replace("'", "")  # names the missing package


def test_bad_inputs_raise_clear_errors():
    env = FootstepEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([np.nan, 0, 0, 0, 0, 0]))
    with pytest.raises(ValueError, match="unknown backend 'bogus'; valid backends: pymunk, mujoco"):
        FootstepEnv(backend="bogus")
    with pytest.raises(ValueError, match="unknown noise preset 'loud'"):
        FootstepEnv(noise="loud")
    with pytest.raises(ValueError, match="noise.sigma_x"):
        FootstepEnv(noise={"sigma_x": -1.0})
    with pytest.raises(ValueError, match="task.scenes.obstacle_radius_min"):
        FootstepEnv(task={"name": "nav_obstacles", "scenes": {"obstacle_radius_min": -0.2}})
    with pytest.raises(ValueError, match="task.max_steps"):
        FootstepEnv(task={"max_steps": 0})


def test_out_of_range_actions_are_clipped():
    a, b = FootstepEnv(), FootstepEnv()
    a.reset(seed=1)
    b.reset(seed=1)
    oa = a.step(np.array([5, -5, 2, 1, -1, 1.0]))
    ob = b.step(np.array([1, -1, 1, 1, -1, 1.0]))
    np.testing.assert_array_equal(oa[0], ob[0])
    assert oa[1] == ob[1]


def test_render_is_an_rgb_image():
    env = FootstepEnv(obstacles=True, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.ones(6))
    frame = env.render()
    assert frame.shape == (600, 600, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 5  # something is drawn
