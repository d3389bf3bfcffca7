"""Policy selection on validation scenes: ``train.select.every=N`` keeps the best policy, not the last.

PPO's policy moves from one update to the next, so the last policy of a run is one draw among its
recent ones.  With selection on, every ``every`` env steps (and once
at the end) the current policy is written as a run directory of its own (``checkpoints/candidate``)
and evaluated there the way ``footsim-eval`` evaluates a run (deterministic actions, episode ``i`` on
scene ``i`` with seed ``i``) on ``n_scenes`` validation scenes sampled from ``scenes_seed``, under the
run's noise or the ``noise`` preset given (e.g. the thesis's for a run trained under a wider one).  The best
so far (success, then fewer falls and collisions, then the earlier) is kept in ``checkpoints/best``,
and at the end it becomes the run's ``model.zip``.  ``selection.csv`` lists every validation.

The validation seed must not be the seed of the scenes the run is reported on (``eval.scenes_seed``):
a policy chosen on its test scenes would report a biased figure.  Size the validation set to the
differences it should resolve: a success rate near 0.85 measured on 200 scenes has a standard error
of about 0.025, as large as the spread of the validations of one MuJoCo obstacle run
(``docs/RESULTS.md``, ``mj_obst_beta_1m``).
"""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from footsim.rl.common import (
    CHECKPOINT_DIR,
    MODEL_FILE,
    VECNORM_FILE,
    LoadedPolicy,
    under_noise,
    write_json,
    write_policy,
)
from footsim.utils import atomic_save, atomic_write_text

SELECTION_FILE = "selection.csv"
CANDIDATE_DIR = "candidate"
BEST_DIR = "best"
BEST_INFO = "best.json"
COLUMNS = ("num_timesteps", "success", "fall", "collision", "timeout", "success_time_mean", "best")


def select_config(cfg: DictConfig) -> dict[str, int] | None:
    """The run's ``train.select`` section as ints, or None when selection is off (``every: 0``, or a
    run config written before the section existed)."""
    section = cfg.train.get("select")
    if section is None or int(section.get("every", 0)) == 0:
        return None
    return {"every": int(section.every), "n_scenes": int(section.n_scenes), "scenes_seed": int(section.scenes_seed)}


def validate_select(cfg: DictConfig) -> None:
    """Fail at start, naming the key, on a ``train.select`` that cannot work."""
    section = cfg.train.get("select")
    if section is None:
        return
    for key in ("every", "n_scenes", "scenes_seed"):
        value = section.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ValueError(f"train.select.{key} must be a non-negative integer, got {value!r}")
    if section.every == 0:
        return
    if section.n_scenes == 0:
        raise ValueError("train.select.n_scenes must be positive when train.select.every > 0")
    if not cfg.eval.get("scenes") and section.scenes_seed == cfg.eval.scenes_seed:
        raise ValueError(
            f"train.select.scenes_seed ({section.scenes_seed}) is eval.scenes_seed: the policy would be chosen "
            "on the scenes it is reported on; pick another validation seed"
        )


def _better(new: dict, old: dict | None) -> bool:
    if old is None:
        return True
    unsafe_new, unsafe_old = new["fall"] + new["collision"], old["fall"] + old["collision"]
    return (new["success"], -unsafe_new) > (old["success"], -unsafe_old)


