"""Cross-backend transfer matrix (``footsim-transfer-matrix``, :mod:`footsim.tools.transfer_matrix`).

1. Trains one policy per backend with a Hydra multirun of ``footsim-train``
   (``footsim-train -m backend=a,b <train overrides> hydra.sweep.dir=OUT/train``), or reuses the
   run directories below ``runs=DIR`` (any directory holding ``config.yaml`` and ``model.zip``).
2. Evaluates every policy on every evaluation backend, on one scene file (``scenes=FILE``, or
   ``n_scenes`` drawn with the task's sampler and written to ``OUT/scenes.json``), once per
   evaluation randomization preset (``randomization=none,default``).  A cell whose
   ``summary.json`` already exists is not evaluated again (re-running the command resumes).
   With ``shard=K/N`` (and ``runs=``) this process evaluates scene shard K of every cell
   (:class:`footsim.rl.evaluate.Shard`); N such processes, on any machines sharing OUT, fill
   the cells, and the one that completes the last cell writes the outputs.
3. Writes ``OUT/matrix.csv`` (one row per policy × eval backend × randomization), ``matrix.md``
   and the heatmaps ``heatmap_success.png`` and ``heatmap_success_time.png`` (mean over the
   policies trained on the same backend; one panel per randomization preset), all atomically.

The command's own keys and defaults are in ``conf/transfer_matrix.yaml``; every other
``key=value`` goes to ``footsim-train`` unchanged (``train.total_timesteps=200000 seed=1``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from footsim import config as fconf
from footsim.rl.common import CONFIG_FILE, MODEL_FILE, SUMMARY_METRICS, load_run_config
from footsim.rl.evaluate import Shard, evaluate_run, merge_shards, walk_on_backend
from footsim.tasks.scenes import sample_scenes, save_scenes
from footsim.utils import atomic_save, atomic_write_text

COLUMNS = ("train_backend", "eval_backend", "randomization", *SUMMARY_METRICS, "run", "eval_dir")


# -- 1. training --------------------------------------------------------------------------------
def train_command(
    backends: list[str], overrides: list[str], sweep_dir: Path, launcher: str | None, train_eval: bool
) -> list[str]:
    cmd = [sys.executable, "-c", "from footsim.tools.train import main; main()", "-m"]
    if launcher:
        cmd.append(f"+launcher={launcher}")
    cmd.append(f"backend={','.join(backends)}")
    if not train_eval and not any(o.startswith("eval.after_train=") for o in overrides):
        cmd.append("eval.after_train=false")
    return [*cmd, *overrides, f"hydra.sweep.dir={sweep_dir}"]


def train_policies(
    backends: list[str], overrides: list[str], sweep_dir: Path, launcher: str | None, train_eval: bool
) -> None:
    cmd = train_command(backends, overrides, sweep_dir, launcher, train_eval)
    print("training:", " ".join(cmd[3:]), flush=True)
    proc = subprocess.run(cmd)
    if proc.returncode != 0:  # some jobs may still have finished: the matrix uses what exists
        print(
            f"footsim-transfer-matrix: footsim-train exited with {proc.returncode}; using the runs that finished",
            file=sys.stderr,
        )


def find_runs(root: Path) -> list[Path]:
    """Run directories (config.yaml + model.zip) below ``root`` (or ``root`` itself), in job order."""

    root = Path(root)
    found = {
        p.parent
        for p in root.rglob(MODEL_FILE)
        if (p.parent / CONFIG_FILE).is_file() and "checkpoints" not in p.parent.parts[len(root.parts) :]
    }

    def key(p: Path):
        rel = p.relative_to(root).parts
        return [(0, int(s)) if s.isdigit() else (1, s) for s in rel]

    return sorted(found, key=key)


# -- 2. evaluation ------------------------------------------------------------------------------
def scene_file(cfg: dict, run_cfg, out: Path) -> Path:
    if cfg["scenes"]:
        return Path(cfg["scenes"]).expanduser().resolve()
    path = out / "scenes.json"
    if not path.is_file():
        sampler, task = fconf.build_task(fconf.to_plain(run_cfg.task))
        n, seed = int(cfg["n_scenes"]), int(cfg["scenes_seed"])
        save_scenes(
            path,
            sample_scenes(sampler, n, seed),
            meta={"n": n, "seed": seed, "task": run_cfg.task.name, "obstacles": bool(task.obstacles)},
        )
    return path


def eval_config(run_cfg, eval_backend: str, randomization: str):
    """The run's config moved to ``eval_backend`` (with that backend's walk unless it is the
    training backend) under the ``randomization`` preset — as ``footsim-eval backend=B randomization=R``."""

    cfg = OmegaConf.create(OmegaConf.to_container(run_cfg, resolve=True))
    OmegaConf.set_struct(cfg, False)
    if eval_backend != run_cfg.backend.name:
        cfg.backend = fconf.load_preset("backend", eval_backend)
        cfg.walk = walk_on_backend(run_cfg, eval_backend)[0]
    cfg.randomization = fconf.load_preset("randomization", randomization)
    return cfg


def evaluate_cell(
    run_dir: Path, run_cfg, eval_backend: str, randomization: str, scenes: Path, cell_dir: Path, cfg: dict
) -> dict | None:
    """The cell's summary; None while a sharded cell waits for other shards."""
    summary_path = cell_dir / "summary.json"
    if summary_path.is_file():
        return json.loads(summary_path.read_text())
    shard = Shard.parse(cfg["shard"]) if cfg.get("shard") else None
    if shard is not None and shard.path(cell_dir).is_file():  # this shard is done: merge if the others are
        return merge_shards(cell_dir, plot=bool(cfg["plot"]), require_all=False)
    cfg_eval = OmegaConf.create(
        {
            "scenes": str(scenes),
            "deterministic": bool(cfg["deterministic"]),
            "seed": int(cfg["eval_seed"]),
            "plot": bool(cfg["plot"]),
            "video": False,
            "shard": None if shard is None else shard.name,
        }
    )
    label = f"{run_cfg.backend.name} -> {eval_backend} (randomization={randomization})"
    summary = evaluate_run(eval_config(run_cfg, eval_backend, randomization), run_dir, cell_dir, cfg_eval, label=label)
    return summary if shard is None or summary_path.is_file() else None


