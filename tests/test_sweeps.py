"""Hydra sweeps: local multirun with a crashing job, sweep summary, launcher presets, Optuna HPO."""

import csv
import importlib.util
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from budgets import tiny_training
from hydra import compose, initialize_config_dir

from footsim.config import conf_dir
from footsim.rl import sweeps
from footsim.tools import sweep_summary

TINY = tiny_training(256, "eval.n_scenes=3", "eval.plot=false")


def run(*args, cwd=None, timeout=300):
    return subprocess.run([*args], capture_output=True, text=True, cwd=cwd, timeout=timeout)


def _fail_msg(proc):
    return f"rc={proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"


def _compose(*overrides):
    with initialize_config_dir(str(conf_dir()), version_base="1.3"):
        return compose("config", overrides=list(overrides), return_hydra_config=True)


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


# -- local multirun -------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.skipif(
    not _has("hydra_plugins.hydra_joblib_launcher"),
    reason="hydra-joblib-launcher not installed (pip install 'footsim[joblib]')",
)
def test_local_multirun_keeps_results_of_good_jobs_and_reports_the_crashed_ones(tmp_path):
    sweep = tmp_path / "sweep"
    # 4 jobs, 2 in parallel: seeds 0 and 1 train; agent.n_epochs=0 is invalid and crashes its 2 jobs
    proc = run(
        "footsim-train",
        "-m",
        "+launcher=local",
        "hydra.launcher.n_jobs=2",
        *TINY,
        "seed=0,1",
        "agent.n_epochs=1,0",
        f"hydra.sweep.dir={sweep}",
    )
    assert proc.returncode != 0, "a crashed job must make the sweep exit non-zero"
    assert "agent.n_epochs must be a positive integer" in proc.stderr, _fail_msg(proc)
    assert "Joblib.Parallel" in proc.stdout + proc.stderr  # the local preset selects the joblib launcher

    for job in ("0", "1"):  # each good job's run dir is self-contained
        for name in ("config.yaml", "model.zip", "eval/summary.json", ".hydra/overrides.yaml"):
            assert (sweep / job / name).is_file(), (job, name, _fail_msg(proc))
        assert not (sweep / job / sweeps.FAILED_FILE).exists()
    for job in ("2", "3"):
        failed = json.loads((sweep / job / sweeps.FAILED_FILE).read_text())
        assert "agent.n_epochs must be a positive integer" in failed["error"] and "Traceback" in failed["traceback"]
        assert "agent.n_epochs=0" in failed["overrides"]
        assert not (sweep / job / "model.zip").exists()

    proc = run("footsim-sweep-summary", f"dir={sweep}")
    assert proc.returncode == 0, _fail_msg(proc)
    rows = list(csv.DictReader((sweep / "sweep_summary.csv").open()))
    assert [(r["job"], r["status"], r["seed"], r["agent.n_epochs"]) for r in rows] == [
        ("0", "ok", "0", "1"),
        ("1", "ok", "1", "1"),
        ("2", "failed", "0", "0"),
        ("3", "failed", "1", "0"),
    ]
    for r in rows[:2]:
        assert r["episodes"] == "3" and 0.0 <= float(r["success"]) <= 1.0
    assert "agent.n_epochs must be a positive integer" in rows[2]["error"]
    md = (sweep / "sweep_summary.md").read_text()
    assert "4 jobs, 2 ok, 2 failed" in md and "| 3 | failed | 0 | 1 |" in md
    assert md == proc.stdout.split("\nwrote ")[0]
    assert "job 2 failed" in proc.stderr


# -- summary on a synthetic sweep (fast) ------------------------------------------------------------
def _fake_job(root: Path, name: str, overrides: list[str], summary=None, failed=None, model=True):
    job = root / name
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    if summary is not None:
        (job / "eval").mkdir()
        (job / "eval" / "summary.json").write_text(json.dumps(summary))
    if failed is not None:
        (job / sweeps.FAILED_FILE).write_text(json.dumps({"error": failed}))
    if model:
        (job / "model.zip").write_text("x")


