"""Probe: a MuJoCo obstacle-free zoo policy on the standard scenes whose goal lies within ``near`` m,
with the chosen action dimensions clamped to ±c of the step limits (unclamped: c = 1), at the study's
2 ms timestep.  Prints one JSON line of outcome counts.

    python scripts/probe_step_clamp.py mj_nav_300k_s0 0.5 0.5 2,5      # each foot's turn at ±0.5
"""

import json
import math
import sys
import time

import footsim  # noqa: F401  (first, so that it pins OpenBLAS's kernels before NumPy loads)

# isort: split
import numpy as np

from footsim import zoo
from footsim.results import reproduce as rp
from footsim.rl.evaluate import evaluate
from footsim.tasks.scenes import sample_scenes

name, clamp, near = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
dims = [int(d) for d in sys.argv[4].split(",")] if len(sys.argv) > 4 else [2, 5]
job = rp.Job(
    "probe",
    "standard",
    "policy",
    name,
    0,
    backend="mujoco",
    task="nav",
    noise="none",
    scenes_seed=20220101,
    n_scenes=500,
    backend_settings=(("physics_dt", 0.002),),
)
env, policy = rp.job_env_and_controller(job, str(zoo.zoo_dir()))
scenes = sample_scenes(env.sampler, 500, 20220101)
indices = [i for i, s in enumerate(scenes) if math.hypot(s.goal.x, s.goal.y) < near]


class Clamped:
    def reset(self, scene, info):
        policy.reset(scene, info)

    def __call__(self, obs, info):
        action = np.array(policy(obs, info), dtype=np.float32)
        action[dims] = np.clip(action[dims], -clamp, clamp)
        return action


started = time.time()
records = evaluate(env, Clamped(), scenes, seed=0, progress=False, indices=indices)
counts = {k: sum(r["outcome"] == k for r in records) for k in ("success", "fall", "timeout", "collision")}
print(
    json.dumps(
        {
            "name": name,
            "clamp": clamp,
            "dims": dims,
            "n": len(records),
            **counts,
            "wall_s": round(time.time() - started, 1),
        }
    )
)
