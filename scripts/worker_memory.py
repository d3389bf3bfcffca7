"""Memory of SubprocVecEnv env workers, as ``footsim-train`` starts them (forkserver, with the
same preload): RSS, PSS and USS of every child process after 20 vector steps.

    python scripts/worker_memory.py [backend=mujoco] [n_envs=4]
    python scripts/worker_memory.py standalone=true [backends=pymunk,mujoco,dm_control,pybullet] [repeats=3]

PSS divides shared pages among the processes that map them, so it is what each worker adds.
``standalone=true`` starts a fresh Python per run that builds one env with ``gymnasium.make``
and takes 30 random steps, and prints the medians of its RSS / PSS / USS and of its anonymous
(private heap) and file-backed (library) resident parts.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys

import footsim  # noqa: F401  (registers the env; first, so that it pins OpenBLAS's kernels before NumPy loads)

# isort: split
import gymnasium as gym
import numpy as np
import psutil
from stable_baselines3.common.vec_env import SubprocVecEnv


def make(backend: str):
    return lambda: gym.make("footsim/FootstepNav-v1", backend=backend)


_ONE_ENV = """
import sys, gymnasium as gym, psutil
import footsim
env = gym.make("footsim/FootstepNav-v1", backend=sys.argv[1])
env.reset(seed=0)
for _ in range(30):
    if any(env.step(env.action_space.sample())[2:4]):
        env.reset()
m = psutil.Process().memory_full_info()
status = dict(line.split(":", 1) for line in open("/proc/self/status"))
kb = lambda key: int(status[key].split()[0]) / 1024
print(m.rss / 2**20, m.pss / 2**20, m.uss / 2**20, kb("RssAnon"), kb("RssFile"))
env.close()
"""


def standalone(backends: list[str], repeats: int) -> None:
    print(f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '(unset)')}; medians of {repeats} processes [MB]\n")
    print("| backend | RSS | PSS | USS | anonymous | file-backed |\n|---|---|---|---|---|---|")
    for backend in backends:
        runs = [
            [
                float(v)
                for v in subprocess.run(
                    [sys.executable, "-c", _ONE_ENV, backend], check=True, capture_output=True, text=True
                ).stdout.split()[-5:]
            ]
            for _ in range(repeats)
        ]
        medians = [statistics.median(column) for column in zip(*runs)]
        print(f"| {backend} | " + " | ".join(f"{v:.0f}" for v in medians) + " |")


def main(argv: list[str]) -> None:
    import multiprocessing

    from footsim.backends.base import BACKENDS

    args = dict(a.split("=", 1) for a in argv)
    if args.get("standalone", "false").lower() in ("1", "true", "yes"):
        return standalone(
            args.get("backends", "pymunk,mujoco,dm_control,pybullet").split(","), int(args.get("repeats", "3"))
        )
    backend, n = args.get("backend", "mujoco"), int(args.get("n_envs", "4"))
    multiprocessing.set_forkserver_preload(  # as footsim.rl.train.build_vec_env
        ["stable_baselines3.common.vec_env", "footsim.env", BACKENDS[backend].target.split(":")[0]]
    )
    venv = SubprocVecEnv([make(backend) for _ in range(n)], start_method="forkserver")
    try:
        venv.reset()
        for _ in range(20):
            venv.step(np.array([venv.action_space.sample() for _ in range(n)]))
        for child in psutil.Process(os.getpid()).children(recursive=True):
            m = child.memory_full_info()
            print(
                f"pid {child.pid}: RSS {m.rss / 2**20:.0f} MB, PSS {m.pss / 2**20:.0f} MB, USS {m.uss / 2**20:.0f} MB"
            )
    finally:
        venv.close()


if __name__ == "__main__":
    main(sys.argv[1:])
