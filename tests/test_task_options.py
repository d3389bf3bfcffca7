"""Task options beyond the thesis: IMU tilt in the observation, a stability reward term."""

import math

import numpy as np
import pytest

from footsim import config as fconf
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.tasks import nav
from footsim.tasks.nav import NavTaskConfig


def test_stability_term_is_exp_of_the_max_tilt():
    scene = Scene(goal=Pose2D(1.0, 0.0, 0.0))
    a = [0.0] * 6
    plain = nav.reward_terms(Pose2D(), scene, a, a)
    assert "stability" not in plain  # the thesis's five terms unless asked
    terms = nav.reward_terms(Pose2D(), scene, a, a, max_tilt=0.1)
    assert terms["stability"] == pytest.approx(math.exp(-0.5))  # hand-computed: exp(-0.1 / 0.2), the default scale
    assert {k: terms[k] for k in plain} == plain
    config = NavTaskConfig(reward={"distance": {"weight": 1.0}, "stability": {"weight": 1.0, "params": {"scale": 0.4}}})
    assert config.uses_tilt
    terms = nav.reward_terms(Pose2D(), scene, a, a, max_tilt=0.1, config=config)
    assert terms == pytest.approx({"distance": math.exp(-0.5), "stability": math.exp(-0.25)})


def test_imu_values_are_appended_after_the_thesis_layout():
    config = NavTaskConfig(observe_imu=True, imu_scale=0.35)
    scene = Scene(goal=Pose2D(1.0, 0.5, 0.3))
    prev = ([0.1] * 6, [-0.2] * 6)
    base = nav.observation(Pose2D(), scene, prev, NavTaskConfig())
    obs = nav.observation(Pose2D(), scene, prev, config, tilt=(0.1, -0.2, 0.3))
    assert config.observation_size == 20 and obs.shape == (20,)
    np.testing.assert_array_equal(obs[:17], base)
    np.testing.assert_allclose(obs[17:], np.tanh(np.array([0.1, -0.2, 0.3]) / 0.35), rtol=1e-6)
    assert NavTaskConfig(obstacles=True, observe_imu=True).observation_size == 17 + 36 + 3


def test_bad_option_values_are_named():
    with pytest.raises(ValueError, match="task.observe_imu"):
        fconf.build_task({"name": "nav", "observe_imu": "yes"})
    with pytest.raises(ValueError, match="task.imu_scale"):
        fconf.build_task({"name": "nav", "imu_scale": -1.0})
    with pytest.raises(ValueError, match="unknown term.*wobble"):
        fconf.build_task({"name": "nav", "reward": {"wobble": {"weight": 0.1}}})


def test_2d_env_with_the_options_reports_zero_tilt():
    task = dict(
        fconf.load_preset("task", "nav"),
        observe_imu=True,
        reward={
            "distance": {"weight": 0.3},
            "angle": {"weight": 0.3},
            "orientation": {"weight": 0.2},
            "continuity": {"weight": 0.1},
            "stability": {"weight": 0.1, "params": {"scale": 0.2}},
        },
    )
    env = FootstepEnv(task=task)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (20,) and env.observation_space.shape == (20,)
    obs, _, _, _, info = env.step(np.full(6, 0.5, dtype=np.float32))
    np.testing.assert_array_equal(obs[17:], 0.0)
    assert info["reward_terms"]["stability"] == 1.0  # nothing tilts in 2D
    env.close()


def test_mujoco_env_observes_the_measured_tilt():
    pytest.importorskip("mujoco")
    from footsim.backends.physics3d import fused_roll_pitch

    task = dict(fconf.load_preset("task", "nav"), observe_imu=True)
    env = FootstepEnv(backend="mujoco", task=task)
    try:
        env.reset(seed=1)
        obs, _, _, _, info = env.step(np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0], dtype=np.float32))
        assert info["outcome"] == "running"
        roll, pitch = fused_roll_pitch(env.backend.sim.base_pose()[1])  # independent read of the base
        np.testing.assert_allclose(obs[17:19], np.tanh(np.array([roll, pitch]) / 0.35), atol=1e-6)
        assert np.tanh(max(abs(roll), abs(pitch)) / 0.35) <= obs[19] + 1e-6
    finally:
        env.close()


def test_path_hint_points_at_the_goal_in_free_space():
    scene = Scene(goal=Pose2D(2.0, 1.0, 0.5))
    config = NavTaskConfig(path_hint=True)
    hint = nav.PathHint(scene, Pose2D(), config)
    pose = Pose2D(0.0, 0.0, 0.3)
    sin_h, cos_h = hint.bearing(pose)
    beta = math.atan2(1.0, 2.0) - 0.3  # hand-computed bearing to the goal, robot frame
    assert (sin_h, cos_h) == pytest.approx((math.sin(beta), math.cos(beta)), abs=1e-9)


