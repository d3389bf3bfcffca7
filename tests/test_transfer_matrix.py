"""footsim-transfer-matrix: a tiny pymunk × mujoco matrix (train + evaluate), then the runs= reuse path."""

import csv
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

from footsim.rl import transfer_matrix  # noqa: E402
from footsim.tools import transfer_matrix as transfer_matrix_tool  # noqa: E402

TINY = [
    "train.total_timesteps=64",
    "train.n_envs=2",
    "agent.n_steps=32",
    "agent.batch_size=32",
    "agent.n_epochs=1",
    "train.progress_bar=false",
    "train.tensorboard=false",
    "train.vec_env=dummy",
    "task.max_steps=4",
]


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_transfer_matrix_trains_evaluates_and_reuses_runs(tmp_path):
    out = tmp_path / "matrix"
    transfer_matrix_tool.main([f"out={out}", "backends=pymunk,mujoco", "n_scenes=2", *TINY])
    rows = _rows(out / "matrix.csv")
    assert {(r["train_backend"], r["eval_backend"]) for r in rows} == {
        ("pymunk", "pymunk"),
        ("pymunk", "mujoco"),
        ("mujoco", "pymunk"),
        ("mujoco", "mujoco"),
    }
    assert len(rows) == 4 and all(r["randomization"] == "none" and r["episodes"] == "2" for r in rows)
    for r in rows:
        assert sum(float(r[k]) for k in ("success", "timeout", "fall", "collision", "sim_error")) == pytest.approx(1.0)
    for name in ("heatmap_success.png", "heatmap_success_time.png", "matrix.md", "scenes.json"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "train" / "0" / "model.zip").is_file() and (out / "train" / "1" / "model.zip").is_file()

    # reuse the trained runs: no training, the same scene file, both randomization presets, one eval backend
    again = tmp_path / "again"
    transfer_matrix_tool.main(
        [
            f"out={again}",
            f"runs={out / 'train'}",
            f"scenes={out / 'scenes.json'}",
            "eval_backends=pymunk",
            "randomization=none,default",
        ]
    )
    rows2 = _rows(again / "matrix.csv")
    assert not (again / "train").exists()
    assert {(r["train_backend"], r["eval_backend"], r["randomization"]) for r in rows2} == {
        ("pymunk", "pymunk", "none"),
        ("mujoco", "pymunk", "none"),
        ("pymunk", "pymunk", "default"),
        ("mujoco", "pymunk", "default"),
    }
    same = {r["train_backend"]: r for r in rows if r["eval_backend"] == "pymunk"}
    for r in rows2:  # deterministic policy, same scenes, no randomization: the same numbers
        if r["randomization"] == "none":
            assert r["timeout"] == same[r["train_backend"]]["timeout"]
    assert (again / "heatmap_success.png").is_file()

    # the same matrix in 2 scene shards (two processes sharing out=): the second writes the matrix
    sharded = tmp_path / "sharded"
    args = [f"out={sharded}", f"runs={out / 'train'}", f"scenes={out / 'scenes.json'}", "eval_backends=pymunk"]
    transfer_matrix_tool.main([*args, "randomization=none,default", "shard=1/2"])
    assert not (sharded / "matrix.csv").exists()  # every cell waits for shard 0/2
    transfer_matrix_tool.main([*args, "randomization=none,default", "shard=0/2"])
    drop = ("eval_dir",)
    assert [{k: v for k, v in r.items() if k not in drop} for r in _rows(sharded / "matrix.csv")] == [
        {k: v for k, v in r.items() if k not in drop} for r in rows2
    ]
    for r in rows2:
        cell = sharded / Path(r["eval_dir"]).relative_to(again)
        assert (cell / "episodes.csv").read_bytes() == (Path(r["eval_dir"]) / "episodes.csv").read_bytes()


def test_arguments(tmp_path):
    cfg, overrides = transfer_matrix_tool.parse_args(
        ["backends=[pymunk,pybullet]", "randomization=none,default", "n_scenes=7", "seed=3", "train.total_timesteps=10"]
    )
    assert overrides == ["seed=3", "train.total_timesteps=10"]  # seed is footsim-train's
    assert cfg["backends"] == ["pymunk", "pybullet"] and cfg["randomization"] == ["none", "default"]
    assert cfg["n_scenes"] == 7
    cmd = transfer_matrix.train_command(cfg["backends"], overrides, "/x", "local", False)
    assert "-m" in cmd and "+launcher=local" in cmd and "backend=pymunk,pybullet" in cmd
    assert "eval.after_train=false" in cmd and cmd[-1] == "hydra.sweep.dir=/x"
    with pytest.raises(SystemExit, match="runs= reuses"):
        transfer_matrix_tool.parse_args(["runs=/tmp", "train.total_timesteps=5"])
    with pytest.raises(SystemExit, match="give runs=DIR and out=DIR"):
        transfer_matrix_tool.parse_args(["shard=0/2"])
    with pytest.raises(SystemExit, match="shard must be K/N"):
        transfer_matrix_tool.parse_args(["runs=/tmp", "out=/tmp/o", "shard=2/2"])
    with pytest.raises(SystemExit, match="no trained run"):
        transfer_matrix.transfer_matrix(
            {**transfer_matrix_tool.parse_args([])[0], "runs": str(tmp_path), "out": str(tmp_path / "o")}, []
        )
