"""2D env speed: env steps/s with random actions, without and with rays (``footsim-bench what=env2d``)."""

from __future__ import annotations

import statistics
import time

import gymnasium as gym
import numpy as np

from footsim.env import FootstepEnv


def bench_env2d(steps: int = 20000, repeats: int = 5, wrapped: bool = False) -> list[dict]:
    """2D env steps/s with random actions (episodes reset as they end), without and with rays.

    Measures the raw ``FootstepEnv``; ``wrapped=True`` adds rows for the env built by
    ``gymnasium.make("footsim/FootstepNav-v1")`` (its passive checker and order-enforcing /
    episode-statistics wrappers run on every step)."""

    def make_raw(**kwargs):
        return FootstepEnv(**kwargs)

    def make_gym(**kwargs):
        return gym.make("footsim/FootstepNav-v1", **kwargs)

    variants = [("", make_raw)] + ([(" [gymnasium.make]", make_gym)] if wrapped else [])
    rows = []
    for suffix, make in variants:
        for label, kwargs in (
            ("pymunk, nav (17-D, no rays)", {}),
            ("pymunk, nav_obstacles (53-D, 36 rays)", {"obstacles": True}),
        ):
            env = make(**kwargs)
            rates = []
            for r in range(repeats):
                rng = np.random.default_rng(r)
                actions = rng.uniform(-1, 1, size=(steps, 6))
                env.reset(seed=r)
                start, start_cpu = time.perf_counter(), time.process_time()
                for a in actions:
                    _, _, terminated, truncated, _ = env.step(a)
                    if terminated or truncated:
                        env.reset()
                rates.append((steps / (time.process_time() - start_cpu), steps / (time.perf_counter() - start)))
            env.close()
            cpu = [r[0] for r in rates]
            rows.append(
                {
                    "benchmark": label + suffix,
                    "median env steps/s (CPU time)": statistics.median(cpu),
                    "min": min(cpu),
                    "max": max(cpu),
                    "median env steps/s (wall)": statistics.median(r[1] for r in rates),
                }
            )
    return rows
