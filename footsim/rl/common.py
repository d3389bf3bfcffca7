"""Shared pieces of training and evaluation: atomic files, model construction, policy loading."""

from __future__ import annotations

import contextlib
import json
import math
import os
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf, open_dict

from footsim.config import build_noise, build_task, plain_config, upgrade_run_config
from footsim.utils import atomic_save, atomic_write_text

MODEL_FILE = "model.zip"
VECNORM_FILE = "vecnormalize.pkl"
CONFIG_FILE = "config.yaml"
CHECKPOINT_DIR = "checkpoints"
#: The metrics of eval/summary.json that tables show first, in this order (other scalar keys follow).
SUMMARY_METRICS = (
    "episodes",
    "success",
    "timeout",
    "fall",
    "collision",
    "sim_error",
    "success_time_mean",
    "success_time_std",
    "success_steps_mean",
    "success_steps_std",
)


def write_json(path: str | os.PathLike, data) -> None:
    """Strict JSON, atomically: NaN and inf (e.g. the success time of a run without a success)
    become ``null``, which every JSON parser reads."""
    atomic_write_text(path, json.dumps(_finite_or_null(data), indent=2, default=float, allow_nan=False) + "\n")


def _finite_or_null(value):
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def save_config(run_dir: Path, cfg: DictConfig) -> None:
    atomic_write_text(run_dir / CONFIG_FILE, OmegaConf.to_yaml(cfg, resolve=True))


def load_run_config(run_dir: str | os.PathLike) -> DictConfig:
    """A run's resolved config, in today's keys (``footsim.config.upgrade_run_config``)."""

    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir} is not a footsim run directory: {CONFIG_FILE} is missing")
    cfg = OmegaConf.load(path)
    if not isinstance(cfg, DictConfig):
        raise ValueError(f"{path} is not a footsim run config: expected a mapping, got a list")
    return upgrade_run_config(cfg)


def validate_train_config(cfg: DictConfig) -> None:
    """Fail at start, naming the key, on values that cannot work."""
    positive_ints = {
        "train.total_timesteps": cfg.train.total_timesteps,
        "train.n_envs": cfg.train.n_envs,
        "train.checkpoint_freq": cfg.train.checkpoint_freq,
        "agent.n_steps": cfg.agent.n_steps,
        "agent.batch_size": cfg.agent.batch_size,
        "agent.n_epochs": cfg.agent.n_epochs,
        "eval.n_scenes": cfg.eval.n_scenes,
    }
    for key, value in positive_ints.items():
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise ValueError(f"{key} must be a positive integer, got {value!r}")
    for key in ("learning_rate", "gamma", "gae_lambda", "clip_range", "vf_coef", "max_grad_norm"):
        value = cfg.agent[key]
        if not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
            raise ValueError(f"agent.{key} must be a positive number, got {value!r}")
    if cfg.agent.gamma > 1 or cfg.agent.gae_lambda > 1:
        raise ValueError("agent.gamma and agent.gae_lambda must be <= 1")
    if cfg.agent.ent_coef < 0:
        raise ValueError(f"agent.ent_coef must be >= 0, got {cfg.agent.ent_coef!r}")
    if cfg.agent.get("lr_schedule", "constant") not in LR_SCHEDULES:
        raise ValueError(f"agent.lr_schedule must be one of {LR_SCHEDULES}, got {cfg.agent.lr_schedule!r}")
    if cfg.agent.activation not in ("tanh", "relu"):
        raise ValueError(f"agent.activation must be tanh or relu, got {cfg.agent.activation!r}")
    if cfg.agent.get("distribution", "gaussian") not in ("gaussian", "beta"):
        raise ValueError(f"agent.distribution must be gaussian or beta, got {cfg.agent.distribution!r}")
    if cfg.agent.get("beta_action", "mode") not in ("mode", "mean"):
        raise ValueError(f"agent.beta_action must be mode or mean, got {cfg.agent.beta_action!r}")
    if cfg.train.vec_env not in ("auto", "dummy", "subproc"):
        raise ValueError(f"train.vec_env must be auto, dummy or subproc, got {cfg.train.vec_env!r}")
    # the task's and the noise's own checks, here before the env workers (and torch) start
    build_task(plain_config(cfg.task))
    build_noise(plain_config(cfg.noise))
    replay = cfg.train.get("replay")
    if replay is not None:
        from footsim.rl.replay import check_replay

        check_replay(replay.get("prob"), replay.get("capacity"))
    for key, section in (("train.select.noise", cfg.train.get("select")), ("eval.noise", cfg.eval)):
        preset = (section or {}).get("noise")
        if preset is not None:
            try:
                under_noise(cfg, preset)
            except ValueError as err:
                raise ValueError(f"{key}: {err}") from None


def under_noise(cfg: DictConfig, preset: str | None) -> DictConfig:
    """``cfg`` with its noise replaced by the ``conf/noise`` preset (a copy); ``cfg`` itself for None.
    Validation and the evaluation after training may judge a run under another noise than it trained
    under (e.g. trained under a wider one, reported under the thesis's)."""
    if preset is None:
        return cfg
    from footsim.config import load_preset

    values = load_preset("noise", str(preset))
    build_noise(values)
    out = cfg.copy()
    with open_dict(out):
        out.noise = values
    return out


LR_SCHEDULES = ("constant", "linear")


def learning_rate_schedule(agent: DictConfig):
    """SB3's learning rate: a float (constant) or a function of the remaining share of the run
    (1 at the first update, 0 at the last): ``linear`` decays ``learning_rate`` to 0 over the run."""
    rate = float(agent.learning_rate)
    if agent.get("lr_schedule", "constant") == "constant":
        return rate
    return lambda progress_remaining: rate * progress_remaining


