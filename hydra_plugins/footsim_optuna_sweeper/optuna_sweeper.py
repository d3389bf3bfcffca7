"""The Hydra ``Sweeper`` plugin class (thin: optuna is imported only when the sweeper is used)."""

from __future__ import annotations

from typing import Any

from hydra.plugins.sweeper import Sweeper
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig

from .config import OptunaSweeperConf  # noqa: F401  (registers hydra/sweeper/optuna when Hydra scans plugins)


class FootsimOptunaSweeper(Sweeper):
    """Optuna study as a Hydra sweep: batches of ``n_jobs`` trials through the configured launcher."""

    def __init__(self, **kwargs: Any) -> None:
        from ._impl import OptunaSweeperImpl

        self._impl = OptunaSweeperImpl(**kwargs)

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self._impl.setup(hydra_context=hydra_context, task_function=task_function, config=config)

    def sweep(self, arguments: list[str]) -> Any:
        return self._impl.sweep(arguments)
