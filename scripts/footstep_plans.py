"""Every footstep plan of a fixed set of planning problems, exactly, to show that a change of the
planner's implementation changed no plan.

    python scripts/footstep_plans.py out=FILE.txt [scenes=100] [check=FILE.txt]

Problems: ``scenes`` obstacle scenes (``SceneSampler(obstacles=True)``, seed 20220101, as the
evaluation's scene set) × four starts each: the robot at rest at the origin; the plan's first
double step executed and the rest of the plan replayed (``previous``); a random believed pose in
the scene (feet from ``feet_from_nav`` after a random last step), which gives partial plans and
starts closer to obstacles than the safety margin; and the same with a 60-expansion budget and a
stable region that forbids backward steps (every rule of the search).  One line per plan: status,
cost, ε, expansions, and every footstep and landing pose as ``repr`` of its floats.  Only public
surfaces are used, so the script runs unchanged before and after a change.  ``check=FILE``
compares with a recorded file and exits 1 at the first difference.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import footsim  # noqa: F401  (before NumPy loads: footsim pins OpenBLAS's kernels)

# isort: split
import numpy as np

from footsim.geometry import Pose2D
from footsim.planners.footstep import FootstepParams, FootstepPlanner, feet_from_nav
from footsim.tasks.scenes import SceneSampler, sample_scenes
from footsim.walk.footsteps import Footstep, FootstepGeometry, StepLimits

LIMITS = StepLimits(0.156, 0.103, 0.764)
GEOMETRY = FootstepGeometry(LIMITS, 0.154, 0.106, 0.1799)
TRUNK = (0.15, 0.15)


def _line(tag: str, plan) -> str:
    steps = " ".join(f"{s.name[0]}{tuple(map(repr, st))}" for s, st in plan.steps)
    poses = " ".join(f"{s.name[0]}{tuple(map(repr, p))}" for s, p in plan.poses)
    return f"{tag} {plan.status} cost={plan.cost!r} eps={plan.epsilon!r} n={plan.expanded} | {steps} | {poses}"


def _stable_csv(directory: str) -> str:
    rows = ["right_x,right_y,right_theta,left_x,left_y,left_theta,fall_rate,n,falls"]
    grid = (-1.0, -0.5, 0.0, 0.5, 1.0)
    for x in grid:
        for y in grid:
            for t in grid:
                rate = 1.0 if x < 0 else 0.0
                rows.append(f"{x},{y},{t},{x},{y},{t},{rate},2,{int(2 * rate)}")
    path = Path(directory) / "stable.csv"
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def plans(n_scenes: int) -> list[str]:
    lines = []
    rng = np.random.default_rng(7)
    scenes = sample_scenes(SceneSampler(obstacles=True), n_scenes, seed=20220101)
    with tempfile.TemporaryDirectory() as tmp:
        small = FootstepParams(expansion_budget=60, stable_region=_stable_csv(tmp))
        for k, scene in enumerate(scenes):
            planner = FootstepPlanner(GEOMETRY, TRUNK, scene, FootstepParams())
            feet = GEOMETRY.initial_feet()
            first = planner.plan(feet.left, feet.right)
            lines.append(_line(f"{k} rest", first))
            if first.ok and len(first.steps) >= 2:
                step = first.next_double_step()
                _, after, _, _ = GEOMETRY.execute(feet, step)
                lines.append(_line(f"{k} replan", planner.plan(after.left, after.right, previous=first)))
            g = scene.goal
            nav = Pose2D(g.x * rng.uniform(0, 1) + rng.normal(0, 0.3), g.y * rng.uniform(0, 1), rng.uniform(-3, 3))
            last = Footstep(*(rng.uniform(-1, 1, 3) * LIMITS.as_array()))
            left, right = feet_from_nav(nav, GEOMETRY, last)
            lines.append(_line(f"{k} random", planner.plan(left, right)))
            constrained = FootstepPlanner(GEOMETRY, TRUNK, scene, small)
            lines.append(_line(f"{k} small", constrained.plan(left, right)))
    return lines


def main(argv: list[str]) -> int:
    opts = dict(a.split("=", 1) for a in argv)
    t0 = time.process_time()
    lines = plans(int(opts.get("scenes", 100)))
    print(f"{len(lines)} plans in {time.process_time() - t0:.1f} s CPU", file=sys.stderr)
    if "out" in opts:
        Path(opts["out"]).write_text("\n".join(lines) + "\n")
    if "check" in opts:
        recorded = Path(opts["check"]).read_text().splitlines()
        for i, (a, b) in enumerate(zip(recorded, lines)):
            if a != b:
                print(f"plan {i} differs:\n  recorded {a[:300]}\n  now      {b[:300]}")
                return 1
        if len(recorded) != len(lines):
            print(f"{len(recorded)} recorded plans, {len(lines)} now")
            return 1
        print(f"all {len(lines)} plans identical")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
