"""Small staged grid sweep of the velocity baseline's parameters on the 2D backend.

Tuning scenes are sampled with seed 777 (not the 500-scene evaluation sets).  Stage 1 tunes
the motion parameters on obstacle-free scenes, stage 2 the costmap/carrot/approach options on
obstacle scenes with the stage-1 winner.  Score: success rate, then mean time to success.
Usage: python scripts/sweep_velocity.py [n_scenes=100] > sweep.txt
       python scripts/sweep_velocity.py 30 backend=mujoco   # a 3D backend: a motion-only grid
                                                            # for its slower gait (falls count as failures)
"""

import itertools
import sys

from footsim.env import FootstepEnv
from footsim.planners.velocity import VelocityController
from footsim.rl.evaluate import evaluate, summarize
from footsim.tasks.scenes import sample_scenes

BACKEND = "pymunk"


def score(task: str, params: dict, n: int) -> dict:
    env = FootstepEnv(task=task, backend=BACKEND)
    scenes = sample_scenes(env.sampler, n, 777)
    s = summarize(evaluate(env, VelocityController.from_env(env, params), scenes, progress=False))
    return s


def run_stage(task, grid, base, n):
    keys = list(grid)
    rows = []
    for values in itertools.product(*grid.values()):
        params = {**base, **dict(zip(keys, values))}
        s = score(task, params, n)
        rows.append((s["success"], -s["success_time_mean"], params, s))
        print(
            f"{task} {dict(zip(keys, values))}: success {s['success']:.3f} collision {s['collision']:.3f} "
            f"fall {s['fall']:.3f} timeout {s['timeout']:.3f} time {s['success_time_mean']:.2f}",
            flush=True,
        )
    rows.sort(key=lambda r: (r[0], r[1]), reverse=True)
    return rows[0][2]


def main():
    global BACKEND
    options = dict(a.split("=", 1) for a in sys.argv[1:] if "=" in a)
    positional = [a for a in sys.argv[1:] if "=" not in a]
    n = int(positional[0]) if positional else 100
    BACKEND = options.get("backend", "pymunk")
    if BACKEND != "pymunk":  # 3D: ~20x slower per episode, so only the motion limits that matter for falls
        motion = {"max_vel_x": [0.15, 0.25, 0.35], "max_rotation_vel": [0.5, 1.0], "smoothing": [0.5, 1.0]}
        print("motion best:", run_stage("nav", motion, {}, n), flush=True)
        return
    motion = {
        "max_vel_x": [0.3, 0.45],
        "max_vel_y": [0.1, 0.2],
        "max_rotation_vel": [0.6, 1.0],
        "translation_slow_down_factor": [0.5, 1.0],
        "rotation_slow_down_factor": [0.3, 1.0],
    }
    best = run_stage("nav", motion, {}, n)
    print("stage 1 best:", best, flush=True)
    obstacles = {
        "inflation": [0.03, 0.08],
        "heading_target": ["goal", "carrot"],
        "behind_ball": [False, True],
        "carrot_distance": [5, 10],
        "smoothing": [0.5, 1.0],
    }
    best = run_stage("nav_obstacles", obstacles, best, n)
    print("stage 2 best:", best, flush=True)


if __name__ == "__main__":
    main()
