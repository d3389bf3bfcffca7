"""The calibrated 2D backend's fall model from a capability map (``backend.fall_model=PATH``)."""

import json
import math

import numpy as np
import pytest

from footsim.calibration.execution_model import CapabilityFallModel
from footsim.calibration.walkcheck import make_backend
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.walk.footsteps import DoubleStep

HEADER = (
    "right_x,right_y,right_theta,left_x,left_y,left_theta,fall_rate,n,falls,sim_errors,warmup_failures,landed,"
    "position_error_mean,position_error_max,yaw_error_mean,yaw_error_max"
)


def _row(action, falls, n=10):
    """A capability.csv row written by hand: the cell's unit action, its trials and falls."""
    landed = n - falls
    return ",".join(map(str, [*action, falls / n, n, falls, 0, 0, landed, 0.01, 0.02, 0.01, 0.02]))


#: x levels -1, 0, 1 of a same-step map (y = θ = 0), fall rates 1.0, 0.0 and 0.3
TINY = {
    (-1.0, 0, 0, -1.0, 0, 0): (10, 10),
    (0.0, 0, 0, 0.0, 0, 0): (0, 10),
    (1.0, 0, 0, 1.0, 0, 0): (3, 10),
}


@pytest.fixture
def tiny_map(tmp_path):
    path = tmp_path / "capability.csv"
    lines = [HEADER] + [_row(action, falls, n) for action, (falls, n) in TINY.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def _backend(path, **overrides):
    return make_backend("pymunk", backend_overrides={"fall_model": str(path), **overrides})


def _falls(backend, action, episodes, seed=0):
    """How many one-step episodes of ``action`` fell (fresh rng per episode, as the env seeds them)."""
    limits = backend.robot.step_limits
    fell = 0
    for k in range(episodes):
        backend.reset(Scene(goal=Pose2D(5.0, 0.0, 0.0)), np.random.default_rng([seed, k]))
        result = backend.execute(DoubleStep.from_action(np.asarray(action, float), limits))
        fell += result.max_tilt > 0.7  # the task's default fall threshold
    return fell


def test_nearest_cell_lookup(tiny_map):
    model = CapabilityFallModel.load(tiny_map)
    assert model.fall_rates.tolist() == [1.0, 0.0, 0.3]
    # squared distances by hand: to x=-1: (1.6² + 1.2²) = 4.0, to x=0: 0.36 + 0.04 = 0.40, to x=1: 0.16 + 0.64 = 0.80
    assert model.cell_index([0.6, 0, 0, 0.2, 0, 0]) == 1
    assert model.cell_index([0.9, 0, 0, 0.5, 0, 0]) == 2  # 0.01 + 0.25 = 0.26 < 0.81 + 0.25
    assert model.cell_index([-0.7, 0.3, 0.1, -0.4, 0, 0]) == 0
    assert model.probability([-0.7, 0.3, 0.1, -0.4, 0, 0]) == 1.0
    # exactly between two cells (mean x 0.5): the cell written first wins
    assert model.cell_index([0.5, 0, 0, 0.5, 0, 0]) == 1
    # the directory holding capability.csv is accepted too
    assert CapabilityFallModel.load(tiny_map.parent).fall_rates.tolist() == [1.0, 0.0, 0.3]


def test_fall_frequency_matches_the_cell_rate(tiny_map):
    n, p = 2000, 0.3
    falls = _falls(_backend(tiny_map), [1, 0, 0, 1, 0, 0], n)
    # binomial(2000, 0.3): mean 600, σ = sqrt(2000 · 0.3 · 0.7) = 20.5; 5σ bound
    assert abs(falls - n * p) < 5 * math.sqrt(n * p * (1 - p))
    # a step nearest the x = 1 cell falls just as often (mean x 0.8 → the x = 1 cell)
    falls = _falls(_backend(tiny_map), [1.0, 0, 0, 0.6, 0, 0], n, seed=1)
    assert abs(falls - n * p) < 5 * math.sqrt(n * p * (1 - p))


def test_rate_zero_never_falls_rate_one_always(tiny_map):
    backend = _backend(tiny_map)
    assert _falls(backend, [0, 0, 0, 0, 0, 0], 2000) == 0
    assert _falls(backend, [0.3, 0, 0, -0.3, 0, 0], 500) == 0  # mean x 0: the rate-0 cell
    assert _falls(backend, [-1, 0, 0, -1, 0, 0], 200) == 200


def test_fall_draws_are_reproducible_per_seed(tiny_map):
    backend = _backend(tiny_map)
    limits = backend.robot.step_limits

    def sequence(seed):
        backend.reset(Scene(goal=Pose2D(5.0, 0.0, 0.0)), np.random.default_rng(seed))
        step = DoubleStep.from_action(np.array([1.0, 0, 0, 1.0, 0, 0]), limits)
        return [backend.execute(step).max_tilt > 0 for _ in range(40)]

    a, b, c = sequence(7), sequence(7), sequence(8)
    assert a == b and a != c and 0 < sum(a) < 40


def test_env_reports_the_fall_and_the_map_works_with_an_execution_model(tiny_map, tmp_path):
    import gymnasium as gym

    import footsim  # noqa: F401
    from footsim.calibration import execution_model as em

    model = tmp_path / "model.json"
    model.write_text(
        json.dumps(
            {
                "format": em.FORMAT,
                "version": em.VERSION,
                "features": ["dx", "dy", "dtheta"],
                "outputs": ["dx", "dy", "dtheta"],
                "coef": np.eye(3).tolist(),
                "intercept": [0, 0, 0],
                "residual_std": [0.01, 0.01, 0.01],
                "fall": None,
            }
        )
    )
    for backend in (
        {"name": "pymunk", "fall_model": str(tiny_map)},
        {"name": "pymunk", "fall_model": str(tiny_map), "execution_model": str(model)},
    ):
        env = gym.make("footsim/FootstepNav-v1", backend=backend)
        env.reset(seed=0)
        _, _, terminated, _, info = env.step(np.array([-1, 0, 0, -1, 0, 0], dtype=np.float32))  # rate 1
        assert terminated and info["outcome"] == "fall"
        env.reset(seed=0)
        for _ in range(20):  # rate 0: walking in place never falls
            _, _, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
            assert info["outcome"] != "fall"
            if terminated or truncated:
                break
        env.close()


def test_off_by_default():
    assert make_backend("pymunk").fall_model is None


def test_bad_fall_model_input(tiny_map, tmp_path):
    with pytest.raises(FileNotFoundError, match="no capability map"):
        _backend(tmp_path / "missing.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("right_x,fall_rate\n0,0\n")
    with pytest.raises(ValueError, match="missing column"):
        _backend(bad)
    empty = tmp_path / "empty.csv"
    empty.write_text(HEADER + "\n")
    with pytest.raises(ValueError, match="no cells"):
        _backend(empty)
    out_of_range = tmp_path / "range.csv"
    out_of_range.write_text(HEADER + "\n" + _row((0, 0, 0, 0, 0, 0), 15, n=10) + "\n")  # 15 falls in 10 trials
    with pytest.raises(ValueError, match=r"fall_rate of cell .* is 1.5"):
        _backend(out_of_range)
    no_trials = tmp_path / "none.csv"
    zero_trials = _row((0, 0, 0, 0, 0, 0), 0, n=1).replace(",1,0,0,0,1,", ",0,0,0,0,0,", 1)  # n = 0: rate NaN
    no_trials.write_text(HEADER + "\n" + zero_trials + "\n")
    with pytest.raises(ValueError, match="without trials"):
        _backend(no_trials)
    with pytest.raises(ValueError, match="execution_falls"):
        _backend(tiny_map, execution_falls=True)