def test_summary_table_of_a_synthetic_sweep(tmp_path, capsys):
    _fake_job(
        tmp_path,
        "10",
        ["seed=2", "+experiment=thesis_2d"],
        {"episodes": 5, "success": 0.4, "label": "p", "success_time_mean": float("nan")},
    )
    _fake_job(tmp_path, "2", ["seed=1", "+experiment=thesis_2d"], {"episodes": 5, "success": 0.8, "extra": 1})
    _fake_job(tmp_path, "3", ["seed=3", "+experiment=thesis_2d"], failed="ValueError: bad | value")
    _fake_job(tmp_path, "4", ["seed=4", "+experiment=thesis_2d"], model=False)
    out = tmp_path / "report" / "table"
    (tmp_path / "report").mkdir()
    assert sweep_summary.main([f"dir={tmp_path}", f"out={out}"]) == 0
    rows = list(csv.DictReader(open(f"{out}.csv")))
    assert [r["job"] for r in rows] == ["2", "3", "4", "10"]  # numeric job order
    assert [r["status"] for r in rows] == ["ok", "failed", "no_eval", "ok"]
    assert rows[0]["success"] == "0.8" and rows[0]["extra"] == "1" and rows[3]["success_time_mean"] == "nan"
    assert rows[2]["error"] == "no eval/summary.json and no model.zip"
    assert list(rows[0])[:6] == ["job", "status", "seed", "experiment", "episodes", "success"]
    md = open(f"{out}.md").read()
    assert "Common overrides: `experiment=thesis_2d`" in md
    assert "| 3 | failed | 3 |" in md and "bad \\| value" in md  # pipes escaped
    assert "label" not in md
    assert "4 jobs, 2 ok, 2 failed or without evaluation" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv,message",
    [
        ([], "missing dir="),
        (["dir=/nonexistent/sweep"], "is not a directory"),
        (["directory=x"], "expected one of"),
        (["dir=a", "dir=b"], "given twice"),
    ],
)
def test_summary_cli_rejects_bad_arguments(argv, message, capsys):
    assert sweep_summary.main(argv) == 2
    assert message in capsys.readouterr().err


def test_summary_of_a_dir_without_jobs(tmp_path, capsys):
    assert sweep_summary.main([f"dir={tmp_path}"]) == 2
    assert "no Hydra jobs" in capsys.readouterr().err


# -- launcher presets: composing their configs ---------------------------------------------------------
def test_local_preset_composes():
    if not _has("hydra_plugins.hydra_joblib_launcher"):
        pytest.skip("hydra-joblib-launcher not installed (pip install 'footsim[joblib]')")
    cfg = _compose("+launcher=local")
    assert cfg.hydra.launcher._target_.endswith("JoblibLauncher") and cfg.train.progress_bar is False


def test_slurm_preset_composes():
    if not _has("hydra_plugins.hydra_submitit_launcher"):
        pytest.skip("hydra-submitit-launcher not installed (pip install 'footsim[slurm]')")
    cfg = _compose("+launcher=slurm", "train.n_envs=4", "hydra.launcher.partition=cpu")
    launcher = cfg.hydra.launcher
    assert launcher._target_.endswith("SlurmLauncher")
    assert launcher.cpus_per_task == 4 and launcher.partition == "cpu" and launcher.timeout_min == 240


def test_ray_preset_composes():
    if not _has("hydra_plugins.hydra_ray_launcher"):
        pytest.skip("hydra-ray-launcher not installed (pip install 'footsim[ray]')")
    cfg = _compose("+launcher=ray")
    assert cfg.hydra.launcher._target_.endswith("RayLauncher")
    assert cfg.hydra.launcher.ray.init.address is None and cfg.hydra.launcher.ray.remote.num_cpus == 1
    assert cfg.hydra.launcher.ray.init.object_store_memory is None  # ray.init refuses a size for an existing cluster