def policy_class(agent: DictConfig):
    """SB3 policy for the configured action distribution."""
    if agent.get("distribution", "gaussian") == "beta":
        from footsim.rl.beta import BetaActorCriticPolicy  # torch: imported by what trains or loads a policy

        return BetaActorCriticPolicy
    return "MlpPolicy"


def policy_kwargs(agent: DictConfig) -> dict:
    import torch

    kwargs = {
        "net_arch": {"pi": list(agent.net_arch.pi), "vf": list(agent.net_arch.vf)},
        "activation_fn": {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[agent.activation],
        "log_std_init": float(agent.log_std_init),
    }
    if agent.get("distribution", "gaussian") == "beta":
        kwargs["deterministic_action"] = str(agent.get("beta_action", "mode"))
    return kwargs


def write_policy(model, directory: Path) -> None:
    """``model`` and its normalization statistics as a run directory's policy files (atomically)."""
    from stable_baselines3.common.vec_env import VecNormalize

    directory.mkdir(parents=True, exist_ok=True)
    atomic_save(model.save, directory / MODEL_FILE, ".zip")
    venv = model.get_vec_normalize_env()
    if isinstance(venv, VecNormalize):
        atomic_save(venv.save, directory / VECNORM_FILE, ".pkl")
    elif (directory / VECNORM_FILE).exists():
        (directory / VECNORM_FILE).unlink()


@contextlib.contextmanager
def _random_state_kept():
    """Python's, numpy's and torch's global random states as they were before the block: loading a
    policy (SB3 re-seeds all three with the saved model's seed) must not change a training that
    validates a candidate, nor anything else that draws from them."""
    import random

    import torch

    python_state, numpy_state = random.getstate(), np.random.get_state()
    with torch.random.fork_rng():
        yield
    random.setstate(python_state)
    np.random.set_state(numpy_state)


class LoadedPolicy:
    """A trained run's policy as a function obs → action (with its observation normalization)."""

    def __init__(self, run_dir: str | os.PathLike, model_file: str = MODEL_FILE, beta_action: str | None = None):
        """``beta_action`` ("mode" or "mean"): a Beta policy's deterministic action instead of the one
        it was trained with (``agent.beta_action``); refused for a Gaussian policy."""
        from stable_baselines3 import PPO

        from footsim.rl.beta import BetaDistribution

        run_dir = Path(run_dir)
        path = run_dir / model_file
        if not path.is_file():
            raise FileNotFoundError(f"no trained model at {path}")
        with _random_state_kept():  # SB3's load seeds python's, numpy's and torch's global generators
            self.model = PPO.load(path, device="cpu")
        self.model.policy.set_training_mode(False)  # evaluation only: no module changes mode afterwards
        if beta_action is not None:
            dist = self.model.policy.action_dist
            if not isinstance(dist, BetaDistribution):
                raise ValueError(f"beta_action={beta_action}: the policy in {run_dir} is not a Beta policy")
            dist.deterministic_action = beta_action  # checked by the distribution
        self._act = self._deterministic_act()
        self.obs_rms = None
        vecnorm = run_dir / VECNORM_FILE
        if vecnorm.is_file():
            import pickle

            with open(vecnorm, "rb") as fh:
                stats = pickle.load(fh)
            if getattr(stats, "norm_obs", False):
                self.obs_rms, self.clip_obs, self.epsilon = stats.obs_rms, stats.clip_obs, stats.epsilon

    def __call__(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        if self.obs_rms is not None:
            obs = np.clip(
                (obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon), -self.clip_obs, self.clip_obs
            )
        if deterministic and self._act is not None:
            return self._act(obs)
        action, _ = self.model.predict(obs, deterministic=deterministic)
        return action

    def _deterministic_act(self):
        """``obs → model.predict(obs, deterministic=True)``, computed by the same torch operations in
        the same order, without what predict spends on every single observation (switching the
        modules' training mode, checking and converting the input, a distribution object per call):
        most of an evaluation's time in 2D; ``tests/test_zoo.py`` checks the two agree bit for bit.
        For the heads whose mode is a plain function of the action net's output on Box spaces (SB3's
        Gaussian without squashing: the mean; the Beta head: its mode); None for any other policy
        (then SB3's ``predict`` decides)."""
        import torch as th
        from gymnasium import spaces
        from stable_baselines3.common.distributions import DiagGaussianDistribution
        from stable_baselines3.common.preprocessing import preprocess_obs

        from footsim.rl.beta import BetaDistribution

        policy = self.model.policy
        obs_space, space = policy.observation_space, policy.action_space
        if not (isinstance(obs_space, spaces.Box) and isinstance(space, spaces.Box)):
            return None
        dist = policy.action_dist
        if isinstance(dist, DiagGaussianDistribution) and not policy.squash_output:
            head = policy.action_net
        elif isinstance(dist, BetaDistribution):

            def head(latent):
                return dist.mode_of(policy.action_net(latent))

        else:
            return None

        def act(obs: np.ndarray) -> np.ndarray:
            with th.no_grad():
                observation = th.as_tensor(np.array(obs).reshape((-1, *obs_space.shape)))
                features = policy.pi_features_extractor(preprocess_obs(observation, obs_space))
                action = head(policy.mlp_extractor.forward_actor(features))
            action = np.clip(action.numpy().reshape((-1, *space.shape)), space.low, space.high)
            return action.squeeze(axis=0) if np.ndim(obs) == len(obs_space.shape) else action

        return act
