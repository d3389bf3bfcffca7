"""Evaluation shards: ``footsim-eval shard=K/N`` jobs merged give the single-process evaluation,
episode for episode; a missing shard is named and can be re-run alone."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import pytest
from budgets import tiny_training

from footsim.rl.evaluate import Shard

TINY_TRAIN = tiny_training(256, "eval.after_train=false")


def run(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run([*args], capture_output=True, text=True, timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"{args} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


def _rows(path: Path) -> list[dict]:
    return list(csv.DictReader(path.open()))


@pytest.mark.parametrize("text", ["3/3", "-1/2", "1", "a/b", "1/0", "1/2/3"])
def test_shard_rejects_bad_values(text):
    with pytest.raises(ValueError, match="shard must be K/N"):
        Shard.parse(text)


def test_shards_cover_every_scene_once_in_order():
    assert [list(Shard.parse(f"{k}/3").scenes(10)) for k in range(3)] == [[0, 1, 2], [3, 4, 5], [6, 7, 8, 9]]
    assert [list(Shard(k, 4).scenes(4)) for k in range(4)] == [[0], [1], [2], [3]]
    with pytest.raises(ValueError, match="5 shards for 4 scenes"):
        Shard(0, 5).scenes(4)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("train") / "run"
    run("footsim-train", *TINY_TRAIN, f"hydra.run.dir={path}")
    return path


@pytest.mark.slow
def test_three_shards_merge_to_the_single_run_and_a_lost_shard_is_rerun_alone(run_dir, tmp_path):
    # localization noise and footstep randomization: every episode draws from its own seeded RNGs
    common = [f"run={run_dir}", "n_scenes=7", "noise=localization", "randomization=default", "plot=false"]
    single = tmp_path / "single"
    run("footsim-eval", *common, f"hydra.run.dir={single}")
    sharded = tmp_path / "sharded"  # a multirun: the shards share its sweep dir
    proc = run("footsim-eval", "-m", *common, "shard=0/3,1/3,2/3", f"hydra.sweep.dir={sharded}")
    assert "1 of 3 shards missing" in proc.stdout  # after shard 1/3, before 2/3
    assert sorted(p.name for p in (sharded / "shards").iterdir()) == ["0-of-3.json", "1-of-3.json", "2-of-3.json"]
    expected = _rows(single / "episodes.csv")
    assert [r["scene"] for r in expected] == [str(i) for i in range(7)]
    assert _rows(sharded / "episodes.csv") == expected  # row by row, every column
    assert (sharded / "episodes.csv").read_bytes() == (single / "episodes.csv").read_bytes()
    assert json.loads((sharded / "summary.json").read_text()) == json.loads((single / "summary.json").read_text())

    # a failed shard: its file is absent; merge names it and keeps what is written
    (sharded / "shards" / "1-of-3.json").unlink()
    merged_before = (sharded / "episodes.csv").read_bytes()
    proc = run("footsim-eval", f"merge={sharded}", check=False)
    assert proc.returncode != 0
    assert "1 of 3 shards missing" in proc.stderr and "1/3 (scenes 2..3)" in proc.stderr, proc.stderr
    assert (sharded / "episodes.csv").read_bytes() == merged_before
    # re-run that shard alone into the same directory: the merge happens again, same result
    proc = run("footsim-eval", *common, "shard=1/3", f"hydra.run.dir={sharded}")
    assert f"results in {sharded}" in proc.stdout
    assert (sharded / "episodes.csv").read_bytes() == (single / "episodes.csv").read_bytes()
    run("footsim-eval", f"merge={sharded}")  # explicit merge of complete shards: the same files
    assert (sharded / "episodes.csv").read_bytes() == (single / "episodes.csv").read_bytes()

    # a shard of another evaluation (other seed) in the same directory is refused, by file name
    run("footsim-eval", *common, "shard=1/3", "seed=5", f"hydra.run.dir={tmp_path / 'other'}")
    (tmp_path / "other" / "shards" / "1-of-3.json").replace(sharded / "shards" / "1-of-3.json")
    proc = run("footsim-eval", f"merge={sharded}", check=False)
    assert proc.returncode != 0 and "shards of different evaluations" in proc.stderr and "1-of-3.json" in proc.stderr


@pytest.mark.slow
def test_baseline_shards_merge_to_the_single_run(tmp_path):
    common = ["controller=velocity", "n_scenes=5", "randomization=default", "plot=false"]
    single, sharded = tmp_path / "single", tmp_path / "sharded"
    run("footsim-eval", *common, f"hydra.run.dir={single}")
    for k in (1, 0):  # separate jobs, any order, one directory
        run("footsim-eval", *common, f"shard={k}/2", f"hydra.run.dir={sharded}")
    expected, merged = _rows(single / "episodes.csv"), _rows(sharded / "episodes.csv")
    assert len(merged) == 5 and list(merged[0]) == list(expected[0])
    for a, b in zip(merged, expected):  # planning wall times differ between any two runs
        assert {k: v for k, v in a.items() if "_ms" not in k} == {k: v for k, v in b.items() if "_ms" not in k}
    assert json.loads((sharded / "summary.json").read_text()) == json.loads((single / "summary.json").read_text())
    assert (sharded / "config_used.json").read_text() == (single / "config_used.json").read_text()


@pytest.mark.slow
def test_a_stochastic_policy_sharded_gives_the_single_run(run_dir, tmp_path):
    """deterministic=false: each episode samples its actions from torch seeded with its own seed, so
    a shard's episodes do not depend on the episodes another shard ran before them."""
    common = [f"run={run_dir}", "n_scenes=4", "deterministic=false", "plot=false"]
    single, sharded = tmp_path / "single", tmp_path / "sharded"
    run("footsim-eval", *common, f"hydra.run.dir={single}")
    run("footsim-eval", *common, "shard=1/2", f"hydra.run.dir={sharded}")
    run("footsim-eval", *common, "shard=0/2", f"hydra.run.dir={sharded}")
    assert (sharded / "episodes.csv").read_bytes() == (single / "episodes.csv").read_bytes()
