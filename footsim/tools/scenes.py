"""``footsim-scenes out=FILE n=500 seed=S obstacles=true|false``: sample scenes of the task's
distribution into a scene file (:mod:`footsim.tasks.scenes`)."""

from __future__ import annotations

import sys

from footsim.tasks.scenes import SceneSampler, sample_scenes, save_scenes
from footsim.utils import parse_kv_args


def main(argv: list[str] | None = None) -> None:
    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {"out": None, "n": "500", "seed": "0", "obstacles": "false"},
        "footsim-scenes",
        usage=__doc__,
    )
    if not args["out"]:
        raise SystemExit("footsim-scenes: out=FILE is required")
    try:
        n, seed = int(args["n"]), int(args["seed"])
    except ValueError:
        raise SystemExit(
            f"footsim-scenes: n and seed must be integers, got n={args['n']!r} seed={args['seed']!r}"
        ) from None
    if n <= 0:
        raise SystemExit(f"footsim-scenes: n must be > 0, got {n}")
    flag = str(args["obstacles"]).lower()
    if flag not in ("true", "false"):
        raise SystemExit(f"footsim-scenes: obstacles must be true or false, got {args['obstacles']!r}")
    scenes = sample_scenes(SceneSampler(obstacles=flag == "true"), n, seed)
    save_scenes(args["out"], scenes, meta={"n": n, "seed": seed, "obstacles": flag == "true"})
    print(f"wrote {n} scenes to {args['out']}")
