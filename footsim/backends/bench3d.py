"""Speed and memory of a backend: env double steps/s vs the raw physics rate of the same ticks.

``bench_backend(name, repeats)`` builds the backend the way ``footsim-walkcheck`` does (the walk
preset tuned for it), walks ``repeats`` double steps of a moderate forward/turning pattern and
records every control tick's joint targets.  It then resets and replays exactly those targets
through the sim's physics verbs (``set_leg_targets`` + ``advance``) — the same physics ticks
without the walk engine, the checks or any bookkeeping.  Rates are per CPU second of this
process (``time.process_time``), so other jobs on the machine do not count; wall-clock rates
are reported too.
"""

from __future__ import annotations

import os
import time

import numpy as np

from footsim.geometry import Pose2D
from footsim.tasks.scenes import Scene
from footsim.walk.footsteps import DoubleStep

#: The benchmark's double steps (actions in [-1, 1]), cycled: forward at half the limit with a
#: gentle turn, so every backend can walk it without falling.
PATTERN = np.array([[0.5, 0.0, 0.1, 0.5, 0.0, 0.1], [0.5, 0.0, -0.1, 0.5, 0.0, -0.1]])


def _rss_mb() -> float:
    try:
        import psutil

        return psutil.Process(os.getpid()).memory_info().rss / 2**20
    except ImportError:  # pragma: no cover
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def bench_backend(name: str, repeats: int = 100, seed: int = 0) -> dict:
    """Measure one backend.  Returns a dict:

    ``env_steps_per_s`` (double steps per CPU second through ``Backend.execute``),
    ``physics_steps_per_s`` (the same double steps' physics ticks replayed directly),
    ``ratio`` (env time / physics time, ≥ 1), ``physics_ticks_per_s`` (physics timesteps per CPU
    second in the replay), wall-clock variants ``*_wall``, ``rss_mb`` (resident memory of this
    process after the run) and ``rss_backend_mb`` (growth caused by building and running it),
    plus ``fell`` (whether the pattern made it fall — the figures are then not comparable).
    """
    from footsim.walkcheck import make_backend

    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats!r}")
    rss_before = _rss_mb()
    backend = make_backend(name)
    try:
        scene = Scene(goal=Pose2D(100.0, 0.0, 0.0))
        sim = getattr(backend, "sim", None)
        steps = [DoubleStep.from_action(PATTERN[i % len(PATTERN)], backend.robot.step_limits) for i in range(repeats)]

        # Env: the full double step (walk engine + IK + physics + checks), recording the targets.
        backend.reset(scene, np.random.default_rng(seed))
        recorded = []
        if sim is not None:
            original = sim.set_leg_targets

            def recording(targets, _orig=original):
                recorded.append(np.array(targets, dtype=float))
                _orig(targets)

            sim.set_leg_targets = recording
            # warm-up run with recording to get the exact ticks, then a clean timed run; the
            # compiled control tick bypasses set_leg_targets, so record through the verbs
            # (the same commands: tests/test_kernels3d.py)
            backend.compiled_ticks = False
            for ds in steps:
                backend.execute(ds)
            del sim.set_leg_targets, backend.compiled_ticks
            backend.reset(scene, np.random.default_rng(seed))
        fell = False
        t_cpu, t_wall = time.process_time(), time.perf_counter()
        for ds in steps:
            result = backend.execute(ds)
            fell = fell or result.fell or result.sim_error is not None
        env_cpu, env_wall = time.process_time() - t_cpu, time.perf_counter() - t_wall
        out = {
            "backend": name,
            "repeats": repeats,
            "env_steps_per_s": repeats / env_cpu,
            "env_steps_per_s_wall": repeats / env_wall,
            "fell": bool(fell),
        }
        if sim is not None:
            backend.reset(scene, np.random.default_rng(seed))
            substeps = backend.substeps
            set_targets, advance = sim.set_leg_targets, sim.advance
            t_cpu, t_wall = time.process_time(), time.perf_counter()
            for targets in recorded:
                set_targets(targets)
                advance(substeps)
            phys_cpu, phys_wall = time.process_time() - t_cpu, time.perf_counter() - t_wall
            out.update(
                physics_steps_per_s=repeats / phys_cpu,
                physics_steps_per_s_wall=repeats / phys_wall,
                physics_ticks_per_s=len(recorded) * substeps / phys_cpu,
                ratio=env_cpu / phys_cpu,
                ratio_wall=env_wall / phys_wall,
                control_dt=backend.control_dt,
                physics_dt=backend.physics_dt,
            )
        out["rss_mb"] = _rss_mb()
        out["rss_backend_mb"] = out["rss_mb"] - rss_before
        return out
    finally:
        backend.close()


def bench_mujoco(repeats: int = 100) -> dict:
    """:func:`bench_backend` for MuJoCo."""
    return bench_backend("mujoco", repeats)


if __name__ == "__main__":  # pragma: no cover
    import sys

    for backend_name in sys.argv[1:] or ["mujoco"]:
        print(bench_backend(backend_name, 100))
