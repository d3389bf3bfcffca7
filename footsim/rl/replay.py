"""Failed-scene replay for training (``train.replay.prob``): practice where the policy fails.

Every training env keeps the scenes of its episodes that did not end in success (up to
``capacity``, the oldest dropped first).  At each reset it replays one of them, drawn uniformly,
with probability ``prob``, and otherwise samples a fresh scene as usual; a replayed scene that
ends in success leaves the buffer.  This is a simple form of prioritized level replay (Jiang et
al., 2021): the scene distribution tilts toward the hard tail (e.g. obstacles crowding the goal)
without changing what is evaluated, which always uses the task's own sampler.  Off (``prob: 0``)
by default, so a run trains on the thesis's scene distribution.
"""

from __future__ import annotations

from collections import deque

import gymnasium as gym
import numpy as np


def check_replay(prob, capacity) -> None:
    """Fail naming the key on a ``train.replay`` that cannot work."""
    if isinstance(prob, bool) or not (isinstance(prob, (int, float)) and 0.0 <= prob <= 1.0):
        raise ValueError(f"train.replay.prob must be a number in [0, 1], got {prob!r}")
    if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity <= 0:
        raise ValueError(f"train.replay.capacity must be a positive integer, got {capacity!r}")


class FailedSceneReplay(gym.Wrapper):
    """Replays a :class:`footsim.env.FootstepEnv`'s failed scenes with probability ``prob`` at reset."""

    def __init__(self, env: gym.Env, prob: float, capacity: int, seed: int):
        super().__init__(env)
        check_replay(prob, capacity)
        self.prob = float(prob)
        self.failed: deque = deque(maxlen=capacity)
        self.rng = np.random.default_rng(seed)
        self._replayed = None  # the scene of this episode when it is a replay

    def reset(self, *, seed=None, options=None):
        self._replayed = None
        if self.failed and not (options and "scene" in options) and self.rng.random() < self.prob:
            self._replayed = self.failed[int(self.rng.integers(len(self.failed)))]
            options = {**(options or {}), "scene": self._replayed}
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            scene = self.env.unwrapped.scene
            if info.get("outcome") == "success":
                if self._replayed is not None and self._replayed in self.failed:
                    self.failed.remove(self._replayed)  # mastered
            elif self._replayed is None:
                self.failed.append(scene)
        return obs, reward, terminated, truncated, info
