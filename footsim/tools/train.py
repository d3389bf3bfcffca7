"""``footsim-train [overrides]``: train PPO on a composed config, then evaluate
(:func:`footsim.rl.train.train`); a Hydra app on ``conf/config.yaml``, also under multirun launchers.
``init_from=zoo:NAME`` starts from a zoo entry (:mod:`footsim.zoo`)."""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from footsim import zoo
from footsim.config import conf_dir
from footsim.rl.common import CONFIG_FILE
from footsim.rl.train import train
from footsim.utils import note_not_honoured


def _main(cfg: DictConfig):
    hydra_cfg = HydraConfig.get()
    if cfg.get("resume"):
        ignored = [o for o in hydra_cfg.overrides.task if o.split("=", 1)[0].lstrip("+~") != "resume"]
        if ignored:  # the run's saved config decides
            note_not_honoured("resume", f"continuing with the run's saved config ({CONFIG_FILE})", " ".join(ignored))
    if zoo.is_zoo_ref(cfg.get("init_from")):  # init_from=zoo:NAME: the entry's directory, checked
        try:
            parent = zoo.resolve(cfg.init_from)
        except zoo.ZooError as err:
            raise SystemExit(f"footsim-train: init_from={cfg.init_from}: {err}") from None
        print(f"init_from={cfg.init_from}: {parent}")
        cfg.init_from = str(parent)
    summary = train(cfg, Path(hydra_cfg.runtime.output_dir))
    return summary.get("success") if summary else None


def main() -> None:
    hydra.main(config_path=str(conf_dir()), config_name="config", version_base="1.3")(_main)()
