"""The task owns the episode: reward and termination terms as data, decided from the backend's truth."""

import math

import numpy as np
import pytest

from footsim import config as fconf
from footsim.backends.base import StepResult
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.scene import Obstacle, Scene
from footsim.tasks.nav import NavTask, NavTaskConfig
from footsim.tasks.terms import (
    REWARD_TERMS,
    TERMINATION_TERMS,
    StepContext,
    reward_table,
    reward_term,
    termination_table,
)


def lateral_offset(step, scale: float) -> float:
    """A user's reward term, found by ``func: "<this module>:lateral_offset"``."""
    return math.exp(-abs(step.pose.y) / scale)


def far_away(step, radius: float) -> bool:
    """A user's termination term: the robot left a disc around the start."""
    return math.hypot(step.pose.x, step.pose.y) > radius


@reward_term("upright_bonus_for_tests", needs=("tilt",))
def upright_bonus(step) -> float:
    """A user's term that reads the backend's tilt (declared with ``needs``)."""
    return 1.0 - step.max_tilt


def _task(kind: str = "2d", **options) -> NavTask:
    task = NavTask(NavTaskConfig(obstacles=True, **options), kind)
    task.reset(Scene(Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(1.0, 1.0, 0.2),)), Pose2D())
    return task


def _result(**truth) -> StepResult:
    return StepResult(pose=truth.pop("pose", Pose2D(0.1, 0.0, 0.0)), duration_s=0.5, **truth)


def test_collision_rule_defaults_by_backend_kind():
    assert _task("2d").config.collision_ends_episode is True
    assert _task("3d").config.collision_ends_episode is False
    assert _task("3d", collision_ends_episode=True).config.collision_ends_episode is True


@pytest.mark.parametrize(
    "truth, outcome",
    [
        ({"sim_error": "exploded", "max_tilt": 1.0, "collided": True}, "sim_error"),
        ({"max_tilt": 0.71, "collided": True}, "fall"),
        ({"max_tilt": 0.69, "collided": True}, "collision"),
        ({"max_tilt": math.pi / 2, "pose": Pose2D(2.0, 0.0, 0.0)}, "fall"),
        ({"collided": True, "pose": Pose2D(2.0, 0.0, 0.0)}, "collision"),
        ({"pose": Pose2D(2.0, 0.0, 0.0)}, "success"),
        ({"pose": Pose2D(math.nan, 0.0, 0.0)}, "sim_error"),
    ],
)
def test_outcome_priority_from_the_truth(truth, outcome):
    task = _task()
    reward, terms, terminated, truncated = task.step(_result(**truth), [0.0] * 6)
    assert task.outcome == outcome and terminated and not truncated
    if outcome == "sim_error":
        assert reward == 0.0 and task.pose == Pose2D()  # the last finite pose is kept
    if outcome == "success":  # all five terms in [0, 1] plus 99 remaining steps at the maximum
        assert reward == pytest.approx(sum(terms[k] * w for k, w in zip(terms, (0.3, 0.3, 0.2, 0.0, 0.2))) + 99.0)


def test_3d_contacts_do_not_end_the_episode_and_the_threshold_is_the_tasks():
    task = _task("3d", fall_threshold=0.5)
    _, _, terminated, _ = task.step(_result(collided=True, max_tilt=0.45), [0.0] * 6)
    assert not terminated and task.outcome == "running"
    task.step(_result(max_tilt=0.55), [0.0] * 6)
    assert task.outcome == "fall"


def test_timeout_truncates_after_max_steps():
    task = _task(max_steps=3)
    flags = [task.step(_result(), [0.0] * 6)[2:] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)] and task.outcome == "timeout"


def test_a_user_reward_term_is_one_function_and_one_config_entry():
    term = {"weight": 0.5, "func": f"{__name__}:lateral_offset", "params": {"scale": 0.25}}
    env = FootstepEnv(task={"name": "nav", "reward": {"lateral": term}})
    plain = FootstepEnv()
    try:
        env.reset(seed=2)
        plain.reset(seed=2)
        action = np.array([0.2, 0.6, 0.0, 0.2, 0.6, 0.0])
        _, reward, _, _, info = env.step(action)
        _, reward_plain, _, _, info_plain = plain.step(action)
        expected = math.exp(-abs(info["pose"][1]) / 0.25)  # hand-computed from the reported true pose
        assert info["reward_terms"]["lateral"] == pytest.approx(expected)
        assert list(info["reward_terms"])[-1] == "lateral"  # appended after the preset's terms
        assert reward == pytest.approx(reward_plain + 0.5 * expected)
    finally:
        env.close()
        plain.close()


