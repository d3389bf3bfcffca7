"""Policy selection on validation scenes (``train.select``): the schedule, the choice, the installed model."""

import csv
import json
import subprocess
import zipfile

import pytest
from budgets import tiny_training
from omegaconf import OmegaConf

from footsim.rl.selection import _better, validate_select


def _cfg(**select):
    return OmegaConf.create({"train": {"select": select}, "eval": {"scenes": None, "scenes_seed": 20220101}})


def test_the_better_policy_succeeds_more_then_falls_and_collides_less_then_came_first():
    a = {"success": 0.80, "fall": 0.10, "collision": 0.05}
    assert _better(a, None)
    assert _better({"success": 0.81, "fall": 0.19, "collision": 0.0}, a)  # success first
    assert _better({"success": 0.80, "fall": 0.05, "collision": 0.05}, a)  # then fewer unsafe endings
    assert not _better(dict(a), a)  # a tie keeps the earlier policy
    assert not _better({"success": 0.79, "fall": 0.0, "collision": 0.0}, a)


@pytest.mark.parametrize(
    "select,message",
    [
        ({"every": -1, "n_scenes": 10, "scenes_seed": 7}, "train.select.every must be a non-negative integer"),
        ({"every": 100, "n_scenes": 0, "scenes_seed": 7}, "train.select.n_scenes must be positive"),
        ({"every": 100, "n_scenes": 10, "scenes_seed": 20220101}, "is eval.scenes_seed"),
    ],
)
def test_a_select_section_that_cannot_work_fails_naming_the_key(select, message):
    with pytest.raises(ValueError, match=message):
        validate_select(_cfg(**select))


def test_selection_off_accepts_any_validation_seed():
    validate_select(_cfg(every=0, n_scenes=10, scenes_seed=20220101))


def _weights(path):
    with zipfile.ZipFile(path) as z:
        return z.read("policy.pth")


