"""Interleaved A/B of the 3D backends' speed for two checkouts of footsim.

    python scripts/ab_bench3d.py A_DIR B_DIR [backends=mujoco,dm_control,pybullet] [rounds=3] [repeats=3]

A_DIR and B_DIR are checkouts (e.g. ``git worktree add /tmp/base <commit>``).  Each round runs
``footsim-bench what=<backend> repeats=R`` once per checkout, in alternating order, each in a
fresh process with ``PYTHONPATH`` set to the checkout, and reads the env double steps/s and the
env / raw-physics ratio (measured within one run, so robust to the machine's drift).  Prints the
per-round figures and their medians as a markdown table.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys

RUNNER = """
import sys
try:
    from footsim.tools.bench import main
except ImportError:
    from footsim.bench import main
main(sys.argv[1:])
"""


def run(checkout: str, backend: str, repeats: int) -> dict[str, float]:
    env = {**os.environ, "PYTHONPATH": os.path.abspath(checkout), "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    out = subprocess.run(
        [sys.executable, "-c", RUNNER, f"what={backend}", f"repeats={repeats}"],
        env=env,
        cwd="/",
        capture_output=True,
        text=True,
        check=True,
        timeout=1800,
    ).stdout
    lines = [line for line in out.splitlines() if line.startswith("|")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    row = [c.strip() for c in lines[2].strip("|").split("|")]
    values = dict(zip(header, row))
    return {"env": float(values["env_steps_per_s"]), "ratio": float(values["ratio"])}


def main(argv: list[str]) -> None:
    a_dir, b_dir = argv[0], argv[1]
    opts = dict(arg.split("=", 1) for arg in argv[2:])
    backends = opts.get("backends", "mujoco,dm_control,pybullet").split(",")
    rounds, repeats = int(opts.get("rounds", 3)), int(opts.get("repeats", 3))
    print("| backend | round | A env double steps/s | A ratio | B env double steps/s | B ratio |")
    print("|---|---|---|---|---|---|")
    summary = []
    for backend in backends:
        results: dict[str, list[dict[str, float]]] = {"A": [], "B": []}
        for r in range(rounds):
            order = (("A", a_dir), ("B", b_dir)) if r % 2 == 0 else (("B", b_dir), ("A", a_dir))
            for label, checkout in order:
                results[label].append(run(checkout, backend, repeats))
            a, b = results["A"][-1], results["B"][-1]
            print(
                f"| {backend} | {r} | {a['env']:.1f} | {a['ratio']:.3f} | {b['env']:.1f} | {b['ratio']:.3f} |",
                flush=True,
            )
        summary.append(
            (
                backend,
                *(statistics.median(x[key] for x in results[side]) for side in "AB" for key in ("env", "ratio")),
            )
        )
    print("\nmedians\n\n| backend | A env double steps/s | A ratio | B env double steps/s | B ratio |")
    print("|---|---|---|---|---|")
    for backend, a_env, a_ratio, b_env, b_ratio in summary:
        print(f"| {backend} | {a_env:.1f} | {a_ratio:.3f} | {b_env:.1f} | {b_ratio:.3f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
