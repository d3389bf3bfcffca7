"""Calibrated 2D: fitting the execution model, the 2D backend applying it, bad files."""

import json

import numpy as np
import pytest

from footsim.calibration import execution_model as calibrate
from footsim.calibration.execution_model import FEATURES, ExecutionModel
from footsim.calibration.walkcheck import make_backend, run_sequence, standard_sequences


def _model(coef, intercept=(0, 0, 0), std=(0, 0, 0), fall=None, names=("dx", "dy", "dtheta")):
    return {
        "format": calibrate.FORMAT,
        "version": calibrate.VERSION,
        "features": list(names),
        "outputs": ["dx", "dy", "dtheta"],
        "coef": np.asarray(coef, float).tolist(),
        "intercept": list(intercept),
        "residual_std": list(std),
        "fall": fall,
    }


def test_fit_recovers_a_known_linear_model_and_fall_logistic():
    rng = np.random.default_rng(0)
    n = 4000
    predicted = rng.uniform([-0.3, -0.15, -1.5], [0.3, 0.15, 1.5], (n, 3))
    coef = rng.normal(0, 0.3, (3, len(FEATURES))) + np.hstack([np.eye(3) * 0.8, np.zeros((3, 3))])
    intercept = np.array([0.01, -0.02, 0.03])
    sigma = np.array([0.01, 0.005, 0.02])
    executed = calibrate.features(predicted) @ coef.T + intercept + rng.normal(0, 1, (n, 3)) * sigma
    action = rng.uniform(-1, 1, (n, 6))
    w_true, b_true = np.array([0.5, 0.2, 1.0, 0.5, 0.2, 1.0]), -3.0
    p = 1 / (1 + np.exp(-(np.abs(action) @ w_true + b_true)))
    fell = rng.random(n) < p
    executed[fell] = np.nan
    model = calibrate.fit(
        {"action": action, "predicted": predicted, "executed": executed, "fell": fell.astype(float)}, names=FEATURES
    )
    np.testing.assert_allclose(model["coef"], coef, atol=0.02)
    np.testing.assert_allclose(model["intercept"], intercept, atol=0.01)
    np.testing.assert_allclose(model["residual_std"], sigma, rtol=0.1)
    assert model["n_falls"] == int(fell.sum()) and model["fall"] is not None
    np.testing.assert_allclose(model["fall"]["coef"], w_true, atol=0.4)
    assert model["fall"]["intercept"] == pytest.approx(b_true, abs=0.5)
    loaded = ExecutionModel(json.loads(json.dumps(model)), noise=False)  # the payload round-trips
    np.testing.assert_allclose(
        loaded.mean(predicted[0]), calibrate.features(predicted[0]) @ coef.T + intercept, atol=0.02
    )


def _forward(backend, n=10):
    seq = standard_sequences()[0]  # forward max
    return run_sequence(backend, type(seq)(seq.name, seq.actions[:n], seq.measure))


def test_pymunk_applies_the_execution_model(tmp_path):
    path = tmp_path / "half.json"
    path.write_text(json.dumps(_model(np.diag([0.5, 1.0, 1.0]))))
    plain = _forward(make_backend("pymunk"))
    from footsim import config as fconf

    walk = fconf.build_walk(fconf.load_preset("walk", "pymunk"))
    robot = fconf.build_robot("wolfgang")
    cfg = fconf.load_preset("backend", {"name": "pymunk", "execution_model": str(path)})
    calibrated = _forward(fconf.build_backend(cfg, robot, walk))
    assert calibrated["displacement"][0] == pytest.approx(0.5 * plain["displacement"][0], rel=1e-6)
    assert calibrated["displacement"][1] == pytest.approx(plain["displacement"][1], abs=1e-9)
    # residual noise comes from the episode rng: reproducible per seed, different across seeds
    path.write_text(json.dumps(_model(np.eye(3), std=(0.02, 0.02, 0.05))))
    noisy = fconf.build_backend(cfg, robot, walk)
    a, b = _forward(noisy)["pose"], _forward(noisy)["pose"]
    assert a == b and a != plain["pose"]
    # the fall model ends the walk when enabled
    path.write_text(json.dumps(_model(np.eye(3), fall={"coef": [0] * 6, "intercept": 50.0})))
    falls = fconf.build_backend({**cfg, "execution_falls": True}, robot, walk)
    assert _forward(falls)["fell"] and not _forward(fconf.build_backend(cfg, robot, walk))["fell"]


def test_env_with_execution_model(tmp_path):
    import gymnasium as gym

    import footsim  # noqa: F401

    path = tmp_path / "m.json"
    path.write_text(json.dumps(_model(np.diag([0.5, 1.0, 1.0]))))
    env = gym.make("footsim/FootstepNav-v1", backend={"name": "pymunk", "execution_model": str(path)})
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([1, 0, 0, 1, 0, 0], dtype=np.float32))
    assert 0.0 < info["pose"][0] < 0.2
    env.close()


@pytest.mark.parametrize(
    "content, message",
    [
        ("{not json", "not valid JSON"),
        (json.dumps({"coef": [[1, 0, 0]] * 3}), "not a footsim execution model"),
        (json.dumps({**_model(np.eye(3)), "coef": [[1, 0], [0, 1]]}), "coef must be 3 x 3"),
        (json.dumps({**_model(np.eye(3)), "features": ["dx", "dy", "speed"]}), "unknown features"),
        (json.dumps({**_model(np.eye(3)), "residual_std": [-1, 0, 0]}), "residual_std >= 0"),
    ],
)
def test_bad_execution_model_files_fail_clearly(tmp_path, content, message):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(ValueError, match=message):
        ExecutionModel.load(path)
    from footsim import config as fconf

    with pytest.raises(ValueError, match=message):
        fconf.build_backend(
            {"name": "pymunk", "execution_model": str(path)},
            fconf.build_robot("wolfgang"),
            fconf.build_walk(fconf.load_preset("walk", "pymunk")),
        )
    with pytest.raises(FileNotFoundError, match="execution model file not found"):
        ExecutionModel.load(tmp_path / "missing.json")