def test_a_user_reward_term_can_be_added_on_the_command_line():
    """``+task.reward.NAME={...}`` composes (the term tables are untyped for this) and the task
    resolves the user's function; a misspelt key in an entry is named when the task is built."""
    override = f"+task.reward.lateral={{weight:0.5,func:'{__name__}:lateral_offset',params:{{scale:0.25}}}}"
    cfg = fconf.compose("config", ["task=nav", override])
    _, config = fconf.build_task(fconf.to_plain(cfg.task))
    lateral = config.reward_terms[-1]
    assert (lateral.name, lateral.weight) == ("lateral", 0.5)
    step = StepContext(config)
    step.pose = Pose2D(0.0, 0.1, 0.0)
    assert lateral.call(step) == pytest.approx(math.exp(-0.1 / 0.25))  # hand-computed
    cfg = fconf.compose("config", ["task=nav", "+task.reward.distance.wieght=1"])
    with pytest.raises(ValueError, match=r"task.reward.distance: unknown key\(s\) \['wieght'\]"):
        fconf.build_task(fconf.to_plain(cfg.task))


def test_a_user_term_needing_the_tilt_makes_the_task_ask_for_it():
    config = NavTaskConfig(reward={"upright": {"weight": 0.5, "func": f"{__name__}:upright_bonus"}})
    assert config.uses_tilt
    task = NavTask(config, "3d")
    task.reset(Scene(Pose2D(2.0, 0.0, 0.0)), Pose2D())
    reward, terms, _, _ = task.step(_result(max_tilt=0.25, tilt=(0.1, -0.25)), [0.0] * 6)
    assert terms == {"upright": 0.75} and reward == 0.375 and task.tilt == (0.1, -0.25, 0.25)


def test_a_registered_term_named_by_func_keeps_its_registration():
    """``func`` naming a registered function under another name keeps what it was registered
    with: a reward term its requirements, a termination term its settle rule (success: the
    remaining steps are paid)."""
    (arrived,) = termination_table({"arrived": {"func": "footsim.tasks.nav:success"}})
    assert arrived.name == "arrived" and arrived.settle is TERMINATION_TERMS["success"].settle is not None
    (upright,) = reward_table(
        {"upright": {"weight": 1.0, "func": "footsim.tasks.nav:stability", "params": {"scale": 0.2}}}
    )
    assert upright.needs == REWARD_TERMS["stability"].needs == frozenset({"tilt"})


def test_a_user_termination_term_names_its_outcome():
    terminations = {"far_away": {"func": f"{__name__}:far_away", "params": {"radius": 0.3}}}
    env = FootstepEnv(task={"name": "nav", "terminations": terminations})
    try:
        env.reset(seed=0, options={"scene": Scene(Pose2D(5.0, 0.0, 0.0))})
        outcomes = []
        for _ in range(5):
            _, _, terminated, _, info = env.step(np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]))
            outcomes.append(info["outcome"])
            if terminated:
                break
        assert outcomes[-1] == "far_away" and math.hypot(*info["pose"][:2]) > 0.3
        assert all(o == "running" for o in outcomes[:-1])
    finally:
        env.close()


@pytest.mark.parametrize(
    "task, message",
    [
        ({"reward": {"distance": {"weight": -1.0}}}, r"task\.reward\.distance\.weight must be a number >= 0"),
        ({"reward": {"distance": {"wieght": 1.0}}}, r"task\.reward\.distance: unknown key\(s\) \['wieght'\]"),
        (
            {"reward": {"mine": {"weight": 1.0, "func": "footsim.nowhere:f"}}},
            r"task\.reward\.mine\.func .* cannot be imported",
        ),
        ({"terminations": {"stuck": None}}, r"task\.terminations: unknown term 'stuck'"),
        ({"fall_threshold": 2.0}, r"task\.fall_threshold must be in \(0, pi/2\)"),
        ({"collision_ends_episode": "yes"}, r"task\.collision_ends_episode must be true, false or null"),
    ],
)
def test_bad_terms_are_named(task, message):
    with pytest.raises(ValueError, match=message):
        fconf.build_task({"name": "nav", **task})


def test_a_backend_config_with_a_task_rule_is_refused():
    with pytest.raises(ValueError, match=r"backend\.fall_threshold is a task rule: set task\.fall_threshold"):
        FootstepEnv(backend={"name": "pymunk", "fall_threshold": 0.5})
