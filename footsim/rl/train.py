"""Training: ``footsim-train [overrides]`` — SB3 PPO on any backend, then an evaluation.

The run directory is Hydra's output dir.  It receives ``config.yaml`` (resolved), ``model.zip``,
``vecnormalize.pkl``, ``checkpoints/`` (written atomically every ``train.checkpoint_freq`` env
steps), TensorBoard logs in ``tb/``, and ``eval/`` with the evaluation results.
``footsim-train resume=RUN_DIR`` continues an interrupted run from its latest checkpoint.
With ``train.select.every=N`` the run's ``model.zip`` is its best policy on validation scenes, not
its last (``footsim.rl.selection``; ``checkpoints/latest.zip`` stays the last).
"""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from footsim.backends.base import BACKENDS, backend_class
from footsim.env import OUTCOMES, make_env
from footsim.rl.common import (
    CHECKPOINT_DIR,
    MODEL_FILE,
    learning_rate_schedule,
    load_run_config,
    policy_class,
    policy_kwargs,
    save_config,
    under_noise,
    validate_train_config,
    write_json,
    write_policy,
)
from footsim.rl.evaluate import evaluate_run
from footsim.rl.selection import Selector, make_selection_callback, select_config, validate_select
from footsim.rl.transfer import init_from_run, reset_log_std
from footsim.utils import atomic_save

LATEST = "latest.zip"
LATEST_VECNORM = "latest_vecnormalize.pkl"


def worker_seeds(seed: int, n_envs: int, resumed_at: int = 0) -> list[int]:
    """Independent seeds of a run's env workers, from ``SeedSequence((seed, resumed_at))``.

    Not SB3's ``seed + i``: with it run seed s + 1 would draw the scenes and noise of run s's workers
    1..n-1, so a study's seeds would share most of their episodes.  ``resumed_at`` (the steps a resumed
    run has done) gives a resume fresh streams instead of the run's first episodes again."""
    return [int(child.generate_state(1)[0]) for child in np.random.SeedSequence([seed, resumed_at]).spawn(n_envs)]


def seed_workers(venv, seed: int, resumed_at: int = 0) -> list[int]:
    """Give ``venv``'s workers :func:`worker_seeds`, used at their next reset (as ``VecEnv.seed``'s
    are).  Called after the model is built: SB3's model seeding sets ``seed + i`` again."""
    base = venv
    while hasattr(base, "venv"):  # VecNormalize and other wrappers
        base = base.venv
    if not hasattr(base, "_seeds"):
        raise RuntimeError(f"{type(base).__name__} has no per-env seeds (_seeds): stable-baselines3 changed its VecEnv")
    seeds = worker_seeds(seed, base.num_envs, resumed_at)
    base._seeds = seeds
    return seeds


def _env_factory(cfg: DictConfig, rank: int, worker_process: bool = False, resumed_at: int = 0):
    plain = OmegaConf.to_container(cfg, resolve=True)

    def make():
        from stable_baselines3.common.monitor import Monitor

        if worker_process:  # a terminal's Ctrl-C reaches the whole group: the trainer alone handles
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # it and closes its workers afterwards
        env = make_env(plain)
        replay = plain["train"].get("replay") or {}
        if replay.get("prob", 0.0):
            from footsim.rl.replay import FailedSceneReplay

            # its own stream per worker (and per resume: the replay buffer is not checkpointed)
            replay_seed = np.random.SeedSequence([int(plain["seed"]), resumed_at, rank, 1]).generate_state(1)[0]
            env = FailedSceneReplay(env, replay["prob"], replay["capacity"], seed=int(replay_seed))
        return Monitor(env)

    return make