class Selector:
    """Validates snapshots of the training policy and keeps the best one (see the module doc)."""

    def __init__(self, cfg: DictConfig, run_dir: Path, settings: dict[str, int]):
        self.cfg, self.run_dir, self.settings = cfg, run_dir, settings
        self.dir = run_dir / CHECKPOINT_DIR
        self.rows: list[dict[str, Any]] = []
        self.best: dict[str, Any] | None = None
        self._env = None
        self._scenes: list | None = None
        path = run_dir / SELECTION_FILE
        if path.is_file():  # a resumed run keeps what it validated before the interruption
            with open(path, newline="") as fh:
                self.rows = [dict(r) for r in csv.DictReader(fh)]
            info = self.dir / BEST_DIR / BEST_INFO
            self.best = json.loads(info.read_text()) if info.is_file() else None

    @property
    def validated_steps(self) -> set[int]:
        return {int(r["num_timesteps"]) for r in self.rows}

    def _env_and_scenes(self):
        if self._env is None:
            from footsim.env import make_env
            from footsim.tasks.scenes import sample_scenes

            self._env = make_env(under_noise(self.cfg, self.cfg.train.select.get("noise")))
            self._scenes = sample_scenes(self._env.sampler, self.settings["n_scenes"], self.settings["scenes_seed"])
        return self._env, self._scenes

    def validate(self, model) -> dict[str, Any]:
        """Evaluate ``model`` (with its observation normalization) on the validation scenes; keep it
        in ``checkpoints/best`` when it beats the best so far."""
        from footsim.rl.evaluate import PolicyController, evaluate, summarize

        candidate = self.dir / CANDIDATE_DIR
        write_policy(model, candidate)
        env, scenes = self._env_and_scenes()
        records = evaluate(env, PolicyController(LoadedPolicy(candidate)), scenes, seed=0, progress=False)
        summary = summarize(records)
        result = {"num_timesteps": int(model.num_timesteps), **{k: summary[k] for k in COLUMNS[1:-1]}}
        is_best = _better(result, self.best)
        if is_best:  # its validation goes in with it: best/ never holds one policy and another's figures
            write_json(candidate / BEST_INFO, result)
            _move_dir(candidate, self.dir / BEST_DIR)
            self.best = result
        self.rows.append({**result, "best": int(is_best)})
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(self.rows)
        atomic_write_text(self.run_dir / SELECTION_FILE, buffer.getvalue())
        print(
            f"validation at {result['num_timesteps']} steps: success {result['success']:.3f}"
            f"{' (best so far)' if is_best else ''}",
            flush=True,
        )
        return result

    def install_best(self) -> dict[str, Any] | None:
        """Copy the best policy to the run's ``model.zip`` / ``vecnormalize.pkl``; returns its validation."""
        best = self.dir / BEST_DIR
        if self.best is None or not (best / MODEL_FILE).is_file():
            return None
        for name in (MODEL_FILE, VECNORM_FILE):
            if (best / name).is_file():
                _copy_atomically(best / name, self.run_dir / name)
        return self.best

    def close(self) -> None:
        if self._env is not None:
            self._env.close()
            self._env = None


def _copy_atomically(source: Path, target: Path) -> None:
    def copy(tmp: str) -> None:
        shutil.copyfile(source, tmp)

    atomic_save(copy, target, target.suffix)


def _move_dir(source: Path, target: Path) -> None:
    """``source`` becomes ``target`` (renamed, on one file system); the old ``target`` goes after."""
    old = target.with_name(target.name + ".old")
    if old.exists():
        shutil.rmtree(old)
    if target.exists():
        target.rename(old)
    source.rename(target)
    if old.exists():
        shutil.rmtree(old)


def make_selection_callback(selector: Selector):
    from stable_baselines3.common.callbacks import BaseCallback

    class ValidateEvery(BaseCallback):
        """Validates the policy at the first rollout start at or past each multiple of ``every`` env
        steps: right after an update, so each validation scores the policy as it is at that step
        count, and the final policy (after the last update) is a step count of its own (a resumed
        run keeps the schedule of the run it continues)."""

        def __init__(self):
            super().__init__()
            self.every = selector.settings["every"]
            self.next_at = self.every

        def _on_training_start(self) -> None:
            self.next_at = (int(self.model.num_timesteps) // self.every + 1) * self.every

        def _on_rollout_start(self) -> None:
            steps = int(self.model.num_timesteps)
            if steps >= self.next_at:
                self.next_at = (steps // self.every + 1) * self.every
                if steps not in selector.validated_steps:
                    selector.validate(self.model)

        def _on_step(self) -> bool:
            return True

    return ValidateEvery()