def test_path_hint_goes_around_an_obstacle_on_the_straight_line():
    from footsim.scene import Obstacle

    scene = Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(1.0, 0.0, 0.3),))
    config = NavTaskConfig(obstacles=True, path_hint=True, path_hint_lookahead=1.0)
    hint = nav.PathHint(scene, Pose2D(), config)
    sin_h, cos_h = hint.bearing(Pose2D())
    assert abs(sin_h) > 0.3  # not straight at the obstacle (bearing 0)
    # every planned point keeps the clearance from the obstacle (cell-size tolerance)
    assert np.hypot(hint.points[:, 0] - 1.0, hint.points[:, 1]).min() >= 0.3 + 0.2 - 0.05
    obs = nav.observation(Pose2D(), scene, ([0.0] * 6, [0.0] * 6), config, hint=(sin_h, cos_h))
    assert config.observation_size == 17 + 36 + 2 and obs.shape == (55,)
    assert obs[-2:] == pytest.approx([sin_h, cos_h], abs=1e-6)


def test_env_with_path_hint_runs_and_checks_pass():
    from gymnasium.utils.env_checker import check_env

    task = dict(fconf.load_preset("task", "nav_obstacles"), path_hint=True)
    env = FootstepEnv(task=task)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    assert obs.shape == (55,)
    for _ in range(5):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert np.isfinite(obs).all() and abs(obs[-2] ** 2 + obs[-1] ** 2 - 1.0) < 1e-5
        if terminated or truncated:
            break
    env.close()
    with pytest.raises(ValueError, match="task.path_hint"):
        fconf.build_task({"name": "nav", "path_hint": 1})


def test_contact_term_pays_only_for_steps_without_an_obstacle_contact():
    """The same MuJoCo episode (walking into an obstacle) with the contact term at weight 0 and 0.5:
    the rewards differ by 0.5 on the steps without a contact and by 0 on those with one."""
    pytest.importorskip("mujoco")
    from footsim.scene import Obstacle

    blocked = Scene(goal=Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.35, 0.0, 0.15),))
    forward = np.array([0.5, 0.0, 0.0, 0.5, 0.0, 0.0], dtype=np.float32)

    def episode(weight):
        task = fconf.load_preset("task", "nav_obstacles")
        task["reward"]["contact"] = {"weight": weight}
        env = FootstepEnv(backend="mujoco", task=dict(task, max_steps=4))
        try:
            env.reset(seed=0, options={"scene": blocked})
            steps = [env.step(forward) for _ in range(4)]
        finally:
            env.close()
        return [(reward, info["collided"], info["reward_terms"]["contact"]) for _, reward, _, _, info in steps]

    off, on = episode(0.0), episode(0.5)
    assert [c for _, c, _ in off] == [c for _, c, _ in on]  # the weight changes no physics
    assert any(c for _, c, _ in on) and not all(c for _, c, _ in on)
    for (r_off, collided, _), (r_on, _, value) in zip(off, on):
        assert value == (0.0 if collided else 1.0)
        assert r_on - r_off == pytest.approx(0.0 if collided else 0.5)
    scene = Scene(goal=Pose2D(1.0, 0.0, 0.0))
    a = [0.0] * 6
    assert "contact" not in nav.reward_terms(Pose2D(), scene, a, a)  # only when the contact is given
    assert nav.reward_terms(Pose2D(), scene, a, a, collided=True)["contact"] == 0.0


def test_history_holds_the_earlier_observations_newest_first():
    """With the thesis's noise each observation differs; the history block of each observation is
    the goal features and rays of the observations the test saw before it, newest first, and the
    episode's first observation stands in for the ones before it (again after a reset)."""
    task = dict(fconf.load_preset("task", "nav_obstacles"), observe_history=2)
    env = FootstepEnv(task=task, noise=fconf.load_preset("noise", "localization"))
    assert env.observation_space.shape == (53 + 2 * 41,)
    assert env.task.observation_layout[-1] == ("history", 82)

    def block(obs):  # goal features (5) and rays (36) of an observation
        return np.concatenate([obs[:5], obs[17:53]])

    for seed in (3, 4):  # the second reset starts a fresh history
        obs, _ = env.reset(seed=seed)
        seen = [obs]
        np.testing.assert_array_equal(obs[53:], np.concatenate([block(obs), block(obs)]))
        for _ in range(6):
            obs, _, terminated, truncated, _ = env.step(np.array([0.3, 0.0, 0.1, 0.3, 0.0, 0.1], dtype=np.float32))
            np.testing.assert_array_equal(env.task.observe(env._believed), obs)  # observing again changes nothing
            older = seen[-2] if len(seen) > 1 else seen[-1]
            np.testing.assert_array_equal(obs[53:], np.concatenate([block(seen[-1]), block(older)]))
            assert not np.array_equal(block(obs), block(seen[-1]))  # fresh noise: the blocks differ
            seen.append(obs)
            if terminated or truncated:
                break
    assert NavTaskConfig(observe_history=3).observation_size == 17 + 3 * 5  # without obstacles: goal features only


