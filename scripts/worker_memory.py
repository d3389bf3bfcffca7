"""Memory of SubprocVecEnv env workers, as ``footsim-train`` starts them (forkserver, with the
same preload): RSS, PSS and USS of every child process after 20 vector steps.

    python scripts/worker_memory.py [backend=mujoco] [n_envs=4]

PSS divides shared pages among the processes that map them, so it is what each worker adds.
"""

from __future__ import annotations

import os
import sys

import gymnasium as gym
import numpy as np
import psutil
from stable_baselines3.common.vec_env import SubprocVecEnv

import footsim  # noqa: F401  (registers the env)


def make(backend: str):
    return lambda: gym.make("footsim/FootstepNav-v0", backend=backend)


def main(argv: list[str]) -> None:
    import multiprocessing

    from footsim.backends.base import BACKENDS

    args = dict(a.split("=", 1) for a in argv)
    backend, n = args.get("backend", "mujoco"), int(args.get("n_envs", "4"))
    multiprocessing.set_forkserver_preload(  # as footsim.rl.train.build_vec_env
        ["stable_baselines3.common.vec_env", "footsim.env", BACKENDS[backend].target.split(":")[0]])
    venv = SubprocVecEnv([make(backend) for _ in range(n)], start_method="forkserver")
    try:
        venv.reset()
        for _ in range(20):
            venv.step(np.array([venv.action_space.sample() for _ in range(n)]))
        for child in psutil.Process(os.getpid()).children(recursive=True):
            m = child.memory_full_info()
            print(f"pid {child.pid}: RSS {m.rss / 2**20:.0f} MB, PSS {m.pss / 2**20:.0f} MB, USS {m.uss / 2**20:.0f} MB")
    finally:
        venv.close()


if __name__ == "__main__":
    main(sys.argv[1:])
