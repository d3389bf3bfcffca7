"""``footsim.bench.physics3d``: the replay times exactly the env's physics ticks."""

import numpy as np
import pytest

from footsim.bench.physics3d import PATTERN, bench_backend
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.walk.footsteps import DoubleStep


def test_replay_covers_every_env_tick():
    pytest.importorskip("mujoco")
    from footsim.calibration.walkcheck import make_backend

    repeats = 3
    out = bench_backend("mujoco", repeats=repeats)
    assert not out["fell"]
    assert out["env_steps_per_s"] > 0 and out["physics_steps_per_s"] > 0 and out["rss_mb"] > 0
    ticks = round(out["physics_ticks_per_s"] * repeats / out["physics_steps_per_s"])
    # Independent count: the durations the env reports for the same double steps (the phase reset
    # may end a step before the engine's planned end).
    backend = make_backend("mujoco")
    try:
        backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
        expected = (
            sum(
                round(
                    backend.execute(
                        DoubleStep.from_action(PATTERN[i % len(PATTERN)], backend.robot.step_limits)
                    ).duration_s
                    / backend.control_dt
                )
                for i in range(repeats)
            )
            * backend.substeps
        )
    finally:
        backend.close()
    assert ticks == expected
    assert np.isclose(out["ratio"], out["physics_steps_per_s"] / out["env_steps_per_s"])
