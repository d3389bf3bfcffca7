"""Fingerprints of footsim's behaviour, to show that a refactoring changed nothing.

    python scripts/behaviour_hashes.py [out=FILE.json] [check=FILE.json] [backends=pymunk,mujoco,dm_control,pybullet]

Each fingerprint is a SHA-256 over the exact float64 bytes of what the code computes:

* ``walk_engine``: 300 random double steps through ``QuinticWalk`` (joint targets, trunk, feet,
  executed steps), the engine built by the env for the default backend;
* ``rollout_<backend>``: a 25-step rollout through ``gymnasium.make`` with obstacles,
  localization noise and ``randomization=default`` (observations, rewards, poses, outcomes);
* ``rollout_pymunk_plain``: a 200-step 2D rollout of the default env (no obstacles).

All of them for ``footsim/FootstepNav-v1`` and, prefixed ``v0:``, for ``footsim/FootstepNav-v0``.

``check=FILE`` compares with a recorded file and exits 1 naming every fingerprint that differs.
The bytes depend on the numerical libraries too (numpy's small-matrix kernels, numba, the
simulators' builds differ in the last bits between versions) and presumably on the CPU (numba
compiles for the host's instruction set): the same commit and library versions gave other
FootstepNav-v1 walk-engine and 3D fingerprints in a new checkout of the development machine, and
a second run there reproduced the new ones.  So ``out=`` also
records the ``environment`` (library versions, CPU model and vector extensions) and ``check=``
names any entry that differs: then record the base commit's fingerprints in this environment and
compare with those.
Only public surfaces are used, so the script runs unchanged before and after a refactoring.
"""

from __future__ import annotations

import hashlib
import json
import sys

import footsim  # noqa: F401  (registers the env; first, so that it pins OpenBLAS's kernels before NumPy loads)

# isort: split
import gymnasium as gym
import numpy as np

ENVS = {"": "footsim/FootstepNav-v1", "v0:": "footsim/FootstepNav-v0"}


def _digest(chunks) -> str:
    h = hashlib.sha256()
    for chunk in chunks:
        if isinstance(chunk, str):
            h.update(chunk.encode())
        else:
            h.update(np.ascontiguousarray(np.asarray(chunk, dtype=np.float64)).tobytes())
    return h.hexdigest()


def walk_engine_hash(env_id: str, n: int = 300) -> str:
    env = gym.make(env_id, backend="mujoco").unwrapped
    try:
        engine = env.backend.engine
        limits = env.robot.step_limits
    finally:
        env.close()
    from footsim.walk.footsteps import DoubleStep

    rng = np.random.default_rng(1234)
    engine.reset()
    chunks = []
    for _ in range(n):
        trajectory = engine.double_step(DoubleStep.from_unit(rng.uniform(-1, 1, 6).tolist(), limits))
        chunks += [trajectory.joint_targets, trajectory.trunk_in_support, np.asarray(trajectory.executed, dtype=float)]
        chunks += [np.asarray(tuple(foot), dtype=float) for foot in trajectory.feet]
    return _digest(chunks)


def rollout_hash(
    env_id: str, backend: str, steps: int, obstacles: bool, noise: str, randomization: str, seed: int
) -> str:
    env = gym.make(env_id, backend=backend, obstacles=obstacles, noise=noise, randomization=randomization)
    chunks = []
    try:
        rng = np.random.default_rng(seed)
        obs, info = env.reset(seed=seed)
        chunks += [obs, info["pose"]]
        for _ in range(steps):
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            chunks += [obs, [reward, float(terminated), float(truncated)], info["pose"], info["pose_estimate"]]
            chunks.append(info["outcome"])
            if terminated or truncated:
                obs, info = env.reset()
                chunks += [obs, info["pose"]]
    finally:
        env.close()
    return _digest(chunks)


def fingerprints(backends: list[str]) -> dict[str, str]:
    out = {}
    for prefix, env_id in ENVS.items():
        out[f"{prefix}walk_engine"] = walk_engine_hash(env_id)
        for backend in backends:
            out[f"{prefix}rollout_{backend}"] = rollout_hash(
                env_id, backend, 25, True, "localization", "default", seed=7
            )
            print(f"{env_id} {backend}: done", file=sys.stderr, flush=True)
        out[f"{prefix}rollout_pymunk_plain"] = rollout_hash(env_id, "pymunk", 200, False, "none", "none", seed=3)
    return out


def _cpu() -> str:
    """The CPU model and the vector extensions that change compiled floating-point code."""
    try:
        info = open("/proc/cpuinfo").read()
    except OSError:
        import platform

        return platform.processor() or "unknown"
    model = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")), "?")
    flags = next((line.split(":", 1)[1].split() for line in info.splitlines() if line.startswith("flags")), [])
    vector = sorted(f for f in flags if f in {"avx", "avx2", "fma", "avx512f", "avx512vl", "avx512_vnni", "amx_tile"})
    return f"{model} [{' '.join(vector)}]"


def environment() -> dict[str, str]:
    """The versions the fingerprints' last bits depend on."""
    import importlib.metadata as md
    import platform

    versions = {"python": platform.python_version(), "cpu": _cpu()}
    for dist in ("numpy", "numba", "mujoco", "dm_control", "pybullet", "pymunk"):
        try:
            versions[dist] = md.version(dist)
        except md.PackageNotFoundError:
            versions[dist] = "absent"
    return versions


def main(argv: list[str]) -> int:
    opts = dict(arg.split("=", 1) for arg in argv)
    backends = opts.get("backends", "pymunk,mujoco,dm_control,pybullet").split(",")
    result = fingerprints(backends)
    print(json.dumps(result, indent=2))
    if "out" in opts:
        with open(opts["out"], "w") as f:
            json.dump({**result, "environment": environment()}, f, indent=2)
            f.write("\n")
    if "check" in opts:
        with open(opts["check"]) as f:
            expected = json.load(f)
        changed = sorted(k for k in result if k in expected and expected[k] != result[k])
        if changed:
            print(f"changed: {changed}", file=sys.stderr)
            now, then = environment(), expected.get("environment", {})
            differ = {k: (then.get(k, "unrecorded"), v) for k, v in now.items() if then.get(k) != v}
            if differ:
                print(f"the environment differs from the recording (recorded, now): {differ}", file=sys.stderr)
            return 1
        print("all fingerprints unchanged", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
