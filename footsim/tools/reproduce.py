"""``footsim-reproduce [key=value ...]``: re-evaluate the study's zoo policies and baselines, rewrite the
data files, the results page and its plots, and report the cells that changed
(:mod:`footsim.results.reproduce`); ``train=true`` runs the study's trainings instead.

Keys: ``plan`` (default conf/study/v1.yaml), ``zoo`` (default $FOOTSIM_ZOO or footsim/zoo),
``out`` (data files and plots, default docs/results), ``page`` (default docs/RESULTS.md),
``only`` (2d, 3d, matrix, zoo or condition names, comma-separated), ``sets`` (scene sets), ``all``
(every condition on every set; false: with neither ``only`` nor ``sets`` given, the plan's
``reproduce:`` scope, in v1 each zoo policy under its own condition on the standard set; the data
files keep the other evaluations' values),
``n_scenes`` (at most this many scenes per set), ``jobs`` (worker processes; default ``auto``, one per
CPU core this process may use),
``shard_size`` (scenes per 3D task, default 50; a 2D task takes five times as many), ``baselines``
(true), ``plots`` (true), ``progress`` (true), ``strict`` (exit 1 when a cell changed; false),
``backends.B.KEY=V`` (evaluate every job on backend B with setting KEY of conf/backend/B.yaml at V,
over the preset, instead of the settings a policy recorded: the study at other physics, e.g.
``backends.mujoco.physics_dt=0.001``; needs ``out`` and ``page`` away from the data files it would
replace).
Training: ``train=true [launcher=L | +launcher=L] [runs_dir=DIR] [dry_run=true] [add=true]``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from omegaconf import OmegaConf

from footsim import zoo
from footsim.results import reproduce as rp

DEFAULTS: dict[str, str | None] = {
    "plan": None,
    "zoo": None,
    "out": "docs/results",
    "page": "docs/RESULTS.md",
    "only": None,
    "sets": None,
    "all": "false",
    "n_scenes": None,
    "jobs": "auto",
    "shard_size": "50",
    "baselines": "true",
    "plots": "true",
    "progress": "true",
    "strict": "false",
    "train": "false",
    "launcher": None,
    "runs_dir": None,
    "dry_run": "false",
    "add": "true",
}
BOOLS = ("all", "baselines", "plots", "progress", "strict", "train", "dry_run", "add")
INTS = ("n_scenes", "jobs", "shard_size")


def parse_args(argv: list[str]) -> dict:
    args: dict = dict(DEFAULTS)
    args["backends"] = {}
    for arg in argv:
        if arg in ("-h", "--help"):
            print((__doc__ or "").strip())
            raise SystemExit(0)
        if "=" not in arg:
            raise SystemExit(f"footsim-reproduce: expected key=value, got {arg!r}; keys: {sorted(DEFAULTS)}")
        key, value = arg.split("=", 1)
        key = "launcher" if key == "+launcher" else key
        if key.startswith("backends."):
            parts = key.split(".")
            if len(parts) != 3 or not all(parts):
                raise SystemExit(f"footsim-reproduce: {key}: expected backends.BACKEND.KEY=VALUE")
            # typed as on a Hydra command line (0.001 a float, true a bool)
            args["backends"].setdefault(parts[1], {})[parts[2]] = OmegaConf.from_dotlist([f"v={value}"]).v
            continue
        if key not in DEFAULTS:
            raise SystemExit(f"footsim-reproduce: unknown key {key!r}; keys: {sorted(DEFAULTS)}")
        args[key] = value
    for key in BOOLS:
        value = str(args[key]).lower()
        if value not in ("true", "false"):
            raise SystemExit(f"footsim-reproduce: {key} must be true or false, got {args[key]!r}")
        args[key] = value == "true"
    if args["jobs"] == "auto":
        args["jobs"] = str(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    for key in INTS:
        if args[key] is None:
            continue
        try:
            args[key] = int(args[key])
        except ValueError:
            raise SystemExit(f"footsim-reproduce: {key} must be an integer, got {args[key]!r}") from None
        if args[key] <= 0:
            raise SystemExit(f"footsim-reproduce: {key} must be > 0, got {args[key]}")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    root = Path(args["zoo"]).expanduser() if args["zoo"] else zoo.zoo_dir()
    try:
        plan = rp.load_plan(args["plan"])
        conditions = rp.select(plan, args["only"])
        if args["train"]:
            runs_dir = Path(args["runs_dir"] or plan.runs_dir).expanduser().resolve()
            rp.train(plan, conditions, runs_dir, root, args["launcher"], args["dry_run"], args["add"])
            return
        only, sets = rp.scope(plan, args["only"], args["sets"].split(",") if args["sets"] else None, args["all"])
        result = rp.reproduce(
            plan,
            Path(args["out"]),
            Path(args["page"]),
            root,
            only=only,
            n_scenes=args["n_scenes"],
            sets=sets,
            workers=args["jobs"],
            shard_size=args["shard_size"],
            baselines=args["baselines"],
            progress=args["progress"],
            plots=args["plots"],
            backend_settings=args["backends"],
        )
    except (rp.PlanError, zoo.ZooError) as err:
        raise SystemExit(f"footsim-reproduce: {err}") from None
    if args["strict"] and result["differences"]:
        raise SystemExit(1)
