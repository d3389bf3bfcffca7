"""Planning time of the baselines on obstacle scenes (``footsim-bench what=planners``, docs/BENCHMARKS.md).

``bench_planners(n_scenes)`` runs both baselines (no noise, 2D backend) on ``n_scenes`` obstacle
scenes of the evaluation distribution and times every plan they make while navigating: the
velocity baseline's global plans (costmap → Lazy Theta*) and the footstep planner's anytime
searches (stopped by its time budget; "first plan" is the time until its first complete plan).
"""

from __future__ import annotations

import math

import numpy as np

from footsim.env import FootstepEnv
from footsim.planners.controllers import make_controller
from footsim.tasks.scenes import sample_scenes


def _row(name: str, times_s, extra: dict | None = None) -> dict:
    t = np.asarray(times_s, dtype=float) * 1e3
    row = {
        "planner": name,
        "plans": int(t.size),
        "median ms": float(np.median(t)) if t.size else math.nan,
        "p95 ms": float(np.percentile(t, 95)) if t.size else math.nan,
        "max ms": float(t.max()) if t.size else math.nan,
        "complete plan within budget": math.nan,
    }
    row.update(extra or {})
    return row


def bench_planners(
    n_scenes: int = 50,
    seed: int = 20220102,
    backend: str = "pymunk",
    velocity: dict | None = None,
    footstep: dict | None = None,
) -> list[dict]:
    env = FootstepEnv(backend=backend, task="nav_obstacles")
    scenes = sample_scenes(env.sampler, n_scenes, seed)
    rows = []
    try:
        for name, params in (("velocity", velocity), ("footstep", footstep)):
            ctrl = make_controller(env, {"name": name, **(params or {})})
            times, first, complete, plans = [], [], 0, 0
            for i, scene in enumerate(scenes):
                obs, info = env.reset(seed=i, options={"scene": scene})
                ctrl.reset(scene, info, seed=i)
                done = False
                while not done:
                    obs, _, terminated, truncated, info = env.step(ctrl(obs, info))
                    done = terminated or truncated
                times += ctrl.plan_times
                if name == "footstep":
                    for plan in ctrl.plans:
                        plans += 1
                        if not math.isnan(plan.first_solution_s):
                            first.append(plan.first_solution_s)
                            complete += 1
            if name == "velocity":
                label = (
                    f"velocity: global plan ({ctrl.params.global_planner}), "
                    f"every {ctrl.params.replan_period} double steps"
                )
                rows.append(_row(label, times))
            else:
                budget = ctrl.params.expansion_budget
                budget_text = (
                    f"{budget} expansions" if budget is not None else f"{ctrl.params.time_budget_s * 1e3:.0f} ms"
                )
                label = f"footstep: anytime A* per double step, budget {budget_text}"
                rows.append(_row(label, times, {"complete plan within budget": complete / max(plans, 1)}))
                rows.append(_row("footstep: time to first complete plan", first))
    finally:
        env.close()
    return rows
