"""Speed and memory of a backend: env double steps/s vs the raw physics rate of the same ticks.

``bench_backend(name, repeats)`` builds the backend the way ``footsim-walkcheck`` does (the walk
preset tuned for it), walks ``repeats`` double steps of a moderate forward/turning pattern and
records every control tick's leg targets.  The timed run alternates, double step by double
step, between the env and a replay of exactly those targets on a second instance of the backend
through the sim's verbs (``set_leg_targets`` + ``advance``) — the same physics ticks without the
walk engine, the control law, the checks or any bookkeeping.  Rates are per CPU second of this
process (``time.process_time``), so other jobs on the machine do not count; wall-clock rates
are reported too.  Resident memory is taken with one backend built (before the replay copy).
"""

from __future__ import annotations

import os
import time

import numpy as np

from footsim.calibration.walkcheck import REQUIRED_SHARE, make_backend
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.tasks.nav import tilted_over
from footsim.walk.footsteps import DoubleStep

#: The benchmark's double steps (actions in [-1, 1]), cycled: forward at 0.4 of the limits, the
#: walk check's required "forward" sequence, which every backend walks without falling.
PATTERN = np.array([[REQUIRED_SHARE, 0.0, 0.0, REQUIRED_SHARE, 0.0, 0.0]])


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
    process after the warm-up run, with one backend built) and ``rss_backend_mb`` (growth caused
    by building and running it),
    plus ``fell`` (whether the pattern made it fall — the figures are then not comparable).
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats!r}")
    rss_before = _rss_mb()
    backend = make_backend(name)
    try:
        scene = Scene(goal=Pose2D(100.0, 0.0, 0.0))
        sim = getattr(backend, "sim", None)
        steps = [DoubleStep.from_action(PATTERN[i % len(PATTERN)], backend.robot.step_limits) for i in range(repeats)]

        # Warm-up: the full double steps once, recording each control tick's leg targets per
        # double step (what the control law commanded before the servo feed-forward, read from
        # the state contract just before each tick's physics).
        backend.reset(scene, np.random.default_rng(seed))
        recorded: list[list[np.ndarray]] = []
        if sim is not None:
            original = sim.advance

            def recording(n_steps, _orig=original):
                recorded[-1].append(sim.state.last_targets())
                _orig(n_steps)

            sim.advance = recording
            for ds in steps:
                recorded.append([])
                backend.execute(ds)
            del sim.advance
        rss_env = _rss_mb()
        # Timed: each env double step (walk engine + IK + physics + checks) is followed by the
        # replay of its physics ticks on a second instance of the same backend (set_leg_targets
        # + advance, nothing else).  Alternating per double step keeps the ratio honest when
        # the machine's speed drifts during the run.
        replay = make_backend(name) if sim is not None else None
        try:
            backend.reset(scene, np.random.default_rng(seed))
            if replay is not None:
                replay.reset(scene, np.random.default_rng(seed))
                set_targets, advance, substeps = replay.sim.set_leg_targets, replay.sim.advance, replay.substeps
            fell = False
            env_cpu = env_wall = phys_cpu = phys_wall = 0.0
            for i, ds in enumerate(steps):
                t_cpu, t_wall = time.process_time(), time.perf_counter()
                result = backend.execute(ds)
                env_cpu += time.process_time() - t_cpu
                env_wall += time.perf_counter() - t_wall
                fell = fell or tilted_over(result) or result.sim_error is not None
                if replay is not None:
                    t_cpu, t_wall = time.process_time(), time.perf_counter()
                    for targets in recorded[i]:
                        set_targets(targets)
                        advance(substeps)
                    phys_cpu += time.process_time() - t_cpu
                    phys_wall += time.perf_counter() - t_wall
        finally:
            if replay is not None:
                replay.close()
        out = {
            "backend": name,
            "repeats": repeats,
            "env_steps_per_s": repeats / env_cpu,
            "env_steps_per_s_wall": repeats / env_wall,
            "fell": bool(fell),
        }
        if replay is not None:
            ticks = sum(map(len, recorded)) * substeps
            out.update(
                physics_steps_per_s=repeats / phys_cpu,
                physics_steps_per_s_wall=repeats / phys_wall,
                physics_ticks_per_s=ticks / phys_cpu,
                ratio=env_cpu / phys_cpu,
                ratio_wall=env_wall / phys_wall,
                control_dt=backend.control_dt,
                physics_dt=backend.physics_dt,
            )
        out["rss_mb"] = rss_env
        out["rss_backend_mb"] = rss_env - rss_before
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
