"""footsim-walktune: the walk objective task composes and measures; a 2-trial Optuna sweep completes."""

import importlib.util
import json
import math
import subprocess

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from footsim.config import conf_dir

needs_pybullet = pytest.mark.skipif(importlib.util.find_spec("pybullet") is None, reason="pybullet not installed")
needs_optuna = pytest.mark.skipif(
    importlib.util.find_spec("optuna") is None, reason="optuna not installed (pip install 'footsim[hpo]')"
)

# one level, 1 measured double step, left only: about a second of CPU
TINY = ["tune.levels=[0.5]", "tune.warmup=0", "tune.measure=1", "tune.symmetric=false", "tune.stand_time=0.2"]


def _compose(*overrides, hydra=False):
    with initialize_config_dir(str(conf_dir()), version_base="1.3"):
        return compose("walktune", overrides=list(overrides), return_hydra_config=hydra)


def test_walktune_composes_the_backends_walk_and_the_hpo_presets():
    cfg = _compose("backend=pybullet")
    mujoco_walk = OmegaConf.load(conf_dir() / "walk" / "bitbots_sim.yaml")
    # conf/walk/pybullet.yaml is `defaults: [mujoco, _self_]`, mujoco.yaml `defaults: [bitbots_sim, _self_]`:
    # Hydra must compose MuJoCo's gait
    assert cfg.backend.name == "pybullet" and cfg.walk.trunk_height == mujoco_walk.trunk_height == 0.394780002666927
    assert cfg.walk.freq == mujoco_walk.freq and "defaults" not in cfg.walk
    for backend in ("pybullet", "mujoco", "dm_control"):
        cfg = _compose(f"+hpo=walk_{backend}", hydra=True)
        assert cfg.backend.name == backend
        sweeper = cfg.hydra.sweeper
        assert sweeper._target_.endswith("FootsimOptunaSweeper") and sweeper.direction == "maximize"
        assert sweeper.sampler._target_ == "optuna.samplers.TPESampler" and sweeper.n_jobs == 1
        assert sweeper.study_name == f"walk_{backend}" and sweeper.storage.startswith("sqlite:///")
        assert sweeper.params["walk.trunk_height"] == "interval(0.34, 0.43)"
        assert sweeper.params["walk.freq"] == "interval(1.0, 3.0)" and len(sweeper.params) == 13
        assert all(key[len("walk.") :] in cfg.walk for key in sweeper.params)  # every searched key is a walk key


@needs_pybullet
def test_walktune_returns_a_finite_objective_on_pybullet(tmp_path):
    from footsim.calibration.walktune import WEIGHTS, run

    cfg = _compose("backend=pybullet", *TINY)
    result = run(cfg, tmp_path)
    assert result["stands"] and math.isfinite(result["objective"])
    assert result["objective"] == pytest.approx(sum(WEIGHTS[t] * result[t] for t in WEIGHTS))
    # forward at half the step limit commands 2 * freq * 0.5 * 0.156 m/s (0.128 m/s at 0.82 Hz); one
    # measured double step right after the start step covers at least 30 % of it
    commanded = 2 * cfg.walk.freq * 0.5 * 0.156
    assert result["v_forward"] > 0.3 * commanded
    saved = json.loads((tmp_path / "walktune.json").read_text())
    assert saved["objective"] == result["objective"] and set(saved["directions"]) == {
        "forward",
        "backward",
        "left",
        "turn_left",
    }
    # a walk the backend rejects (feet overlapping when turning) scores 0, it does not crash the trial
    bad = run(_compose("backend=pybullet", "walk.foot_distance=0.12", *TINY))
    assert bad["objective"] == 0.0 and not bad["stands"] and "foot_distance" in bad["invalid"]


def test_walktune_rejects_the_2d_backend():
    from footsim.calibration.walktune import run

    with pytest.raises(ValueError, match="needs a 3D backend"):
        run(_compose("backend=pymunk"))


@pytest.mark.slow
@needs_pybullet
@needs_optuna
def test_two_trial_walk_sweep_completes(tmp_path):
    import optuna

    from footsim.calibration.walktune import enqueue_walk

    sweep = tmp_path / "hpo"
    storage = f"sqlite:///{sweep / 'optuna.db'}"
    enqueue_walk(storage, "walk_pybullet", "pybullet")  # trial 0 = the current preset
    proc = subprocess.run(
        [
            "footsim-walktune",
            "-m",
            "+hpo=walk_pybullet",
            "backend=pybullet",
            *TINY,
            "hydra.sweeper.n_trials=2",
            f"hydra.sweep.dir={sweep}",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    trials = optuna.load_study(study_name="walk_pybullet", storage=storage).trials
    assert [t.state.name for t in trials] == ["COMPLETE", "COMPLETE"]
    assert (
        trials[0].params["walk.freq"] == pytest.approx(_compose("backend=pybullet").walk.freq) and trials[0].value > 0
    )  # the enqueued preset
    for t in trials:
        assert math.isfinite(t.value) and t.user_attrs["objective"] == pytest.approx(t.value)  # walktune.json
        assert (sweep / str(t.number) / "walktune.json").is_file()
    assert "best_params" in (sweep / "optimization_results.yaml").read_text()