def build_vec_env(cfg: DictConfig, resumed_at: int = 0):
    """The run's vectorized env (seed its workers with :func:`seed_workers` once the model exists)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

    n_envs = int(cfg.train.n_envs)
    kind = cfg.train.vec_env
    if kind == "auto":  # the 2D env is far cheaper than inter-process messaging
        kind = "dummy" if cfg.backend.name == "pymunk" or n_envs == 1 else "subproc"
    if kind == "subproc":  # a missing simulator: its clear ImportError here, not a worker's broken pipe
        import multiprocessing

        backend_class(cfg.backend.name)
        # Workers fork from a forkserver that has already imported torch (SB3's worker loop),
        # numba, the env and the simulator, so they share those pages: measured 153 MB PSS per
        # MuJoCo worker instead of 268 MB (docs/BENCHMARKS.md).  No effect once a forkserver runs.
        multiprocessing.set_forkserver_preload(
            ["stable_baselines3.common.vec_env", "footsim.env", BACKENDS[cfg.backend.name].target.split(":")[0]]
        )
    factories = [_env_factory(cfg, i, worker_process=kind == "subproc", resumed_at=resumed_at) for i in range(n_envs)]
    venv: VecEnv = DummyVecEnv(factories) if kind == "dummy" else SubprocVecEnv(factories, start_method="forkserver")
    if cfg.agent.normalize_reward or cfg.agent.normalize_obs:
        venv = VecNormalize(
            venv,
            norm_obs=bool(cfg.agent.normalize_obs),
            norm_reward=bool(cfg.agent.normalize_reward),
            gamma=float(cfg.agent.gamma),
        )
    return venv


class StopOnInterrupt:
    """While active, Ctrl-C only asks training to stop; the loop stops at its next env step.

    Raising KeyboardInterrupt wherever the signal lands could interrupt a checkpoint half
    written (torch's zip writer then fails).  A second Ctrl-C interrupts at once."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def _handle(self, signum, frame):
        self.requested = True
        signal.signal(signal.SIGINT, self._previous)
        print("\ninterrupt: stopping after the current step (Ctrl-C again to abort now)", flush=True)

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():  # signals are the main thread's
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        if self._previous is not None and not self.requested:
            signal.signal(signal.SIGINT, self._previous)
        return False


def _make_stop_callback(stop: StopOnInterrupt):
    from stable_baselines3.common.callbacks import BaseCallback

    class StopWhenRequested(BaseCallback):
        def _on_step(self) -> bool:
            return not stop.requested

    return StopWhenRequested()


def _make_checkpoint_callback(run_dir: Path, every: int):
    from stable_baselines3.common.callbacks import BaseCallback

    class AtomicCheckpoint(BaseCallback):
        """Saves model (and normalization stats) atomically, so an interruption never corrupts them,
        at the first step at or past each multiple of ``every`` env steps of the whole run (a resumed
        run keeps the schedule of the run it continues)."""

        def __init__(self):
            super().__init__()
            self.next_at = every

        def _on_training_start(self) -> None:
            self.next_at = (int(self.model.num_timesteps) // every + 1) * every

        def _on_step(self) -> bool:
            steps = int(self.model.num_timesteps)
            if steps >= self.next_at:
                self.next_at = (steps // every + 1) * every
                save_checkpoint(self.model, run_dir)
            return True

    return AtomicCheckpoint()


def _make_outcome_callback(window: int = 100):
    """Logs the share of each episode outcome over the last ``window`` finished training episodes
    as ``rollout/<outcome>_rate`` (TensorBoard): the return alone hides whether a policy succeeds,
    stands still until the timeout, or collides."""
    from collections import Counter, deque

    from stable_baselines3.common.callbacks import BaseCallback

    class OutcomeRates(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.recent: deque[str] = deque(maxlen=window)

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"]):
                if done and info.get("outcome", "running") != "running":
                    self.recent.append(info["outcome"])
            return True

        def _on_rollout_end(self) -> None:
            if self.recent:
                counts = Counter(self.recent)
                for outcome in OUTCOMES[1:]:
                    self.logger.record(f"rollout/{outcome}_rate", counts[outcome] / len(self.recent))

    return OutcomeRates()


def save_checkpoint(model, run_dir: Path) -> None:
    ckpt = run_dir / CHECKPOINT_DIR
    atomic_save(model.save, ckpt / LATEST, ".zip")
    venv = model.get_vec_normalize_env()
    if venv is not None:
        atomic_save(venv.save, ckpt / LATEST_VECNORM, ".pkl")
    write_json(ckpt / "latest.json", {"num_timesteps": int(model.num_timesteps), "time": time.time()})


def train(cfg: DictConfig, run_dir: Path) -> dict:
    """Train (or resume) and evaluate; returns the evaluation summary (the sweep objective)."""
    resume_dir = Path(cfg.resume).expanduser().resolve() if cfg.get("resume") else None
    if resume_dir is not None:
        cfg = load_run_config(resume_dir)
        run_dir = resume_dir
        if not (run_dir / CHECKPOINT_DIR / LATEST).is_file():
            raise FileNotFoundError(f"resume: no checkpoint in {run_dir / CHECKPOINT_DIR}")
    validate_train_config(cfg)  # a bad value fails here, before torch is imported
    validate_select(cfg)
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    run_dir.mkdir(parents=True, exist_ok=True)
    save_config(run_dir, cfg)
    torch.set_num_threads(1)  # small MLPs: threads cost more than they gain next to the env workers

    agent = cfg.agent
    if resume_dir is not None:
        from stable_baselines3.common.utils import set_random_seed

        model = PPO.load(run_dir / CHECKPOINT_DIR / LATEST, device="cpu")
        done = int(model.num_timesteps)
        venv = build_vec_env(cfg, resumed_at=done)
        if isinstance(venv, VecNormalize) and (run_dir / CHECKPOINT_DIR / LATEST_VECNORM).is_file():
            venv = VecNormalize.load(str(run_dir / CHECKPOINT_DIR / LATEST_VECNORM), venv.venv)
        model.set_env(venv)
        # torch's and numpy's streams (action sampling, minibatches) go on from the run's seed and its
        # steps, not from whatever this process had
        resumed_seed = int(np.random.SeedSequence([int(cfg.seed), done]).generate_state(1)[0])
        set_random_seed(resumed_seed)
        model.action_space.seed(resumed_seed)
        seed_workers(venv, int(cfg.seed), resumed_at=done)
        print(f"resuming {run_dir} at {done} of {cfg.train.total_timesteps} steps")
    else:
        venv = build_vec_env(cfg)
        model = PPO(
            policy_class(agent),
            venv,
            policy_kwargs=policy_kwargs(agent),
            learning_rate=learning_rate_schedule(agent),
            n_steps=int(agent.n_steps),
            batch_size=int(agent.batch_size),
            n_epochs=int(agent.n_epochs),
            gamma=float(agent.gamma),
            gae_lambda=float(agent.gae_lambda),
            clip_range=float(agent.clip_range),
            ent_coef=float(agent.ent_coef),
            vf_coef=float(agent.vf_coef),
            max_grad_norm=float(agent.max_grad_norm),
            tensorboard_log=str(run_dir / "tb") if cfg.train.tensorboard else None,
            seed=int(cfg.seed),
            device="cpu",
            verbose=0,
        )
        seed_workers(venv, int(cfg.seed))
        if cfg.get("init_from"):
            lineage = init_from_run(model, cfg.init_from, cfg.task)
            if agent.reset_log_std:
                lineage["log_std_reset_to"] = reset_log_std(model, float(agent.log_std_init))
            write_json(run_dir / "parent.json", lineage)
            print(f"initialised from {lineage['init_from']} ({lineage['parent_backend']}, {lineage['parent_task']})")
        done = 0
    remaining = int(cfg.train.total_timesteps) - done
    settings = select_config(cfg)
    selector = Selector(cfg, run_dir, settings) if settings else None
    started = time.time()
    if remaining > 0:
        from stable_baselines3.common.callbacks import CallbackList

        with StopOnInterrupt() as stop:
            callbacks = [
                _make_checkpoint_callback(run_dir, int(cfg.train.checkpoint_freq)),
                _make_outcome_callback(),
                _make_stop_callback(stop),
            ]
            if selector is not None:
                callbacks.append(make_selection_callback(selector))
            callback = CallbackList(callbacks)
            model.learn(
                total_timesteps=remaining,
                callback=callback,
                progress_bar=bool(cfg.train.progress_bar),
                reset_num_timesteps=resume_dir is None,
                tb_log_name="ppo",
            )
        if stop.requested:
            save_checkpoint(model, run_dir)
            venv.close()
            if selector is not None:
                selector.close()
            print(f"interrupted: checkpoint saved; continue with footsim-train resume={run_dir}", flush=True)
            raise SystemExit(130)  # the shell's code for Ctrl-C
    wall = time.time() - started
    write_policy(model, run_dir)
    save_checkpoint(model, run_dir)
    venv.close()
    info: dict[str, Any] = {
        "num_timesteps": int(model.num_timesteps),
        "wall_time_s": wall,
        "steps_per_s": remaining / wall if wall > 0 and remaining > 0 else None,
    }
    if selector is not None:  # the final policy is a candidate too; the best becomes model.zip
        try:
            if int(model.num_timesteps) not in selector.validated_steps:
                selector.validate(model)
            best = selector.install_best()
            assert best is not None  # validated just above
        finally:
            selector.close()
        info["selected"] = best
        print(f"selected the policy at {best['num_timesteps']} steps (validation success {best['success']:.3f})")
    write_json(run_dir / "train_info.json", info)
    print(f"trained {model.num_timesteps} steps in {wall:.0f} s; model: {run_dir / MODEL_FILE}")

    if not cfg.eval.after_train:
        return {}

    return evaluate_run(under_noise(cfg, cfg.eval.get("noise")), run_dir, run_dir / "eval", cfg.eval)