@pytest.mark.slow
def test_the_run_keeps_its_best_validated_policy_and_an_independent_evaluation_agrees(tmp_path):
    run_dir = tmp_path / "run"
    overrides = tiny_training(
        768, "task=nav_obstacles", "train.select.every=256", "train.select.n_scenes=6", "train.select.scenes_seed=7"
    )
    proc = subprocess.run(
        ["footsim-train", *overrides, "eval.after_train=false", f"hydra.run.dir={run_dir}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    with open(run_dir / "selection.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # 2 envs, every 256 env steps: validations at 256, 512 and 768; the final policy (768) is not run twice
    assert [int(r["num_timesteps"]) for r in rows] == [256, 512, 768]

    def key(row):
        return (float(row["success"]), -(float(row["fall"]) + float(row["collision"])))

    best_by_hand = max(rows, key=key)  # max returns the first of equal keys: the earlier policy
    assert [int(r["best"]) for r in rows].count(1) >= 1 and best_by_hand["best"] == "1"
    selected = json.loads((run_dir / "train_info.json").read_text())["selected"]
    assert selected["num_timesteps"] == int(best_by_hand["num_timesteps"])
    assert _weights(run_dir / "model.zip") == _weights(run_dir / "checkpoints" / "best" / "model.zip")
    if selected["num_timesteps"] != 768:
        assert _weights(run_dir / "model.zip") != _weights(run_dir / "checkpoints" / "latest.zip")
    # the 768 row scored the final policy (after the last update), the one the last checkpoint holds
    final = run_dir / "checkpoints" / ("best" if rows[-1]["best"] == "1" else "candidate") / "model.zip"
    assert _weights(final) == _weights(run_dir / "checkpoints" / "latest.zip")

    # footsim-eval on the validation scenes reproduces the figure the selection recorded
    out = tmp_path / "eval"
    proc = subprocess.run(
        ["footsim-eval", f"run={run_dir}", "n_scenes=6", "scenes_seed=7", "plot=false", f"hydra.run.dir={out}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    for metric in ("success", "fall", "collision", "timeout"):
        assert summary[metric] == pytest.approx(float(best_by_hand[metric])), metric


def test_a_resumed_run_keeps_its_validations_best_and_schedule(tmp_path):
    from types import SimpleNamespace

    from footsim.rl.selection import Selector, make_selection_callback

    (tmp_path / "checkpoints" / "best").mkdir(parents=True)
    (tmp_path / "selection.csv").write_text(
        "num_timesteps,success,fall,collision,timeout,success_time_mean,best\n"
        "20000,0.8,0.2,0.0,0.0,10.0,1\n30000,0.7,0.3,0.0,0.0,10.0,0\n"
    )
    best = {"num_timesteps": 20000, "success": 0.8, "fall": 0.2, "collision": 0.0, "timeout": 0.0}
    (tmp_path / "checkpoints" / "best" / "best.json").write_text(json.dumps(best))
    selector = Selector(OmegaConf.create({}), tmp_path, {"every": 20000, "n_scenes": 5, "scenes_seed": 7})
    assert selector.validated_steps == {20000, 30000} and selector.best == best
    validated = []
    selector.validate = lambda model: validated.append(model.num_timesteps)  # no env: the schedule only
    callback = make_selection_callback(selector)
    callback.model = SimpleNamespace(num_timesteps=30002)  # resumed at 30 002 steps
    callback._on_training_start()
    for steps in (30002, 39998, 40000, 40002, 59998, 60000):  # the step counts at rollout starts
        callback.model.num_timesteps = steps
        callback._on_rollout_start()
    assert validated == [40000, 60000]  # the next multiples of 20 000, as the interrupted run would have


def test_validation_and_the_evaluation_after_training_can_take_another_noise(tmp_path):
    """train.select.noise and eval.noise judge a run under a noise preset other than its training one
    (e.g. trained under a wider noise, reported under the thesis's); a bad preset fails naming the key."""
    from footsim import config as fconf
    from footsim.rl.common import under_noise, validate_train_config
    from footsim.rl.selection import Selector

    cfg = fconf.compose("config", ["noise=localization", "train.select.noise=none", "eval.noise=localization_odometry"])
    validate_train_config(cfg)
    selector = Selector(cfg, tmp_path, {"every": 1, "n_scenes": 2, "scenes_seed": 7})
    try:
        env, _ = selector._env_and_scenes()
        assert not env.noise.active  # validated without noise, trained with it
    finally:
        selector.close()
    judged = under_noise(cfg, cfg.eval.noise)
    assert judged.noise.name == "localization_odometry" and judged.noise.odometry_weight == 0.6
    assert cfg.noise.name == "localization" and under_noise(cfg, None) is cfg  # the run's own config untouched
    for key in ("eval.noise", "train.select.noise"):
        bad = fconf.compose("config", [f"{key}=bogus"])
        with pytest.raises(ValueError, match=rf"{key}: unknown noise preset 'bogus'"):
            validate_train_config(bad)

    run_dir = tmp_path / "run"
    overrides = tiny_training(256, "noise=localization", "eval.noise=none", "eval.n_scenes=2", "eval.plot=false")
    proc = subprocess.run(
        ["footsim-train", *overrides, f"hydra.run.dir={run_dir}"], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert (
        "| policy (pymunk, nav, noise=none) |" in proc.stdout
        and OmegaConf.load(run_dir / "config.yaml").noise.name == "localization"
    )


@pytest.mark.slow
def test_validating_during_training_leaves_the_training_unchanged(tmp_path):
    """The same seed with and without train.select ends in the same weights: validating a candidate
    draws nothing from the training's random streams."""

    def train(name, *extra):
        run_dir = tmp_path / name
        overrides = tiny_training(512, "eval.after_train=false", *extra)
        proc = subprocess.run(
            ["footsim-train", *overrides, f"hydra.run.dir={run_dir}"], capture_output=True, text=True, timeout=600
        )
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        return _weights(run_dir / "checkpoints" / "latest.zip")

    plain = train("plain")
    selected = train("selected", "train.select.every=128", "train.select.n_scenes=3", "train.select.scenes_seed=7")
    assert selected == plain