def _row(cell: tuple, summary: dict | None) -> dict:
    run, run_cfg, eval_backend, randomization, cell_dir = cell
    summary = summary or {}
    return {
        "train_backend": run_cfg.backend.name,
        "eval_backend": eval_backend,
        "randomization": randomization,
        **{k: summary.get(k) for k in SUMMARY_METRICS},
        "run": str(run),
        "eval_dir": str(cell_dir),
    }


# -- 3. outputs ---------------------------------------------------------------------------------
def _fmt(v) -> str:
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.6g}"
    return "" if v is None else str(v)


def write_csv(path: Path, rows: list[dict]) -> None:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(COLUMNS), extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _fmt(row.get(k)) for k in COLUMNS})
    atomic_write_text(path, buffer.getvalue())


def aggregate(rows: list[dict], metric: str, randomization: str, train: list[str], evals: list[str]):
    """Matrix [train backend, eval backend] of ``metric``, mean over runs (NaN where none)."""

    m = np.full((len(train), len(evals)), np.nan)
    for i, tb in enumerate(train):
        for j, eb in enumerate(evals):
            vals = [
                float(r[metric])
                for r in rows
                if r["train_backend"] == tb
                and r["eval_backend"] == eb
                and r["randomization"] == randomization
                and r.get(metric) is not None
                and not math.isnan(float(r[metric]))
            ]
            if vals:
                m[i, j] = float(np.mean(vals))
    return m


