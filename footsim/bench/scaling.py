"""Scaling on one machine: PPO steps/s with 1 … N env workers, and one evaluation as 1 … N scene
shards run side by side (``footsim-bench what=ppo_mujoco,eval_shards_mujoco``).

Both run the real command lines (``footsim-train``, ``footsim-eval shard=K/N``) as subprocesses,
so the figures include what a user's job pays (process start, model build, imports).  They are
wall-clock rates: parallel workers only help when idle cores exist, so run them on a quiet
machine; on a loaded one the rows measure the load.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _run(argv: list[str]) -> None:
    done = subprocess.run(argv, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr[-2000:]}")


def _tool(name: str) -> list[str]:
    """A footsim command line run by this interpreter (no reliance on PATH)."""
    module = {"footsim-train": "footsim.tools.train", "footsim-eval": "footsim.tools.evaluate"}[name]
    return [sys.executable, "-c", f"import sys; from {module} import main; sys.argv[0] = {name!r}; main()"]


def bench_ppo(backend: str = "mujoco", workers: tuple[int, ...] = (1, 2), steps: int = 4096) -> list[dict]:
    """One ``footsim-train`` of ``steps`` env steps per worker count (the agent's defaults: ``agent.n_steps``
    per worker and rollout): PPO steps/s over the learning loop (``train_info.json``: rollouts and
    updates, not the process start) and the command's wall time."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="footsim-bench-ppo-") as tmp:
        for n in workers:
            run_dir = Path(tmp) / f"n{n}"
            start = time.perf_counter()
            _run(
                _tool("footsim-train")
                + [
                    f"backend={backend}",
                    f"train.total_timesteps={steps}",
                    f"train.n_envs={n}",
                    "train.progress_bar=false",
                    "train.tensorboard=false",
                    "eval.after_train=false",
                    f"hydra.run.dir={run_dir}",
                ]
            )
            wall = time.perf_counter() - start
            info = json.loads((run_dir / "train_info.json").read_text())
            rows.append(
                {
                    "backend": backend,
                    "env workers": n,
                    "PPO steps": int(info["num_timesteps"]),
                    "PPO steps/s (learning loop)": float(info["steps_per_s"]),
                    "command wall [s]": wall,
                }
            )
    return rows


def bench_eval_shards(
    backend: str = "mujoco", shard_counts: tuple[int, ...] = (1, 2), n_scenes: int = 500, controller: str = "velocity"
) -> list[dict]:
    """One ``n_scenes`` evaluation of a baseline (no trained policy needed) as N shard processes
    started together, then merged (``merge=DIR``): the wall time from the first start to the merged result."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="footsim-bench-shards-") as tmp:
        for n in shard_counts:
            out = Path(tmp) / f"shards{n}"
            common = [f"controller={controller}", f"backend={backend}", f"n_scenes={n_scenes}", "plot=false"]
            start = time.perf_counter()
            procs = [
                subprocess.Popen(
                    _tool("footsim-eval") + common + [f"shard={k}/{n}", f"hydra.run.dir={out}"],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE,
                    text=True,
                )
                for k in range(n)
            ]
            for k, proc in enumerate(procs):
                _, err = proc.communicate()
                if proc.returncode != 0:
                    raise RuntimeError(f"shard {k}/{n} failed ({proc.returncode}):\n{err[-2000:]}")
            _run(_tool("footsim-eval") + [f"merge={out}", "plot=false", f"hydra.run.dir={out}/merge_log"])
            wall = time.perf_counter() - start
            summary = json.loads((out / "summary.json").read_text())
            rows.append(
                {
                    "backend": backend,
                    "controller": controller,
                    "shards (processes)": n,
                    "episodes": int(summary["episodes"]),
                    "success": float(summary["success"]),
                    "wall [s]": wall,
                }
            )
    return rows
