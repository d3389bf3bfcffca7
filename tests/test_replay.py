"""Failed-scene replay (footsim.rl.replay): which scenes are kept, replayed and dropped."""

import numpy as np
import pytest

from footsim import config as fconf
from footsim.env import FootstepEnv
from footsim.rl.common import validate_train_config
from footsim.rl.replay import FailedSceneReplay


def _episode(env, action):
    """Reset and repeat ``action`` until the episode ends; returns (scene, outcome)."""
    env.reset()
    while True:
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            return env.unwrapped.scene, info["outcome"]


def test_failed_scenes_are_kept_replayed_and_dropped_once_mastered():
    standing = np.zeros(6)  # stepping in place never reaches a goal: every episode times out
    env = FailedSceneReplay(FootstepEnv(task={"max_steps": 3}), prob=1.0, capacity=2, seed=0)
    env.unwrapped.reset(seed=1)
    first, outcome = _episode(env.env, standing)  # through the wrapper's inner env: nothing kept
    assert outcome == "timeout" and not env.failed
    failed, _ = _episode(env, standing)  # buffer empty: a fresh scene, failed and kept
    assert failed != first and list(env.failed) == [failed]
    again, _ = _episode(env, standing)  # prob 1: the failed scene comes back (and is not kept twice)
    assert again == failed and list(env.failed) == [failed]
    env.prob = 0.0
    fresh = [_episode(env, standing)[0] for _ in range(2)]  # capacity 2: the oldest is dropped
    assert list(env.failed) == fresh and failed not in env.failed

    # a replayed scene that ends in success leaves the buffer: a goal at the start pose, reached by
    # the first double step in place
    env.prob = 1.0
    target = fresh[0]
    near = type(target)(goal=type(target.goal)(0.0, 0.0, 0.0))
    env.failed[0] = near
    while True:
        scene, outcome = _episode(env, standing)
        if scene == near:
            break
    assert outcome == "success" and near not in env.failed


def test_replay_is_off_by_default_and_bad_values_name_the_key():
    cfg = fconf.compose("config", [])
    assert cfg.train.replay.prob == 0.0
    for override, message in (
        ("train.replay.prob=1.5", r"train\.replay\.prob must be a number in \[0, 1\], got 1\.5"),
        ("train.replay.capacity=0", r"train\.replay\.capacity must be a positive integer, got 0"),
    ):
        with pytest.raises(ValueError, match=message):
            validate_train_config(fconf.compose("config", [override]))
