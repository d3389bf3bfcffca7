"""The walk check for one backend with option overrides, plus extra random sequences: how does a
backend setting change the executed displacement (error against the 2D geometry, as
``footsim-walkcheck``) and the falls?

    python scripts/walkcheck_variant.py backend=pybullet ["backend.stabilizer={hip_roll: 0.5}" ...] [extra=5]
    python scripts/walkcheck_variant.py backend=pybullet backend.solver_iterations=20 engine.enableConeFriction=0

Prints one line per variant: each walk-check sequence's error in % (F = fell), then the errors of
``extra`` random 50-double-step sequences (seeds 3000, 3001, ...).  ``backend.KEY=VALUE``
overrides a backend option (YAML values); ``engine.KEY=VALUE`` (PyBullet only) sets a Bullet engine
parameter (``pybullet.setPhysicsEngineParameter``) after the world is built.
"""

from __future__ import annotations

import sys

import footsim  # noqa: F401  (before NumPy loads: footsim pins OpenBLAS's kernels)

# isort: split
import numpy as np
import yaml

import footsim.calibration.walkcheck as wc
from footsim import config as fconf


def main(argv: list[str]) -> None:
    name, extra, overrides, engine = "mujoco", 5, {}, {}
    for arg in argv:
        key, sep, value = arg.partition("=")
        if not sep:
            raise SystemExit(f"expected key=value, got {arg!r}")
        if key == "backend":
            name = value
        elif key == "extra":
            extra = int(value)
        elif key.startswith("backend."):
            overrides[key.removeprefix("backend.")] = yaml.safe_load(value)
        elif key.startswith("engine."):
            engine[key.removeprefix("engine.")] = yaml.safe_load(value)
        else:
            raise SystemExit(f"unknown key {key!r}; keys: backend, extra, backend.<option>, engine.<bullet parameter>")
    walk = fconf.build_walk(fconf.load_preset("walk", backend=name))
    backend = fconf.build_backend(
        fconf.load_preset("backend", {"name": name, **overrides}), fconf.build_robot("wolfgang"), walk
    )
    if engine:
        if name != "pybullet":
            raise SystemExit("engine.<parameter> is for backend=pybullet")
        import pybullet

        pybullet.setPhysicsEngineParameter(physicsClientId=backend.sim.client, **engine)
    geometric = wc.make_backend("pymunk")
    sequences = wc.standard_sequences() + [
        wc.Sequence(
            f"random seed {3000 + i}", np.random.default_rng(3000 + i).uniform(-1, 1, size=(50, 6)), "translation"
        )
        for i in range(extra)
    ]
    cells = []
    try:
        for sequence in sequences:
            commanded, executed = wc.run_sequence(geometric, sequence), wc.run_sequence(backend, sequence)
            error = wc.error_ratio(executed, commanded, sequence.measure)
            cells.append(f"{sequence.name}: {'F' if executed['fell'] else ''}{100 * error:.0f} %")
    finally:
        backend.close()
        geometric.close()
    print(f"{name} {overrides or ''} {engine or ''}: " + "; ".join(cells))


if __name__ == "__main__":
    main(sys.argv[1:])
