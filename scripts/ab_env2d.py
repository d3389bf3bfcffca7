"""Interleaved A/B timing of the 2D env step for two checkouts of footsim.

    python scripts/ab_env2d.py A_DIR B_DIR [obstacles=1] [chunk=2000] [rounds=120]

A_DIR and B_DIR are checkouts (e.g. ``git worktree add /tmp/base <commit>``).  Two persistent
worker processes, one per checkout, take turns running ``chunk`` env steps with the same random
actions (episodes reset as they end), in alternating order, and report CPU seconds per chunk.
On this shared machine the speed of the same code drifts by up to 2x within minutes; switching
every fraction of a second makes both sides see the same drift, so the median of the per-round
time ratios is far steadier than comparing separate runs.

Run it in both orders (A B, then B A) and combine the two ratios (geometric mean of r1 and 1/r2):
an A/A run of one commit against itself gave 0.967, so a single order carries a side bias of a
few per cent (which process is which: memory layout, hash seeds).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time

import numpy as np


def worker(path: str, obstacles: bool, chunk: int) -> None:
    sys.path.insert(0, path)
    import footsim
    from footsim.env import FootstepEnv

    if not footsim.__file__.startswith(os.path.abspath(path)):
        raise SystemExit(f"imported footsim from {footsim.__file__}, not from {path}")
    env = FootstepEnv(obstacles=obstacles)

    def run(seed: int) -> float:
        actions = np.random.default_rng(seed).uniform(-1, 1, size=(chunk, 6))
        env.reset(seed=seed)
        start = time.process_time()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return time.process_time() - start

    run(0)  # warm up: kernels loaded, caches filled
    print("ready", flush=True)
    for seed, _ in enumerate(sys.stdin, start=1):
        print(run(seed), flush=True)


def main(argv: list[str]) -> None:
    a_dir, b_dir = argv[0], argv[1]
    opts = dict(arg.split("=", 1) for arg in argv[2:])
    obstacles, chunk, rounds = opts.get("obstacles", "1"), int(opts.get("chunk", 2000)), int(opts.get("rounds", 120))

    def spawn(path: str) -> subprocess.Popen:
        proc = subprocess.Popen(
            [sys.executable, __file__, "--worker", os.path.abspath(path), obstacles, str(chunk)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd="/",
            env=dict(os.environ, PYTHONPATH=os.path.abspath(path)),
        )
        if proc.stdout.readline().strip() != "ready":
            raise SystemExit(f"worker for {path} failed to start")
        return proc

    procs = {"A": spawn(a_dir), "B": spawn(b_dir)}
    times: dict[str, list[float]] = {"A": [], "B": []}
    for k in range(rounds):
        for name in ("A", "B") if k % 2 == 0 else ("B", "A"):
            procs[name].stdin.write("go\n")
            procs[name].stdin.flush()
            times[name].append(float(procs[name].stdout.readline()))
    for proc in procs.values():
        proc.stdin.close()
        proc.wait()
    ratios = sorted(a / b for a, b in zip(times["A"], times["B"]))
    q = len(ratios) // 4
    print(f"obstacles={obstacles} chunk={chunk} rounds={rounds}")
    for name, path in (("A", a_dir), ("B", b_dir)):
        print(
            f"{name} {path}: median {chunk / statistics.median(times[name]):,.0f} env steps per CPU second "
            f"(best chunk {chunk / min(times[name]):,.0f})"
        )
    print(
        f"time A / time B per round: median {statistics.median(ratios):.3f} "
        f"(interquartile {ratios[q]:.3f}-{ratios[-q - 1]:.3f}); > 1 means B is faster"
    )


if __name__ == "__main__":
    if sys.argv[1] == "--worker":
        worker(sys.argv[2], sys.argv[3] == "1", int(sys.argv[4]))
    else:
        main(sys.argv[1:])
