"""The Optuna sweep: search space from Hydra sweep syntax, batches of trials through the launcher.

* **Search space** — ``hydra.sweeper.params`` (and sweep overrides on the command line, which win)
  in Hydra's sweep syntax: ``interval(a, b)`` → float (int if both ends are ints),
  ``tag(log, interval(a, b))`` → log scale, ``tag(int, interval(a, b))`` → int,
  ``range(a, b[, step])`` → stepped int/float (``b`` excluded, as in Python), ``choice(a, b)`` or
  ``a,b`` → categorical.  Plain ``key=value`` arguments are fixed for every trial.
* **Budget and resume** — with a persistent ``storage`` (sqlite) the study is loaded if it exists;
  the sweep runs until the study holds ``n_trials`` finished trials (complete, pruned, or failed
  with an error).  Trials an interruption left unfinished (``RUNNING`` in the storage, or stopped
  by Ctrl-C) are marked failed without an error and, with ``retry_interrupted``, enqueued again
  with the same parameters.  Run one sweep process per study at a time.
* **Batches** — ``n_jobs`` trials are asked, each trial's config is composed first (a composition
  error fails that trial only), and the batch is handed to the configured launcher; the job
  number (and so the job's directory under the sweep dir) is the Optuna trial number.
* **Objective** — the task function's return value (``footsim-train``: the evaluation success
  rate).  ``None``, NaN/inf, a non-number, or a raised exception fails the trial; the sweep
  goes on.  Scalars of ``user_attrs_file`` (``eval/summary.json``) are stored as user attributes.
"""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal, cast

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import (
    IntervalSweep,
    Override,
    QuotedString,
    RangeSweep,
    Transformer,
    escape_special_characters,
)
from hydra.core.plugins import Plugins
from hydra.core.utils import JobReturn, JobStatus
from hydra.plugins.launcher import Launcher
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig, ListConfig, OmegaConf

try:
    import optuna
    from optuna.distributions import BaseDistribution, CategoricalDistribution, FloatDistribution, IntDistribution
    from optuna.trial import TrialState
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError("hydra/sweeper=optuna needs optuna >= 4: pip install 'footsim[hpo]'") from exc

log = logging.getLogger(__name__)

RESULTS_FILE = "optimization_results.yaml"
_DIRECTIONS = ("maximize", "minimize")


def _where(key: str) -> str:
    return f"hydra.sweeper.{key}"


# -- search space ------------------------------------------------------------------------------
def _plain(value: Any) -> Any:
    return value.text if isinstance(value, QuotedString) else value


def distribution_for(override: Override) -> BaseDistribution:
    """An Optuna distribution for one Hydra sweep override (error names the key)."""
    key = override.get_key_element()
    value = override.value()
    if override.is_choice_sweep():
        choices = [_plain(v) for v in override.sweep_iterator(transformer=Transformer.identity)]
        for choice in choices:
            if not (choice is None or isinstance(choice, (bool, int, float, str))):
                raise ValueError(f"{key}: choices must be scalars, got {choice!r}")
        return CategoricalDistribution(choices)
    if override.is_range_sweep():
        assert isinstance(value, RangeSweep)
        values = list(value.range())
        if not values:
            raise ValueError(f"{key}: range({value.start}, {value.stop}, {value.step}) is empty")
        if value.step <= 0:
            raise ValueError(f"{key}: range needs a positive step, got {value.step}")
        if all(isinstance(v, int) for v in (value.start, value.stop, value.step)):
            return IntDistribution(int(values[0]), int(values[-1]), step=int(value.step))
        return FloatDistribution(float(values[0]), float(values[-1]), step=float(value.step))
    if override.is_interval_sweep():
        assert isinstance(value, IntervalSweep)
        unknown = set(value.tags) - {"log", "int"}
        if unknown:
            raise ValueError(f"{key}: unknown tag(s) {sorted(unknown)} for interval; use log and/or int")
        log_scale = "log" in value.tags
        if value.start is None or value.end is None or not value.start < value.end:
            raise ValueError(f"{key}: interval needs start < end, got interval({value.start}, {value.end})")
        if log_scale and value.start <= 0:
            raise ValueError(f"{key}: a log interval needs start > 0, got {value.start}")
        if "int" in value.tags or (isinstance(value.start, int) and isinstance(value.end, int)):
            return IntDistribution(int(value.start), int(value.end), log=log_scale)
        return FloatDistribution(float(value.start), float(value.end), log=log_scale)
    raise ValueError(f"{key}: {override.input_line!r} is not a sweep (use interval, range, choice or a,b,c)")