def test_experiment_presets_compose():
    cfg = _compose("+experiment=thesis_2d")
    assert (cfg.backend.name, cfg.task.name, cfg.train.total_timesteps, cfg.eval.n_scenes) == (
        "pymunk",
        "nav",
        1000000,
        500,
    )
    cfg = _compose("+experiment=thesis_2d_obstacles", "noise=localization")
    assert (cfg.task.name, cfg.noise.name) == ("nav_obstacles", "localization")
    cfg = _compose("+experiment=thesis_3d")
    assert (cfg.backend.name, cfg.hydra.runtime.choices.walk, cfg.task.name, cfg.noise.name) == (
        "mujoco",
        "mujoco",
        "nav",
        "none",
    )
    cfg = _compose("+experiment=thesis_3d", "backend=pybullet")  # the walk follows the backend
    assert (cfg.backend.name, cfg.hydra.runtime.choices.walk, cfg.walk.freq) == ("pybullet", "pybullet", 1.2)
    cfg = _compose("+experiment=footstepnav_v0")  # the old setup, by name
    assert (cfg.backend.name, cfg.backend.physics_dt, cfg.robot.name, cfg.walk.freq) == (
        "mujoco",
        0.01,
        "wolfgang_simplified",
        0.819559,
    )
    cfg = _compose("+experiment=dr_mujoco")
    assert (cfg.backend.name, cfg.hydra.runtime.choices.walk, cfg.noise.name, cfg.randomization.name) == (
        "mujoco",
        "mujoco",
        "localization",
        "default",
    )


# -- Optuna sweeper -----------------------------------------------------------------------------------
needs_optuna = pytest.mark.skipif(not _has("optuna"), reason="optuna not installed (pip install 'footsim[hpo]')")


@needs_optuna
def test_optuna_sweeper_is_registered_and_hpo_preset_composes():
    cfg = _compose("+hpo=ppo_2d")
    sweeper = cfg.hydra.sweeper
    assert sweeper._target_ == "hydra_plugins.footsim_optuna_sweeper.optuna_sweeper.FootsimOptunaSweeper"
    assert sweeper.sampler._target_ == "optuna.samplers.TPESampler" and sweeper.sampler.seed == 0
    assert sweeper.storage.startswith("sqlite:///") and sweeper.direction == "maximize"
    assert "agent.learning_rate" in sweeper.params


@needs_optuna
def test_search_space_syntax():
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

    from hydra_plugins.footsim_optuna_sweeper._impl import format_value, split_arguments

    parser = OverridesParser.create()
    space, fixed = split_arguments(
        parser.parse_overrides(
            [
                "a=tag(log, interval(1e-5, 1e-3))",
                "b=interval(0, 10)",
                "c=range(3, 11)",
                "d=choice(relu, tanh)",
                "e=1,2",
                "f=range(0.1, 0.5, 0.1)",
                "g=tag(int, interval(1.0, 4.0))",
                "h=5",
                "b=7",
            ]
        )
    )
    assert space["a"] == FloatDistribution(1e-5, 1e-3, log=True)
    assert space["c"] == IntDistribution(3, 10)
    assert space["d"] == CategoricalDistribution(["relu", "tanh"]) and space["e"] == CategoricalDistribution([1, 2])
    assert (
        space["f"].low == pytest.approx(0.1)
        and space["f"].high == pytest.approx(0.4)
        and space["f"].step == pytest.approx(0.1)
    )
    assert space["g"] == IntDistribution(1, 4)
    assert fixed == {"h": "5", "b": "7"} and "b" not in space  # a later fixed value replaces the search
    assert format_value(1e-05) == "1e-05" and format_value(True) == "true" and format_value(None) == "null"
    with pytest.raises(ValueError, match="x: a log interval needs start > 0"):
        split_arguments(parser.parse_overrides(["x=tag(log, interval(0, 1))"]))
    with pytest.raises(ValueError, match="y: unknown tag"):
        split_arguments(parser.parse_overrides(["y=tag(foo, interval(0, 1))"]))


