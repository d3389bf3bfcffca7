"""What a PyBullet physics tick costs, and which setting pays for it: the robot standing in the
walk-ready pose, ``stepSimulation`` timed for the configured backend and for variants with one
setting changed (CPU time; the variants interleaved round by round, median reported).

    python scripts/pybullet_tick_cost.py [rounds=7] [ticks=500]

Variants: fewer solver iterations, no rolling friction, no rolling or spinning friction, and
pyramid instead of cone friction (Bullet's ``enableConeFriction=0``).  Which of them still walked
on FootstepNav-v0's PyBullet setup: ``git show dd38ad5:docs/BENCHMARKS.md`` (session 11).
"""

from __future__ import annotations

import statistics
import sys
import time

import footsim  # noqa: F401  (before NumPy loads: footsim pins OpenBLAS's kernels)

# isort: split
import numpy as np
import pybullet as p

from footsim import config as fconf
from footsim.geometry import Pose2D
from footsim.scene import Scene

VARIANTS = {
    "as configured": ({}, {}),
    "solver_iterations 40": ({"solver_iterations": 40}, {}),
    "solver_iterations 20": ({"solver_iterations": 20}, {}),
    "solver_iterations 10": ({"solver_iterations": 10}, {}),
    "rolling_friction 0": ({"rolling_friction": 0.0}, {}),
    "rolling and spinning friction 0": ({"rolling_friction": 0.0, "spinning_friction": 0.0}, {}),
    "pyramid friction": ({}, {"enableConeFriction": 0}),
}


def standing(overrides: dict, engine: dict):
    walk = fconf.build_walk(fconf.load_preset("walk", backend="pybullet"))
    backend = fconf.build_backend(
        fconf.load_preset("backend", {"name": "pybullet", **overrides}), fconf.build_robot("wolfgang"), walk
    )
    if engine:
        p.setPhysicsEngineParameter(physicsClientId=backend.sim.client, **engine)
    backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
    return backend


def main(argv: list[str]) -> None:
    args = dict(a.split("=", 1) for a in argv)
    rounds, ticks = int(args.get("rounds", 7)), int(args.get("ticks", 500))
    backends = {name: standing(*spec) for name, spec in VARIANTS.items()}
    times: dict[str, list[float]] = {name: [] for name in backends}
    try:
        for _ in range(rounds):
            for name, backend in backends.items():
                client = backend.sim.client
                start = time.process_time()
                for _ in range(ticks):
                    p.stepSimulation(physicsClientId=client)
                times[name].append(1e6 * (time.process_time() - start) / ticks)
        base = statistics.median(times["as configured"])
        print("| variant | µs per tick (median) | range | relative | contact points |")
        print("|---|---|---|---|---|")
        for name, backend in backends.items():
            sim = backend.sim
            contacts = len(p.getContactPoints(sim.robot_id, physicsClientId=sim.client))
            med = statistics.median(times[name])
            spread = f"{min(times[name]):.0f}–{max(times[name]):.0f}"
            print(f"| {name} | {med:.0f} | {spread} | {med / base:.2f} | {contacts} |")
    finally:
        for backend in backends.values():
            backend.close()


if __name__ == "__main__":
    main(sys.argv[1:])
