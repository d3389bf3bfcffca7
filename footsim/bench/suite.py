"""``footsim-bench [what=env2d,walk,...] [repeats=5] [steps=20000] [wrapped=false]``: speed benchmarks.

Prints markdown tables (medians over ``repeats``) for ``docs/BENCHMARKS.md``.  Each
benchmark runs in this process on one core.  Rates are given per CPU second of this process
(robust on a busy machine) and per wall second.  Nothing here belongs in a unit test.
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


def bench_env2d(steps: int = 20000, repeats: int = 5, wrapped: bool = False) -> list[dict]:
    """2D env steps/s with random actions (episodes reset as they end), without and with rays.

    Measures the raw ``FootstepEnv``; ``wrapped=True`` adds rows for the env built by
    ``gymnasium.make("footsim/FootstepNav-v0")`` (its passive checker and order-enforcing /
    episode-statistics wrappers run on every step)."""
    from footsim.env import FootstepEnv

    def make_raw(**kwargs):
        return FootstepEnv(**kwargs)

    def make_gym(**kwargs):
        import gymnasium as gym

        import footsim  # noqa: F401  (registers the env)

        return gym.make("footsim/FootstepNav-v0", **kwargs)

    variants = [("", make_raw)] + ([(" [gymnasium.make]", make_gym)] if wrapped else [])
    rows = []
    for suffix, make in variants:
        for label, kwargs in (
            ("pymunk, nav (17-D, no rays)", {}),
            ("pymunk, nav_obstacles (53-D, 36 rays)", {"obstacles": True}),
        ):
            env = make(**kwargs)
            rates = []
            for r in range(repeats):
                rng = np.random.default_rng(r)
                actions = rng.uniform(-1, 1, size=(steps, 6))
                env.reset(seed=r)
                start, start_cpu = time.perf_counter(), time.process_time()
                for a in actions:
                    _, _, terminated, truncated, _ = env.step(a)
                    if terminated or truncated:
                        env.reset()
                rates.append((steps / (time.process_time() - start_cpu), steps / (time.perf_counter() - start)))
            env.close()
            cpu = [r[0] for r in rates]
            rows.append(
                {
                    "benchmark": label + suffix,
                    "median env steps/s (CPU time)": statistics.median(cpu),
                    "min": min(cpu),
                    "max": max(cpu),
                    "median env steps/s (wall)": statistics.median(r[1] for r in rates),
                }
            )
    return rows


def bench_walk(repeats: int = 5) -> list[dict]:
    from footsim.walk.bench import bench_walk as walk

    result = walk(repeats=repeats)
    return [{"benchmark": "quintic walk + leg IK, one double step at 500 Hz", **result}]


def _bench_3d(name: str):
    def run(repeats: int = 5) -> list[dict]:
        """Env double steps/s vs raw physics for the same ticks, their ratio, RSS (median of runs)."""
        from footsim.backends.bench3d import bench_backend

        runs = [bench_backend(name, repeats=20, seed=r) for r in range(repeats)]
        keys = [k for k, v in runs[0].items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
        row = {"backend": name}
        row.update({k: statistics.median(r[k] for r in runs) for k in keys if k != "repeats"})
        row["fell"] = any(r.get("fell") for r in runs)
        return [row]

    return run


def bench_planners(repeats: int = 5) -> list[dict]:
    from footsim.planners.bench import bench_planners as planners

    return planners()


BENCHMARKS = {
    "env2d": bench_env2d,
    "walk": bench_walk,
    "mujoco": _bench_3d("mujoco"),
    "dm_control": _bench_3d("dm_control"),
    "pybullet": _bench_3d("pybullet"),
    "planners": bench_planners,
}


def _table(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append("| " + " | ".join(f"{v:.4g}" if isinstance(v, float) else str(v) for v in row.values()) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    from footsim.utils import parse_kv_args

    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {"what": "env2d,walk", "repeats": "5", "steps": "20000", "wrapped": "false"},
        "footsim-bench",
    )
    names = [n for n in args["what"].split(",") if n]
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        raise SystemExit(f"footsim-bench: unknown benchmark(s) {unknown}; valid: {sorted(BENCHMARKS)}")
    try:
        repeats, steps = int(args["repeats"]), int(args["steps"])
    except ValueError:
        raise SystemExit(
            f"footsim-bench: repeats and steps must be integers, got repeats={args['repeats']} steps={args['steps']}"
        ) from None
    if repeats < 1 or steps < 1:
        raise SystemExit(f"footsim-bench: repeats and steps must be >= 1, got repeats={repeats} steps={steps}")
    print(f"machine: {_machine()}; repeats: {repeats} (median reported)\n")
    for name in names:
        kwargs = {"repeats": repeats}
        if name == "env2d":
            kwargs["steps"] = steps
            kwargs["wrapped"] = str(args["wrapped"]).lower() in ("1", "true", "yes")
        try:
            rows = BENCHMARKS[name](**kwargs)
        except ImportError as err:
            print(f"{name}: skipped ({err})\n")
            continue
        print(_table(rows) + "\n")
