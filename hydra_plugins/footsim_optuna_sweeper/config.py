"""The sweeper's config schema, registered as ``hydra/sweeper/optuna``.

No ``from __future__ import annotations`` here: Hydra's plugin scanner executes this module before
it is in ``sys.modules``, and dataclasses then cannot resolve string annotations (every Hydra
app would fail at start).
"""

import importlib.util
import warnings
from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore


@dataclass
class OptunaSweeperConf:
    _target_: str = "hydra_plugins.footsim_optuna_sweeper.optuna_sweeper.FootsimOptunaSweeper"
    _recursive_: bool = False  # the sampler is built by the sweeper, after checking optuna is installed

    # "maximize" | "minimize", or a list of them for a task returning several values
    direction: Any = "maximize"
    study_name: str = "footsim"
    # e.g. sqlite:///multirun/hpo/study.db (relative to the launch dir) or sqlite:////abs/path.db;
    # null = in memory (no resume)
    storage: str | None = None
    # the study's budget: the sweep runs until the study holds n_trials finished trials, so
    # re-running the same command after an interruption only runs the missing ones
    n_trials: int = 20
    # trials asked per batch and handed to the launcher together (parallel with joblib/SLURM/Ray)
    n_jobs: int = 1
    # any optuna sampler; TPE with a seed by default
    sampler: Any = field(default_factory=lambda: {"_target_": "optuna.samplers.TPESampler", "seed": 0})
    # search space: key -> Hydra sweep syntax (interval, tag(log, interval), range, choice, a,b,c)
    params: dict[str, Any] = field(default_factory=dict)
    # on resume, re-run (same parameters) the trials an interruption left unfinished
    retry_interrupted: bool = True
    # scalar entries of this file in each job's run dir become the trial's user attributes
    user_attrs_file: str | None = "eval/summary.json"


ConfigStore.instance().store(
    group="hydra/sweeper", name="optuna", node=OptunaSweeperConf, provider="footsim_optuna_sweeper"
)

if importlib.util.find_spec("hydra_plugins.hydra_optuna_sweeper") is not None:
    warnings.warn(
        "both footsim's Optuna sweeper and the published hydra-optuna-sweeper are installed; they both "
        "register hydra/sweeper=optuna. Uninstall hydra-optuna-sweeper (pip uninstall hydra-optuna-sweeper).",
        stacklevel=1,  # the warning is about this plugin module itself, not about whoever imports it
    )