def format_value(value: Any) -> str:
    """A trial's parameter value as the value part of a Hydra override."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    return escape_special_characters(str(value))


def split_arguments(overrides: Sequence[Override]) -> tuple[dict[str, BaseDistribution], dict[str, str]]:
    """(search space, fixed overrides); a later override of the same key replaces an earlier one."""
    space: dict[str, BaseDistribution] = {}
    fixed: dict[str, str] = {}
    for override in overrides:
        key = override.get_key_element()
        space.pop(key, None)
        fixed.pop(key, None)
        if override.is_sweep_override():
            space[key] = distribution_for(override)
        else:
            fixed[key] = override.get_value_element_as_str()
    return space, fixed


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


# -- the sweeper -------------------------------------------------------------------------------
class OptunaSweeperImpl:
    def __init__(
        self,
        direction: Any = "maximize",
        study_name: str = "footsim",
        storage: str | None = None,
        n_trials: int = 20,
        n_jobs: int = 1,
        sampler: Any = None,
        params: dict | None = None,
        retry_interrupted: bool = True,
        user_attrs_file: str | None = "eval/summary.json",
    ) -> None:
        if isinstance(direction, (list, tuple, ListConfig)):
            self.directions = [str(d) for d in direction]
        else:
            self.directions = [str(direction)]
        if not self.directions or any(d not in _DIRECTIONS for d in self.directions):
            raise ValueError(f"{_where('direction')} must be maximize, minimize or a list of them, got {direction!r}")
        for key, value in (("n_trials", n_trials), ("n_jobs", n_jobs)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{_where(key)} must be a positive integer, got {value!r}")
        if not study_name:
            raise ValueError(f"{_where('study_name')} must be a non-empty string")
        self.study_name, self.storage = str(study_name), storage
        self.n_trials, self.n_jobs = int(n_trials), int(n_jobs)
        self.sampler_cfg = sampler
        self.params = (
            OmegaConf.to_container(params, resolve=True) if isinstance(params, DictConfig) else dict(params or {})
        )
        self.retry_interrupted = bool(retry_interrupted)
        self.user_attrs_file = user_attrs_file
        self.config: DictConfig | None = None
        self.hydra_context: HydraContext | None = None
        self.launcher: Launcher | None = None

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.config, self.hydra_context = config, hydra_context
        self.launcher = Plugins.instance().instantiate_launcher(
            config=config, hydra_context=hydra_context, task_function=task_function
        )

    # -- pieces ---------------------------------------------------------------------------------
    def _sampler(self, n_existing: int) -> optuna.samplers.BaseSampler:
        """The configured sampler; on resume its seed is offset by the study's trial count, so a
        resumed study does not repeat the first samples of the interrupted run (and stays reproducible)."""
        cfg = self.sampler_cfg
        if cfg is None:
            return optuna.samplers.TPESampler()
        if isinstance(cfg, optuna.samplers.BaseSampler):
            return cfg
        from hydra.utils import instantiate

        container = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
        cfg = OmegaConf.create(cast(dict, container))  # a DictConfig's container is a dict
        if n_existing and cfg.get("seed") is not None:
            cfg.seed = int(cfg.seed) + n_existing
        sampler = instantiate(cfg)
        if not isinstance(sampler, optuna.samplers.BaseSampler):
            raise ValueError(f"{_where('sampler')} must build an optuna sampler, got {type(sampler).__name__}")
        return sampler

    def _storage_url(self) -> str | None:
        url = self.storage
        if url and url.startswith("sqlite:///"):
            Path(url[len("sqlite:///") :]).expanduser().parent.mkdir(parents=True, exist_ok=True)
        return url or None

    def _study(self) -> optuna.Study:
        url = self._storage_url()
        n_existing = 0
        if url is not None and self.study_name in optuna.study.get_all_study_names(storage=url):
            n_existing = len(optuna.load_study(study_name=self.study_name, storage=url).trials)
        study = optuna.create_study(
            study_name=self.study_name,
            storage=url,
            sampler=self._sampler(n_existing),
            directions=cast("list[Literal['maximize', 'minimize']]", self.directions),  # checked in __init__
            load_if_exists=True,
        )
        found = [d.name.lower() for d in study.directions]
        if found != self.directions:
            raise ValueError(
                f"{_where('direction')}={self.directions} but the stored study {self.study_name!r} "
                f"optimizes {found}; use another study_name or storage"
            )
        return study

    @staticmethod
    def _is_interrupted(t: optuna.trial.FrozenTrial) -> bool:
        return t.state == TrialState.FAIL and "error" not in t.user_attrs

    def _recover(self, study: optuna.Study) -> None:
        """Mark trials left RUNNING by a killed sweep as interrupted; enqueue interrupted ones again."""
        for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
            log.warning(f"trial {t.number} was left running by an interrupted sweep: marking it failed")
            study.tell(t.number, state=TrialState.FAIL)
        if not self.retry_interrupted:
            return
        trials = study.get_trials(deepcopy=False)
        retried = {t.user_attrs.get("retry_of") for t in trials}
        for t in trials:
            if self._is_interrupted(t) and t.number not in retried and t.params:
                log.info(f"re-running interrupted trial {t.number} with the same parameters")
                study.enqueue_trial(t.params, user_attrs={"retry_of": t.number})

    def _finished(self, study: optuna.Study) -> int:
        return sum(
            1
            for t in study.get_trials(deepcopy=False)
            if t.state in (TrialState.COMPLETE, TrialState.PRUNED)
            or (t.state == TrialState.FAIL and not self._is_interrupted(t))
        )

    def _objective(self, ret: JobReturn) -> tuple[list[float] | None, str]:
        """(values, "") or (None, why the trial failed)."""
        if ret.status != JobStatus.COMPLETED:
            error = ret._return_value  # reading .return_value would re-raise
            return None, f"{type(error).__name__}: {error}"
        value = ret.return_value
        values = list(value) if isinstance(value, (list, tuple, ListConfig)) else [value]
        if len(values) != len(self.directions):
            return None, f"the task returned {value!r}; expected {len(self.directions)} number(s) ({self.directions})"
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                return None, f"the task returned {value!r}, not a finite number (no evaluation?)"
        return [float(v) for v in values], ""

    def _user_attrs(self, trial: optuna.Trial, ret: JobReturn) -> None:
        if ret.hydra_cfg is None:
            return
        try:
            job_dir = Path(str(ret.hydra_cfg.hydra.runtime.output_dir))
        except Exception:
            return
        trial.set_user_attr("job_dir", str(job_dir))
        path = job_dir / self.user_attrs_file if self.user_attrs_file else None
        if path is None or not path.is_file():
            return
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            return
        for key, value in data.items():
            if (value is None or isinstance(value, (bool, int, float, str))) and key not in ("error", "retry_of"):
                trial.set_user_attr(key, value)

    def _fail(self, study: optuna.Study, trial: optuna.Trial, error: str) -> None:
        trial.set_user_attr("error", error)
        study.tell(trial, state=TrialState.FAIL)
        log.warning(f"trial {trial.number} failed: {error}")

    def _launch(self, batch: list[tuple[optuna.Trial, list[str]]]) -> list[tuple[optuna.Trial, JobReturn]]:
        """Launch in runs of consecutive trial numbers, so job number == trial number."""
        out: list[tuple[optuna.Trial, JobReturn]] = []
        runs: list[list[tuple[optuna.Trial, list[str]]]] = []
        for item in batch:
            if runs and runs[-1][-1][0].number + 1 == item[0].number:
                runs[-1].append(item)
            else:
                runs.append([item])
        assert self.launcher is not None  # setup() instantiates it
        for run in runs:
            returns = self.launcher.launch([ov for _, ov in run], initial_job_idx=run[0][0].number)
            out += list(zip([t for t, _ in run], returns))
        return out

    def _write_results(self, study: optuna.Study, sweep_dir: Path) -> None:
        done = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
        results: dict[str, Any] = {
            "name": "optuna",
            "study_name": self.study_name,
            "storage": self.storage,
            "direction": self.directions if len(self.directions) > 1 else self.directions[0],
            "n_trials": len(study.trials),
            "n_complete": len(done),
        }
        if done and len(self.directions) == 1:
            best = study.best_trial
            results.update(
                best_trial=best.number, best_params=best.params, best_value=best.value, best_user_attrs=best.user_attrs
            )
        elif done:
            results["best_trials"] = [
                {"number": t.number, "params": t.params, "values": t.values} for t in study.best_trials
            ]
        _atomic_write(sweep_dir / RESULTS_FILE, OmegaConf.to_yaml(OmegaConf.create(results)))

    # -- the sweep ------------------------------------------------------------------------------
    def sweep(self, arguments: list[str]) -> Any:
        assert self.config is not None and self.launcher is not None and self.hydra_context is not None
        parser = OverridesParser.create(config_loader=self.hydra_context.config_loader)
        lines = [f"{k}={v}" for k, v in self.params.items()] + list(arguments)
        space, fixed = split_arguments(parser.parse_overrides(lines))
        fixed_list = [f"{k}={v}" for k, v in fixed.items()]
        if not space:
            log.warning("hydra.sweeper.params is empty: every trial runs the same config")

        sweep_dir = Path(str(self.config.hydra.sweep.dir))
        sweep_dir.mkdir(parents=True, exist_ok=True)
        OmegaConf.save(self.config, sweep_dir / "multirun.yaml")
        study = self._study()
        self._recover(study)
        finished = self._finished(study)
        log.info(
            f"study {self.study_name!r} ({self.storage or 'in memory'}): {finished} of {self.n_trials} trials "
            f"finished; search space: {', '.join(space) or '-'}; sweep dir: {sweep_dir}"
        )
        returns: list[Sequence[JobReturn]] = []
        while finished < self.n_trials:
            batch: list[tuple[optuna.Trial, list[str]]] = []
            for _ in range(min(self.n_jobs, self.n_trials - finished)):
                trial = study.ask(fixed_distributions=space)
                overrides = fixed_list + [f"{k}={format_value(v)}" for k, v in trial.params.items()]
                try:  # compose first: a bad trial config fails that trial, not the launcher
                    self.hydra_context.config_loader.load_sweep_config(self.config, list(overrides))
                except Exception as exc:
                    self._fail(study, trial, f"config: {type(exc).__name__}: {exc}")
                    finished += 1
                    continue
                batch.append((trial, overrides))
            if not batch:
                continue
            told: set = set()
            try:
                results = self._launch(batch)
                for trial, ret in results:
                    self._user_attrs(trial, ret)
                    values, error = self._objective(ret)
                    if values is None:
                        self._fail(study, trial, error)
                    else:
                        study.tell(trial, values if len(values) > 1 else values[0])
                        log.info(f"trial {trial.number}: {values if len(values) > 1 else values[0]} {trial.params}")
                    told.add(trial.number)
                    finished += 1
                returns.append([ret for _, ret in results])
            except BaseException:  # Ctrl-C, a dead worker pool...: leave the untold trials for a resume
                for trial, _ in batch:
                    if trial.number not in told:
                        trial.set_user_attr("interrupted", True)
                        study.tell(trial, state=TrialState.FAIL)
                self._write_results(study, sweep_dir)
                raise
        self._write_results(study, sweep_dir)
        log.info(f"study {self.study_name!r} done: results in {sweep_dir / RESULTS_FILE}")
        return returns
