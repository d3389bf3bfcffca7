"""``footsim-bench [what=env2d,walk] [repeats=5] [steps=20000]``: speed benchmarks.

Prints markdown tables (medians over ``repeats``) for ``docs/BENCHMARKS.md``.  Each
benchmark runs in this process on one core; nothing here belongs in a unit test.
"""

from __future__ import annotations

import platform
import statistics
import sys
import time

import numpy as np


def _machine() -> str:
    import os

    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def bench_env2d(steps: int = 20000, repeats: int = 5) -> list[dict]:
    """2D env steps/s with random actions (episodes reset as they end), without and with rays."""
    from footsim.env import FootstepEnv

    rows = []
    for label, kwargs in (("pymunk, nav (17-D, no rays)", {}), ("pymunk, nav_obstacles (53-D, 36 rays)", {"obstacles": True})):
        env = FootstepEnv(**kwargs)
        rates = []
        for r in range(repeats):
            rng = np.random.default_rng(r)
            actions = rng.uniform(-1, 1, size=(steps, 6))
            env.reset(seed=r)
            start = time.perf_counter()
            for a in actions:
                _, _, terminated, truncated, _ = env.step(a)
                if terminated or truncated:
                    env.reset()
            rates.append(steps / (time.perf_counter() - start))
        rows.append({"benchmark": label, "median env steps/s": statistics.median(rates),
                     "min": min(rates), "max": max(rates)})
    return rows


def bench_walk(repeats: int = 5) -> list[dict]:
    from footsim.walk.bench import bench_walk as walk

    result = walk(repeats=repeats)
    return [{"benchmark": "quintic walk + leg IK, one double step at 500 Hz", **result}]


BENCHMARKS = {"env2d": bench_env2d, "walk": bench_walk}


def _table(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in row.values()) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    from footsim.tasks.scenes import parse_kv_args

    args = parse_kv_args(sys.argv[1:] if argv is None else argv,
                         {"what": "env2d,walk", "repeats": "5", "steps": "20000"}, "footsim-bench")
    names = [n for n in args["what"].split(",") if n]
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        raise SystemExit(f"footsim-bench: unknown benchmark(s) {unknown}; valid: {sorted(BENCHMARKS)}")
    repeats = int(args["repeats"])
    print(f"machine: {_machine()}; repeats: {repeats} (median reported)\n")
    for name in names:
        kwargs = {"repeats": repeats}
        if name == "env2d":
            kwargs["steps"] = int(args["steps"])
        try:
            rows = BENCHMARKS[name](**kwargs)
        except ImportError as err:
            print(f"{name}: skipped ({err})\n")
            continue
        print(_table(rows) + "\n")
