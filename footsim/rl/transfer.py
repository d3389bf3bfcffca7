"""Transfer learning: start a run from another run's policy (``footsim-train init_from=RUN_DIR``).

Policy and value weights (Gaussian or Beta) are copied, and the parent's observation
normalization statistics when both runs normalize observations.  The backend may differ —
that is the point (2D → 3D, MuJoCo → PyBullet) — but the action space, the action
distribution and the network shapes must match.  The observation may grow when the parent's
observation blocks (``NavTaskConfig.observation_layout``: goal and actions 17, rays, IMU 3,
path hint 2) begin the child's: the new inputs start with zero weights (and, with observation
normalization, mean 0 and variance 1), so the child begins as the parent's policy.  A run
without obstacles (17-D) seeds one with obstacles (53-D): a curriculum that avoids the "stand
still, never collide" local optimum of the obstacle task.
A 2D policy seeds a 3D run that observes its trunk tilt (17 → 20), an obstacle run one with the
global-path hint (53 → 55).
"""

from __future__ import annotations

import copy
import pickle
from pathlib import Path

import numpy as np

from footsim.rl.common import MODEL_FILE, VECNORM_FILE, load_run_config
from footsim.tasks.nav import observation_layout


def init_from_run(model, parent_dir: str | Path, task=None) -> dict:
    """Load ``parent_dir``'s weights into ``model``; returns the lineage record for the run dir.

    ``task`` (this run's task config) lets a parent seed a larger observation whenever the
    parent's observation blocks are a prefix of this run's (e.g. an obstacle run seeding one with
    the path hint); without it only a 17-D obstacle-free parent can seed a larger observation.
    """

    from stable_baselines3 import PPO

    parent_dir = Path(parent_dir).expanduser().resolve()
    path = parent_dir / MODEL_FILE
    if not path.is_file():
        raise FileNotFoundError(f"init_from: no trained model at {path}")
    parent = PPO.load(path, device="cpu")
    if model.action_space.shape != parent.action_space.shape:
        raise ValueError(
            f"init_from: the action spaces differ: parent {parent.action_space.shape} "
            f"vs this run {model.action_space.shape}"
        )
    ours, theirs = model.observation_space.shape, parent.observation_space.shape
    assert ours is not None and theirs is not None  # footsim's observation spaces are Boxes
    parent_cfg = load_run_config(parent_dir)
    expand = ours != theirs
    if expand:
        parent_layout = _layout(parent_cfg.get("task")) or (
            (("goal_and_actions", OBS_WITHOUT_RAYS),) if theirs == (OBS_WITHOUT_RAYS,) else None
        )
        our_layout = _layout(task)
        if our_layout is None and len(ours) == 1 and theirs == (OBS_WITHOUT_RAYS,):
            our_layout = parent_layout  # no task given: the historical rule, a 17-D parent widens
        prefix = (
            parent_layout is not None
            and our_layout is not None
            and len(ours) == 1
            and ours[0] > theirs[0]
            and our_layout[: len(parent_layout)] == parent_layout
        )
        if not prefix:
            raise ValueError(
                f"init_from: the observation spaces differ: parent {theirs} vs this run {ours} "
                f"(a parent can seed a larger observation only if its blocks {_names(parent_layout)} "
                f"begin this run's {_names(our_layout)})"
            )
    if type(parent.policy) is not type(model.policy):
        raise ValueError(
            f"init_from: the parent's policy is {type(parent.policy).__name__}, this run's is "
            f"{type(model.policy).__name__}; choose the same agent distribution (agent=ppo or agent=ppo_beta)"
        )
    venv = model.get_vec_normalize_env()
    stats_path = parent_dir / VECNORM_FILE
    stats = None
    if stats_path.is_file():
        with open(stats_path, "rb") as fh:
            stats = pickle.load(fh)
    parent_normalizes, child_normalizes = bool(getattr(stats, "norm_obs", False)), bool(venv and venv.norm_obs)
    if parent_normalizes != child_normalizes:  # the weights read inputs on another scale
        raise ValueError(
            f"init_from: the parent {'normalizes' if parent_normalizes else 'does not normalize'} its "
            f"observations and this run {'does' if child_normalizes else 'does not'}: set "
            f"agent.normalize_obs={str(parent_normalizes).lower()} as the parent trained"
        )
    state = parent.policy.state_dict()
    if expand:
        state = _widen_first_layers(state, model.policy.state_dict())
    try:
        model.policy.load_state_dict(state)
    except RuntimeError as err:
        raise ValueError(
            f"init_from: the networks differ in shape (agent.net_arch must match the parent's): {err}"
        ) from None

    copied_stats = False
    if venv is not None and stats is not None and child_normalizes and parent_normalizes:
        venv.obs_rms = _widen_obs_rms(stats.obs_rms, ours[0]) if expand else stats.obs_rms
        copied_stats = True
    return {
        "init_from": str(parent_dir),
        "parent_backend": parent_cfg.backend.name,
        "parent_task": parent_cfg.task.name,
        "parent_num_timesteps": int(parent.num_timesteps),
        "copied_obs_normalization": copied_stats,
        "observation_expanded": f"{theirs[0]} -> {ours[0]}" if expand else None,
    }