def markdown(rows: list[dict], train: list[str], evals: list[str], randomizations: list[str]) -> str:
    lines = []
    for rand in randomizations:
        succ = aggregate(rows, "success", rand, train, evals)
        stime = aggregate(rows, "success_time_mean", rand, train, evals)
        lines += [
            f"### randomization={rand}: success (mean success time [s])",
            "",
            "| train \\ eval | " + " | ".join(evals) + " |",
            "|---|" + "---|" * len(evals),
        ]
        for i, tb in enumerate(train):
            cells = [
                ("–" if math.isnan(succ[i, j]) else f"{succ[i, j]:.2f}")
                + ("" if math.isnan(stime[i, j]) else f" ({stime[i, j]:.1f})")
                for j in range(len(evals))
            ]
            lines.append(f"| {tb} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def plot_heatmap(
    path: Path,
    rows: list[dict],
    metric: str,
    title: str,
    train: list[str],
    evals: list[str],
    randomizations: list[str],
    fmt: str,
    vmin=None,
    vmax=None,
    cmap="viridis",
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(randomizations)
    fig, axes = plt.subplots(
        1, n, figsize=(1.2 + 1.6 * len(evals) * n + 1.0 * n, 1.0 + 1.0 * len(train) + 0.8), squeeze=False
    )
    for ax, rand in zip(axes[0], randomizations):
        m = aggregate(rows, metric, rand, train, evals)
        shown = np.ma.masked_invalid(m)
        image = ax.imshow(shown, cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto")
        for i in range(len(train)):
            for j in range(len(evals)):
                text = "n/a" if math.isnan(m[i, j]) else format(m[i, j], fmt)
                ax.text(
                    j,
                    i,
                    text,
                    ha="center",
                    va="center",
                    fontsize=10,
                    bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0},
                )
        ax.set_xticks(range(len(evals)), evals)
        ax.set_yticks(range(len(train)), train)
        ax.set_xlabel("evaluated on")
        ax.set_ylabel("trained on")
        ax.set_title(f"randomization={rand}", fontsize=9)
        fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    atomic_save(lambda tmp: fig.savefig(tmp, dpi=110, format="png"), path, ".png")
    plt.close(fig)


def write_outputs(out: Path, rows: list[dict], train: list[str], evals: list[str], randomizations: list[str]) -> str:
    write_csv(out / "matrix.csv", rows)
    table = markdown(rows, train, evals, randomizations)
    atomic_write_text(out / "matrix.md", table + "\n")
    plot_heatmap(
        out / "heatmap_success.png",
        rows,
        "success",
        "success rate (rows: trained on, columns: evaluated on)",
        train,
        evals,
        randomizations,
        ".2f",
        vmin=0.0,
        vmax=1.0,
    )
    plot_heatmap(
        out / "heatmap_success_time.png",
        rows,
        "success_time_mean",
        "mean success time [s]",
        train,
        evals,
        randomizations,
        ".1f",
        cmap="viridis_r",
    )
    return table


# -- driver -------------------------------------------------------------------------------------
def transfer_matrix(cfg: dict, train_overrides: list[str]) -> list[dict]:
    out = Path(cfg["out"] or time.strftime("outputs/transfer_matrix/%Y-%m-%d/%H-%M-%S")).expanduser().resolve()
    out.mkdir(parents=True, exist_ok=True)
    if cfg["runs"]:
        runs_root = Path(cfg["runs"]).expanduser().resolve()
        if not runs_root.is_dir():
            raise SystemExit(f"footsim-transfer-matrix: runs={runs_root} is not a directory")
    else:
        runs_root = out / "train"
        train_policies(list(cfg["backends"]), train_overrides, runs_root, cfg["launcher"], bool(cfg["train_eval"]))
    runs = find_runs(runs_root)
    if not runs:
        raise SystemExit(f"footsim-transfer-matrix: no trained run (config.yaml + model.zip) below {runs_root}")
    configs = {run: load_run_config(run) for run in runs}
    train_backends = list(dict.fromkeys(c.backend.name for c in configs.values()))
    evals = list(cfg["eval_backends"] or cfg["backends"] or train_backends)
    tasks = {c.task.name for c in configs.values()}
    if len(tasks) > 1:
        print(f"note: the runs were trained on different tasks {sorted(tasks)}; all are evaluated on one scene file")
    scenes = scene_file(cfg, configs[runs[0]], out)
    print(
        f"{len(runs)} {'policy' if len(runs) == 1 else 'policies'} (trained on {', '.join(train_backends)}) "
        f"x eval backends {evals} x randomization "
        f"{cfg['randomization']}; scenes: {scenes}",
        flush=True,
    )

    cells, rows = [], []
    for run in runs:
        run_cfg = configs[run]
        name = run.relative_to(runs_root).as_posix() if run != runs_root else run.name
        for eval_backend in evals:
            for rand in cfg["randomization"]:
                cell_dir = out / "eval" / f"{name.replace('/', '_')}_{run_cfg.backend.name}" / f"{eval_backend}_{rand}"
                cell = (run, run_cfg, eval_backend, rand, cell_dir)
                cells.append(cell)
                summary = evaluate_cell(run, run_cfg, eval_backend, rand, scenes, cell_dir, cfg)
                if not cfg.get("shard"):
                    rows.append(_row(cell, summary))
                    write_csv(out / "matrix.csv", rows)  # partial results survive an interruption
    if cfg.get("shard"):
        # every cell again: other shard processes may have completed cells meanwhile; only the
        # process that finds every cell complete writes the outputs
        summaries = [evaluate_cell(run, rc, eb, rand, scenes, cell_dir, cfg) for run, rc, eb, rand, cell_dir in cells]
        waiting = [str(cell[-1]) for cell, summary in zip(cells, summaries) if summary is None]
        if waiting:
            print(
                f"shard {cfg['shard']} of every cell done; {len(waiting)} of {len(cells)} cells wait for other "
                f"shards ({', '.join(waiting)}); the process completing the last of them writes the matrix"
            )
            return []
        rows = [_row(cell, summary) for cell, summary in zip(cells, summaries)]
        write_csv(out / "matrix.csv", rows)
    table = write_outputs(out, rows, train_backends, evals, list(cfg["randomization"]))
    print(table)
    print(f"transfer matrix in {out} (matrix.csv, matrix.md, heatmap_success.png, heatmap_success_time.png)")
    return rows