def test_bad_history_values_are_named():
    for value in (-1, 1.5, True):
        with pytest.raises(ValueError, match="task.observe_history"):
            NavTaskConfig(observe_history=value)


def test_start_in_place_walks_in_place_first_then_executes_the_actions():
    """With start_in_place=2 the first two double steps are walked in place whatever the action
    (the pose stays the start pose, the time runs on), and the third executes the action exactly
    as the first step of an episode without the option does."""
    scene = Scene(goal=Pose2D(1.5, 0.4, 0.3))
    action = np.array([0.6, -0.3, 0.4, 0.5, 0.2, -0.1], dtype=np.float32)
    plain = FootstepEnv()
    started = FootstepEnv(task=dict(fconf.load_preset("task", "nav"), start_in_place=2))
    plain.reset(seed=5, options={"scene": scene})
    plain.step(action)
    moved = plain.task.pose
    started.reset(seed=5, options={"scene": scene})
    start = started.task.pose
    durations = []
    for _ in range(2):
        _, _, terminated, truncated, info = started.step(action)
        assert not (terminated or truncated)
        assert tuple(started.task.pose) == pytest.approx(tuple(start), abs=1e-12)  # in place
        assert started.task.previous_actions[0] == [0.0] * 6  # the reward's continuity sees the executed step
        durations.append(info["time_s"])
    assert durations[0] > 0 and durations[1] == pytest.approx(2 * durations[0])
    started.step(action)
    assert tuple(started.task.pose) == pytest.approx(tuple(moved), abs=1e-9)
    assert started.task.steps == 3


def test_start_step_scale_executes_the_scaled_action_first():
    """With start_step_scale=0.4 the first start_in_place double step executes 0.4 times the
    policy's action: the pose and the recorded previous action are those of an episode without the
    option given 0.4 times the action; the next step executes the action itself."""
    scene = Scene(goal=Pose2D(1.5, 0.4, 0.3))
    action = np.array([0.6, -0.3, 0.4, 0.5, 0.2, -0.1], dtype=np.float32)
    scaled = [0.4 * float(a) for a in action]
    plain = FootstepEnv()
    started = FootstepEnv(task=dict(fconf.load_preset("task", "nav"), start_in_place=1, start_step_scale=0.4))
    for env in (plain, started):
        env.reset(seed=5, options={"scene": scene})
    plain.step(np.array(scaled, dtype=np.float32))
    started.step(action)
    # the plain env takes the scaled action as float32: equal to 1e-6
    assert tuple(started.task.pose) == pytest.approx(tuple(plain.task.pose), abs=1e-6)
    assert started.task.previous_actions[0] == pytest.approx(scaled, abs=1e-6)
    plain.step(action)
    started.step(action)
    assert tuple(started.task.pose) == pytest.approx(tuple(plain.task.pose), abs=1e-6)


def test_bad_start_in_place_values_are_named():
    for value in (-1, 1.5, True, 100):
        with pytest.raises(ValueError, match="task.start_in_place"):
            NavTaskConfig(start_in_place=value)
    for scale in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"task.start_step_scale must be in \[0, 1\]"):
            NavTaskConfig(start_step_scale=scale)
    with pytest.raises(ValueError, match=r"task.start_in_place must be an integer in \[0, task.max_steps\), got 5"):
        NavTaskConfig(start_in_place=5, max_steps=5)  # the whole episode in place


@pytest.mark.parametrize(
    ("key", "value"),
    [("max_steps", 0), ("max_steps", 2.5), ("max_steps", False), ("n_rays", 0), ("n_rays", 36.0), ("n_rays", "36")],
)
def test_count_settings_refuse_what_is_not_a_whole_count(key, value):
    """A count that int() would silently truncate or accept (2.5 -> 2, True -> 1, 36.0) is named."""
    with pytest.raises(ValueError, match=f"task.{key} must be an integer >= 1, got {value!r}"):
        NavTaskConfig(**{key: value})


def test_count_settings_accept_numpy_integers():
    config = NavTaskConfig(max_steps=np.int64(7), start_in_place=np.int32(6), observe_history=np.int16(1))
    assert (config.max_steps, config.start_in_place, config.observe_history) == (7, 6, 1)