def reset_log_std(model, log_std: float) -> float:
    """Set a Gaussian policy's action log std to ``log_std`` in every dimension (after
    :func:`init_from_run`: a parent trained to convergence has a small std and barely explores a
    new task).  Returns ``log_std``; a Beta policy has no log std and is refused."""

    param = getattr(model.policy, "log_std", None)
    if param is None:
        raise ValueError(
            "agent.reset_log_std=true needs the Gaussian policy (agent=ppo); the Beta policy has no log std"
        )
    import torch

    with torch.no_grad():
        param.fill_(log_std)
    return log_std


OBS_WITHOUT_RAYS = 17


def _layout(task) -> tuple[tuple[str, int], ...] | None:
    """Observation blocks of a task config mapping (a run's ``task``); None if unknown."""

    if task is None or task.get("obstacles") is None:
        return None
    return observation_layout(
        bool(task["obstacles"]),
        int(task.get("n_rays", 36)),
        bool(task.get("observe_imu", False)),
        bool(task.get("path_hint", False)),
        int(task.get("observe_history", 0)),
    )


def _names(layout) -> str:
    return "unknown" if layout is None else "+".join(name for name, _ in layout)


def _widen_obs_rms(rms, size: int):
    """The parent's observation statistics for a larger observation: the new inputs get mean 0 and
    variance 1, so normalization passes them through unchanged (their input weights start at zero,
    so the child still begins as the parent's policy).  SB3's running statistics keep one count for
    all inputs, the parent's, so training moves the new inputs' mean and variance only as fast as
    the old ones' (a run as long as the parent's moves them half-way): they stay near unscaled,
    which the task's observations allow, each lying in [-1, 1] (tanh, sin and cos)."""
    widened = copy.deepcopy(rms)
    extra = size - rms.mean.shape[0]
    widened.mean = np.concatenate([rms.mean, np.zeros(extra, dtype=rms.mean.dtype)])
    widened.var = np.concatenate([rms.var, np.ones(extra, dtype=rms.var.dtype)])
    return widened


def _widen_first_layers(parent_state: dict, child_state: dict) -> dict:
    """Copy the parent's weights; input layers get zero columns for the extra observation values."""
    out = {}
    for key, value in parent_state.items():
        target = child_state.get(key)
        if (
            target is not None
            and value.dim() == 2
            and target.shape[0] == value.shape[0]
            and target.shape[1] > value.shape[1]
        ):
            widened = target.new_zeros(target.shape)
            widened[:, : value.shape[1]] = value
            value = widened
        out[key] = value
    return out
