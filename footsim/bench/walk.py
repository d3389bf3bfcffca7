"""Walk-engine speed: one double step planned (splines) and solved (leg IK of every tick)."""

from __future__ import annotations

import statistics
import time

import numpy as np

from footsim.walk.engine import QuinticWalk
from footsim.walk.footsteps import DoubleStep, FootstepGeometry, StepLimits
from footsim.walk.params import WalkParams


def bench_walk(repeats: int = 5, double_steps: int = 100, control_dt: float = 1.0 / 500.0, seed: int = 0) -> dict:
    """Time ``QuinticWalk.double_step`` plus the leg IK of all its ticks (``joint_targets``, which a
    trajectory solves on first need) on random footsteps while walking (start excluded).

    Each of ``repeats`` runs times ``double_steps`` consecutive double steps; the figures are
    the median over runs of the per-double-step mean CPU time: ``ms_per_double_step``, ``us_per_tick``
    (plus the fastest run, to judge noise from other processes, and ``ticks_per_double_step``).
    """
    if repeats < 1 or double_steps < 1:
        raise ValueError(f"repeats and double_steps must be >= 1, got {repeats}, {double_steps}")
    params = WalkParams()
    limits = StepLimits()
    engine = QuinticWalk(params, FootstepGeometry(limits, foot_distance=params.foot_distance), control_dt=control_dt)
    rng = np.random.default_rng(seed)
    # Moderate random steps (half the limits) keep the walk in its typical, reachable regime.
    orders = [DoubleStep.from_action(rng.uniform(-0.5, 0.5, 6), limits) for _ in range(double_steps)]
    for order in orders[:10]:  # leaves IDLE (the start sequence is not timed) and warms up
        engine.double_step(order)
    per_double_step, wall = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        for order in orders:
            _ = engine.double_step(order).joint_targets  # the IK is solved on this first read
        per_double_step.append((time.process_time() - start_cpu) / double_steps)
        wall.append((time.perf_counter() - start) / double_steps)
    ticks = engine.ticks_per_double_step
    median = statistics.median(per_double_step)
    return {
        "ms_per_double_step": 1e3 * median,  # CPU time of this process: robust on a busy machine
        "us_per_tick": 1e6 * median / ticks,
        "fastest_run_ms_per_double_step": 1e3 * min(per_double_step),
        "wall_ms_per_double_step": 1e3 * statistics.median(wall),
        "ticks_per_double_step": ticks,
        "control_hz": 1.0 / control_dt,
        "repeats": repeats,
    }