@needs_optuna
@pytest.mark.parametrize(
    "key,value,message",
    [
        ("direction", "up", "hydra.sweeper.direction"),
        ("n_trials", 0, "hydra.sweeper.n_trials must be a positive integer"),
        ("n_jobs", -1, "hydra.sweeper.n_jobs must be a positive integer"),
    ],
)
def test_sweeper_validates_its_config(key, value, message):
    from hydra_plugins.footsim_optuna_sweeper._impl import OptunaSweeperImpl

    with pytest.raises(ValueError, match=message):
        OptunaSweeperImpl(**{key: value})


TOY_APP = textwrap.dedent("""
    import math, hydra

    @hydra.main(config_path="conf", config_name="config", version_base="1.3")
    def main(cfg):
        if cfg.x > 4.5:
            raise RuntimeError("x too large")
        if cfg.x < -4.5:
            return None
        return -(cfg.x - 1.0) ** 2

    if __name__ == "__main__":
        main()
""")


def _toy(tmp_path):
    (tmp_path / "conf").mkdir()
    (tmp_path / "conf" / "config.yaml").write_text(
        textwrap.dedent("""
        defaults:
          - override hydra/sweeper: optuna
          - _self_
        x: 0.0
        hydra:
          sweep: {dir: sweep}
          sweeper:
            study_name: toy
            storage: sqlite:///sweep/toy.db
            n_jobs: 3
            sampler: {_target_: optuna.samplers.TPESampler, seed: 1, n_startup_trials: 5}
            params: {x: "interval(-5.0, 5.0)"}
    """)
    )
    (tmp_path / "app.py").write_text(TOY_APP)


def _trials(db, name="toy"):
    import optuna

    return optuna.load_study(study_name=name, storage=f"sqlite:///{db}").get_trials(deepcopy=False)


@pytest.mark.slow
@needs_optuna
def test_optuna_sweeper_on_a_toy_task_failures_and_resume(tmp_path):
    """Fast (no training): batches of 3, failing trials don't stop the study, resume adds trials."""
    _toy(tmp_path)
    proc = run(sys.executable, "app.py", "-m", "hydra.sweeper.n_trials=8", cwd=tmp_path)
    assert proc.returncode == 0, _fail_msg(proc)
    trials = _trials(tmp_path / "sweep" / "toy.db")
    assert len(trials) == 8 and all(t.state.name in ("COMPLETE", "FAIL") for t in trials)
    for t in trials:  # job dir == trial number; failures are the raising / None-returning x
        assert (tmp_path / "sweep" / str(t.number) / ".hydra" / "overrides.yaml").is_file()
        if t.params["x"] > 4.5:
            assert t.state.name == "FAIL" and "x too large" in t.user_attrs["error"]
        elif t.params["x"] < -4.5:
            assert t.state.name == "FAIL" and "returned None" in t.user_attrs["error"]
        else:
            assert t.state.name == "COMPLETE" and t.value == pytest.approx(-((t.params["x"] - 1) ** 2))
    results = (tmp_path / "sweep" / "optimization_results.yaml").read_text()
    assert "best_params" in results and "n_trials: 8" in results

    # the same command again: nothing to do; a larger budget adds trials, numbering continues
    assert run(sys.executable, "app.py", "-m", "hydra.sweeper.n_trials=8", cwd=tmp_path).returncode == 0
    assert len(_trials(tmp_path / "sweep" / "toy.db")) == 8
    proc = run(sys.executable, "app.py", "-m", "hydra.sweeper.n_trials=10", cwd=tmp_path)
    assert proc.returncode == 0, _fail_msg(proc)
    trials = _trials(tmp_path / "sweep" / "toy.db")
    assert [t.number for t in trials] == list(range(10))
    first_params = {t.params["x"] for t in trials[:8]}
    assert not {t.params["x"] for t in trials[8:]} & first_params  # resumed sampler does not repeat itself


