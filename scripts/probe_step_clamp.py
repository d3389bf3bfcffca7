"""Probe: a MuJoCo obstacle-free zoo policy on the standard scenes whose goal lies within ``near`` m,
its actions filtered, at the study's 2 ms timestep.  Prints one JSON line of outcome counts and the
double step each fall came at.

    python scripts/probe_step_clamp.py name=mj_nav_start_s0 clamp=0.5 dims=2,5   # each foot's turn at ±0.5
    python scripts/probe_step_clamp.py name=mj_nav_start_s0 rate=0.3 dims=0,1,2,3,4,5  # each value moves ≤ 0.3 a step
    python scripts/probe_step_clamp.py name=mj_nav_start_s0 clamp=0 first=1 dims=0,1,2,3,4,5  # first step in place

``clamp=C``: the chosen action dimensions clamped to ±C of the step limits (1: unclamped), on the
episode's first ``first`` double steps (0: on every one); ``rate=R``: each chosen dimension moves at
most R from the double step before; ``near=D`` (m): the scenes probed (``near=inf``: all 500).
The results page's probes ran on ``mj_nav_300k_s0`` … ``_s2``, in the zoo at commit 38b3734.
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
from footsim.utils import parse_kv_args

args = parse_kv_args(
    sys.argv[1:],
    {"name": "mj_nav_start_s0", "clamp": "1", "near": "0.5", "dims": "2,5", "rate": "inf", "first": "0"},
    "probe_step_clamp.py",
    usage=__doc__,
)
name, first = args["name"], int(args["first"])
clamp, near, rate = float(args["clamp"]), float(args["near"]), float(args["rate"])
dims = [int(d) for d in args["dims"].split(",")]
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


class Filtered:
    def reset(self, scene, info, seed):
        policy.reset(scene, info, seed)
        self.steps, self.before = 0, None

    def __call__(self, obs, info):
        action = np.array(policy(obs, info), dtype=np.float32)
        if first == 0 or self.steps < first:
            action[dims] = np.clip(action[dims], -clamp, clamp)
        if self.before is not None:
            action[dims] = np.clip(action[dims], self.before[dims] - rate, self.before[dims] + rate)
        self.steps, self.before = self.steps + 1, action.copy()
        return action


started = time.time()
records = evaluate(env, Filtered(), scenes, seed=0, progress=False, indices=indices)
counts = {k: sum(r["outcome"] == k for r in records) for k in ("success", "fall", "timeout", "collision")}
print(
    json.dumps(
        {
            **args,
            "n": len(records),
            **counts,
            "fall_steps": sorted(r["steps"] for r in records if r["outcome"] == "fall"),
            "wall_s": round(time.time() - started, 1),
        }
    )
)
