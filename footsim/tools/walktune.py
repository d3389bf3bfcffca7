"""``footsim-walktune backend=B [walk.KEY=V ...]``: the walk-tuning objective of the composed
``walk`` group on a 3D backend (:func:`footsim.calibration.walktune.run`), as a Hydra app (``-m +hpo=...``
sweeps it with footsim's Optuna sweeper)."""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig

from footsim.calibration.walktune import format_result, run
from footsim.config import conf_dir


def _main(cfg) -> float:
    result = run(cfg, Path(HydraConfig.get().runtime.output_dir))
    print(format_result(result), flush=True)
    return result["objective"]


def main() -> None:
    hydra.main(config_path=str(conf_dir()), config_name="walktune", version_base="1.3")(_main)()


if __name__ == "__main__":
    main()
