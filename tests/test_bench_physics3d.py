"""``footsim.bench.physics3d``: the replay times exactly the env's physics ticks."""

import numpy as np
import pytest

from footsim.bench.physics3d import PATTERN, bench_backend
from footsim.walk.footsteps import DoubleStep


def test_replay_covers_every_env_tick():
    pytest.importorskip("mujoco")
    from footsim.calibration.walkcheck import make_backend

    repeats = 3
    out = bench_backend("mujoco", repeats=repeats)
    assert not out["fell"]
    assert out["env_steps_per_s"] > 0 and out["physics_steps_per_s"] > 0 and out["rss_mb"] > 0
    ticks = round(out["physics_ticks_per_s"] * repeats / out["physics_steps_per_s"])
    # Independent count: the walk engine's trajectory lengths for the same double steps.
    backend = make_backend("mujoco")
    try:
        expected = (
            sum(
                len(
                    backend.engine.double_step(
                        DoubleStep.from_action(PATTERN[i % len(PATTERN)], backend.robot.step_limits)
                    ).joint_targets
                )
                for i in range(repeats)
            )
            * backend.substeps
        )
    finally:
        backend.close()
    assert ticks == expected
    assert np.isclose(out["ratio"], out["physics_steps_per_s"] / out["env_steps_per_s"])