@pytest.mark.slow
@needs_optuna
def test_optuna_sweeper_reruns_trials_left_running_by_a_killed_sweep(tmp_path):
    import optuna

    _toy(tmp_path)
    (tmp_path / "sweep").mkdir()
    storage = f"sqlite:///{tmp_path / 'sweep' / 'toy.db'}"
    study = optuna.create_study(study_name="toy", storage=storage, direction="maximize")
    done = study.ask({"x": optuna.distributions.FloatDistribution(-5, 5)})
    study.tell(done, -1.0)
    stale = study.ask({"x": optuna.distributions.FloatDistribution(-5, 5)})  # never told: the sweep was killed
    proc = run(sys.executable, "app.py", "-m", "hydra.sweeper.n_trials=3", "hydra.sweeper.n_jobs=1", cwd=tmp_path)
    assert proc.returncode == 0, _fail_msg(proc)
    trials = _trials(tmp_path / "sweep" / "toy.db")
    states = [t.state.name for t in trials]
    assert states[:2] == ["COMPLETE", "FAIL"] and states.count("COMPLETE") + states.count("FAIL") == len(trials)
    retry = [t for t in trials if t.user_attrs.get("retry_of") == stale.number]
    assert len(retry) == 1 and retry[0].params == stale.params  # same parameters, run again
    assert sum(t.state.name == "COMPLETE" or "error" in t.user_attrs for t in trials) == 3  # the budget


@needs_optuna
@pytest.mark.slow
def test_hpo_sweep_of_footsim_train_completes_and_resumes(tmp_path):
    import optuna

    sweep = tmp_path / "hpo"
    args = ["footsim-train", "-m", "+hpo=ppo_2d", *TINY, f"hydra.sweep.dir={sweep}"]
    proc = run(*args, "hydra.sweeper.n_trials=2", "hydra.sweeper.n_jobs=2")
    assert proc.returncode == 0, _fail_msg(proc)
    storage = f"sqlite:///{sweep / 'optuna.db'}"
    study = optuna.load_study(study_name="ppo_2d", storage=storage)
    assert [t.state.name for t in study.trials] == ["COMPLETE", "COMPLETE"]
    for t in study.trials:
        assert 0.0 <= t.value <= 1.0 and t.user_attrs["episodes"] == 3  # success rate; summary as user attrs
        assert "agent.learning_rate" in t.params and "agent.n_steps" not in t.params  # fixed on the command line
        assert (sweep / str(t.number) / "model.zip").is_file()
        assert (sweep / str(t.number) / "eval" / "summary.json").is_file()
    # resume: a larger budget adds a trial to the stored study instead of starting over
    proc = run(*args, "hydra.sweeper.n_trials=3", "hydra.sweeper.n_jobs=2")
    assert proc.returncode == 0, _fail_msg(proc)
    study = optuna.load_study(study_name="ppo_2d", storage=storage)
    assert [t.number for t in study.trials] == [0, 1, 2] and all(t.state.name == "COMPLETE" for t in study.trials)
    assert "2 of 3 trials finished" in proc.stdout + proc.stderr


# -- presets that extend another preset of their group --------------------------------------------
@pytest.mark.parametrize(
    "name, base", [("velocity_mujoco", "velocity"), ("velocity_v1", "velocity"), ("footstep_mujoco", "footstep")]
)
def test_group_defaults_match_hydra_composition(name, base):
    """``load_preset`` (used outside Hydra) must read a ``defaults: [base, _self_]`` preset the way
    Hydra composes it: the base's values with the file's overrides on top."""
    import yaml

    from footsim.config import load_preset

    ours = load_preset("controller", name)
    with initialize_config_dir(str(conf_dir()), version_base="1.3"):
        hydra_cfg = compose("eval", overrides=[f"controller={name}"])
    from omegaconf import OmegaConf

    assert ours == OmegaConf.to_container(hydra_cfg.controller, resolve=True)
    raw = yaml.safe_load((conf_dir() / "controller" / f"{name}.yaml").read_text())  # a parser other than ours
    overrides = {k: v for k, v in raw.items() if k != "defaults"}
    assert ours == {**load_preset("controller", base), **overrides} and "defaults" not in ours
