"""Which double steps of a policy's episodes touch an obstacle, per scene, on a chosen backend.

    python scripts/contacts_per_step.py run=RUN_DIR backend=pybullet scenes=FILE \\
        episodes=EVAL_DIR/episodes.csv outcome=fall n=40 [physics_dt=0.002] [parts=true]

Replays the first ``n`` scenes whose ``outcome`` in ``episodes`` (an evaluation's episodes.csv)
matches, with the run's policy on ``backend``, and prints one line per scene: its outcome here and a
string with one character per double step, ``C`` = a robot-obstacle contact during that step.
With ``parts=true`` (MuJoCo-engine backends) each line also names the robot bodies touching an
obstacle at the episode's first contact check that found one, and the end counts them over the
falls that followed a contact.
"""

from __future__ import annotations

import csv
import sys
from collections import Counter

import footsim  # noqa: F401  (first, so that it pins OpenBLAS's kernels before NumPy loads)

# isort: split
import mujoco
from omegaconf import OmegaConf

from footsim import config as fconf
from footsim.env import make_env
from footsim.rl.common import LoadedPolicy
from footsim.rl.evaluate import PolicyController
from footsim.tasks.scenes import load_scenes
from footsim.utils import parse_kv_args


def main(argv: list[str]) -> None:
    args = parse_kv_args(
        argv,
        {
            "run": None,
            "backend": None,
            "scenes": None,
            "episodes": None,
            "outcome": "fall",
            "n": 40,
            "parts": "false",
            "physics_dt": None,
        },
        "contacts_per_step.py",
    )
    if None in (args["run"], args["backend"], args["scenes"], args["episodes"]):
        raise SystemExit("run=, backend=, scenes= and episodes= are required")
    cfg = OmegaConf.load(f"{args['run']}/config.yaml")
    cfg.backend = OmegaConf.create(fconf.load_preset("backend", args["backend"]))
    if args["physics_dt"] is not None:  # e.g. the study's 2 ms (conf/study/v1.yaml, backends:)
        cfg.backend.physics_dt = float(args["physics_dt"])
    scenes = load_scenes(args["scenes"])
    with open(args["episodes"]) as f:
        chosen = [int(r["scene"]) for r in csv.DictReader(f) if r["outcome"] == args["outcome"]][: int(args["n"])]
    env = make_env(cfg)
    controller = PolicyController(LoadedPolicy(args["run"]))
    outcomes = []
    first_parts: list[str] = []  # the bodies at this episode's first contact (parts=true)
    parts = str(args["parts"]).lower() == "true"
    if parts:
        _record_first_contact_parts(env.unwrapped.backend.sim, first_parts)
    fall_parts: Counter[str] = Counter()
    try:
        for index in chosen:
            obs, info = env.reset(seed=index, options={"scene": scenes[index]})
            controller.reset(scenes[index], info, seed=index)
            first_parts.clear()
            steps = ""
            while True:
                obs, _, terminated, truncated, info = env.step(controller(obs, info))
                steps += "C" if info.get("collided") else "."
                if terminated or truncated:
                    break
            outcomes.append((info["outcome"], "C" in steps))
            if info["outcome"] == "fall" and first_parts:
                fall_parts.update(first_parts)
            print(index, info["outcome"], steps, ",".join(first_parts), flush=True)
    finally:
        env.close()
    falls = [touched for outcome, touched in outcomes if outcome == "fall"]
    print(f"{args['backend']}: {len(falls)} falls in {len(outcomes)} scenes, {sum(falls)} of them after a contact")
    if parts:
        print("robot bodies at the first contact of those falls:", dict(fall_parts.most_common()))


def _record_first_contact_parts(sim, parts: list[str]) -> None:
    """Wrap ``sim.obstacle_contact`` so that the first call finding a contact puts the names of the
    robot bodies in that contact into ``parts`` (cleared by the caller at each reset)."""
    check = sim.obstacle_contact

    def obstacle_contact() -> bool:
        touched = check()
        if touched and not parts:
            model, data = sim.mj_model_data()
            mask = sim._obstacle_mask
            for geoms in data.contact.geom[: data.ncon]:
                if mask[geoms].sum() != 1:
                    continue
                robot_geom = int(geoms[0] if mask[geoms[1]] else geoms[1])
                if model.geom_bodyid[robot_geom] != 0:  # body 0 is the world: the floor, not the robot
                    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[robot_geom]))
                    if name not in parts:
                        parts.append(name or f"geom{robot_geom}")
        return touched

    sim.obstacle_contact = obstacle_contact


if __name__ == "__main__":
    main(sys.argv[1:])
