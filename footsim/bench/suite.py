"""The benchmark table of ``footsim-bench``: each benchmark's name to a function returning rows of
a markdown table (medians over ``repeats``), plus the machine line and the table format.

Each benchmark runs in this process on one core, except the scaling ones (``ppo_mujoco``,
``eval_shards_mujoco``: :mod:`footsim.bench.scaling`), which start the command lines as
processes.  Rates are given per CPU second of this process
(robust on a busy machine) and per wall second; the scaling ones in wall time only.  Nothing here
belongs in a unit test.
"""

from __future__ import annotations

import os
import platform
import statistics
from collections.abc import Callable
from typing import Any

from footsim.bench.env2d import bench_env2d
from footsim.bench.physics3d import bench_backend
from footsim.bench.planners import bench_planners
from footsim.bench.scaling import bench_eval_shards, bench_ppo
from footsim.bench.walk import bench_walk


def machine() -> str:
    """Processor, core count and Python version, for the header of a benchmark report."""
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def _walk(repeats: int = 5) -> list[dict]:
    return [{"benchmark": "quintic walk + leg IK, one double step at 500 Hz", **bench_walk(repeats=repeats)}]


def _bench_3d(name: str) -> Callable[..., list[dict]]:
    def run(repeats: int = 5) -> list[dict]:
        """Env double steps/s vs raw physics for the same ticks, their ratio, RSS (median of runs)."""
        runs = [bench_backend(name, repeats=20, seed=r) for r in range(repeats)]
        keys = [k for k, v in runs[0].items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
        row: dict[str, Any] = {"backend": name}
        row.update({k: statistics.median(r[k] for r in runs) for k in keys if k != "repeats"})
        row["fell"] = any(r.get("fell") for r in runs)
        return [row]

    return run


def _planners(repeats: int = 5) -> list[dict]:
    return bench_planners()


BENCHMARKS: dict[str, Callable[..., list[dict]]] = {
    "env2d": bench_env2d,
    "walk": _walk,
    "mujoco": _bench_3d("mujoco"),
    "dm_control": _bench_3d("dm_control"),
    "pybullet": _bench_3d("pybullet"),
    "planners": _planners,
    # wall-clock scaling over processes (footsim.bench.scaling): one run each, `repeats` ignored
    "ppo_mujoco": lambda repeats=1: bench_ppo("mujoco"),
    "eval_shards_mujoco": lambda repeats=1: bench_eval_shards("mujoco"),
}


def table(rows: list[dict]) -> str:
    """``rows`` (dicts with the same keys) as a markdown table, floats to 4 significant digits."""
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in row.values()) + " |")
    return "\n".join(lines)
