"""``footsim-eval run=RUN_DIR|zoo:NAME | controller=velocity|footstep [overrides]``: evaluate a trained run or a
baseline on a scene set (:mod:`footsim.rl.evaluate`); a Hydra app on ``conf/eval.yaml``.

``shard=K/N`` evaluates one slice of the scenes; the shards of one evaluation share a directory:
the Hydra output dir of a single run (``hydra.run.dir=DIR``) or, in a multirun
(``-m shard=0/4,1/4,2/4,3/4``), the sweep dir.  ``merge=DIR`` merges them (no evaluation)."""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode

from footsim import zoo
from footsim.config import conf_dir
from footsim.rl.evaluate import (
    eval_run_config,
    evaluate_baseline,
    evaluate_run,
    evaluate_side_by_side,
    merge_shards,
    shard_of,
)
from footsim.schema import register_schemas
from footsim.utils import note_not_honoured


def _out_dir(cfg) -> Path:
    """Where the results go: the job's output dir; for the shards of a multirun, the sweep dir they share."""
    hydra_cfg = HydraConfig.get()
    if shard_of(cfg) is not None and hydra_cfg.mode == RunMode.MULTIRUN:
        return Path(hydra_cfg.sweep.dir)
    return Path(hydra_cfg.runtime.output_dir)


def _main(cfg) -> dict | None:
    if cfg.get("merge"):
        try:
            return merge_shards(Path(cfg.merge).expanduser(), plot=bool(cfg.plot))
        except (FileNotFoundError, ValueError) as err:
            raise SystemExit(f"footsim-eval: {err}") from None
    controller = cfg.get("controller")
    if controller is not None and controller.get("name", "policy") != "policy":
        if cfg.run is not None:
            note_not_honoured(f"controller={controller.name}", "evaluating the baseline", f"run={cfg.run}")
        return evaluate_baseline(cfg, _out_dir(cfg))
    if cfg.run is None:
        raise SystemExit("footsim-eval: run=RUN_DIR is required (or controller=velocity|footstep for a baseline)")
    try:
        run_dir = zoo.resolve(cfg.run)  # a path, or zoo:NAME (checked against the current configs)
    except zoo.ZooError as err:
        raise SystemExit(f"footsim-eval: run={cfg.run}: {err}") from None
    if cfg.get("backends"):  # the same scenes filmed on several backends, side by side
        evaluate_side_by_side(run_dir, _out_dir(cfg), cfg)
        return None
    run_cfg = eval_run_config(run_dir, cfg)
    return evaluate_run(run_cfg, run_dir, _out_dir(cfg), cfg)


#: conf/eval.yaml's groups that stay empty (the run's choice) unless named on the command line
_CHOSEN_GROUPS = ("backend", "task", "noise", "randomization", "walk")


def check_group_overrides(args: list[str]) -> None:
    """``group.KEY=V`` on a group that ``conf/eval.yaml`` leaves empty needs ``group=NAME`` beside it:
    say so instead of Hydra's "Key ... is not in struct"."""
    named = {a.split("=", 1)[0].lstrip("+~") for a in args if "=" in a}
    for arg in args:
        key = arg.split("=", 1)[0].lstrip("+~")
        group = key.split(".", 1)[0]
        if "." in key and group in _CHOSEN_GROUPS and group not in named:
            raise SystemExit(
                f"footsim-eval: {arg} needs {group}=NAME beside it: a run is evaluated under its recorded "
                f"{group} (a baseline under the default) unless {group}=NAME names a conf/{group} preset, "
                f"which then replaces it with {key.split('.', 1)[1]} set over the preset"
            )


def main() -> None:
    check_group_overrides(sys.argv[1:])
    register_schemas(controllers=True)  # the controller group's schemas, before hydra.main composes
    hydra.main(config_path=str(conf_dir()), config_name="eval", version_base="1.3")(_main)()
