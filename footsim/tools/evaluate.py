"""``footsim-eval run=RUN_DIR | controller=velocity|footstep [overrides]``: evaluate a trained run or a
baseline on a scene set (:mod:`footsim.rl.evaluate`); a Hydra app on ``conf/eval.yaml``."""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig

from footsim.config import conf_dir
from footsim.rl.evaluate import eval_run_config, evaluate_baseline, evaluate_run
from footsim.schema import register_schemas
from footsim.utils import note_not_honoured


def _main(cfg) -> dict:
    controller = cfg.get("controller")
    if controller is not None and controller.get("name", "policy") != "policy":
        if cfg.run is not None:
            note_not_honoured(f"controller={controller.name}", "evaluating the baseline", f"run={cfg.run}")
        return evaluate_baseline(cfg, Path(HydraConfig.get().runtime.output_dir))
    if cfg.run is None:
        raise SystemExit("footsim-eval: run=RUN_DIR is required (or controller=velocity|footstep for a baseline)")
    run_dir = Path(cfg.run).expanduser().resolve()
    run_cfg = eval_run_config(run_dir, cfg)
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    return evaluate_run(run_cfg, run_dir, out_dir, cfg)


def main() -> None:
    register_schemas(controllers=True)  # the controller group's schemas, before hydra.main composes
    hydra.main(config_path=str(conf_dir()), config_name="eval", version_base="1.3")(_main)()
