"""Open-loop random double steps over the full step limits, many sequences: how often does a 3D
backend fall?  (The walk check runs one such sequence; this runs one per seed.)

    python scripts/random_walks.py backend=mujoco seeds=2000:2030 [steps=50] [backend.KEY=VALUE ...]

Prints, per seed, the double step at which the robot fell (or "-"), then the count that survived.
``backend.KEY=VALUE`` overrides a backend option (YAML values: ``null``, numbers).
"""

from __future__ import annotations

import sys

import footsim  # noqa: F401  (before NumPy loads: footsim pins OpenBLAS's kernels)

# isort: split
import numpy as np
import yaml

from footsim import config as fconf
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.tasks.nav import tilted_over
from footsim.walk.footsteps import DoubleStep


def fall_step(backend, actions: np.ndarray) -> int | None:
    """1-based double step at which ``backend`` fell or blew up, or None if it walked them all."""
    backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
    for i, action in enumerate(actions):
        result = backend.execute(DoubleStep.from_action(action, backend.robot.step_limits))
        if tilted_over(result) or result.sim_error is not None:
            return i + 1
    return None


def main(argv: list[str]) -> None:
    args = {"backend": "mujoco", "seeds": "2000:2020", "steps": "50"}
    overrides = {}
    for arg in argv:
        key, sep, value = arg.partition("=")
        if not sep:
            raise SystemExit(f"expected key=value, got {arg!r}")
        if key.startswith("backend."):
            overrides[key.removeprefix("backend.")] = yaml.safe_load(value)
        elif key in args:
            args[key] = value
        else:
            raise SystemExit(f"unknown key {key!r}; keys: {sorted(args)} and backend.<option>")
    name = args["backend"]
    first, _, last = args["seeds"].partition(":")
    seeds = range(int(first), int(last or int(first) + 1))
    walk = fconf.build_walk(fconf.load_preset("walk", backend=name))
    backend = fconf.build_backend(
        fconf.load_preset("backend", {"name": name, **overrides}), fconf.build_robot("wolfgang"), walk
    )
    try:
        survived = 0
        for seed in seeds:
            actions = np.random.default_rng(seed).uniform(-1, 1, size=(int(args["steps"]), 6))
            fell = fall_step(backend, actions)
            survived += fell is None
            print(f"seed {seed}: {'-' if fell is None else f'fell at {fell}'}", flush=True)
    finally:
        backend.close()
    print(
        f"{name} {overrides or ''}: {survived} of {len(seeds)} sequences walked {args['steps']} double steps "
        "without a fall"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
