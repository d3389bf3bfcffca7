"""Which double steps of a policy's episodes touch an obstacle, per scene, on a chosen backend.

    python scripts/contacts_per_step.py run=RUN_DIR backend=pybullet scenes=FILE \\
        episodes=EVAL_DIR/episodes.csv outcome=fall n=40

Replays the first ``n`` scenes whose ``outcome`` in ``episodes`` (an evaluation's episodes.csv)
matches, with the run's policy on ``backend``, and prints one line per scene: its outcome here and a
string with one character per double step, ``C`` = a robot-obstacle contact during that step.
"""

from __future__ import annotations

import csv
import sys

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
        {"run": None, "backend": None, "scenes": None, "episodes": None, "outcome": "fall", "n": 40},
        "contacts_per_step.py",
    )
    if None in (args["run"], args["backend"], args["scenes"], args["episodes"]):
        raise SystemExit("run=, backend=, scenes= and episodes= are required")
    cfg = OmegaConf.load(f"{args['run']}/config.yaml")
    cfg.backend = OmegaConf.create(fconf.load_preset("backend", args["backend"]))
    scenes = load_scenes(args["scenes"])
    with open(args["episodes"]) as f:
        chosen = [int(r["scene"]) for r in csv.DictReader(f) if r["outcome"] == args["outcome"]][: int(args["n"])]
    env = make_env(cfg)
    controller = PolicyController(LoadedPolicy(args["run"]))
    outcomes = []
    try:
        for index in chosen:
            obs, info = env.reset(seed=index, options={"scene": scenes[index]})
            controller.reset(scenes[index], info, seed=index)
            steps = ""
            while True:
                obs, _, terminated, truncated, info = env.step(controller(obs, info))
                steps += "C" if info.get("collided") else "."
                if terminated or truncated:
                    break
            outcomes.append((info["outcome"], "C" in steps))
            print(index, info["outcome"], steps, flush=True)
    finally:
        env.close()
    falls = [touched for outcome, touched in outcomes if outcome == "fall"]
    print(f"{args['backend']}: {len(falls)} falls in {len(outcomes)} scenes, {sum(falls)} of them after a contact")


if __name__ == "__main__":
    main(sys.argv[1:])
