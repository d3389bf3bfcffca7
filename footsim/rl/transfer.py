"""Transfer learning: start a run from another run's policy (``footsim-train init_from=RUN_DIR``).

Policy and value weights (Gaussian or Beta) are copied, and the parent's observation
normalization statistics when both runs normalize observations.  The backend may differ —
that is the point (2D → 3D, MuJoCo → PyBullet) — but the observation and action spaces, the
action distribution and the network shapes must match.
"""

from __future__ import annotations

from pathlib import Path

from footsim.rl.common import MODEL_FILE, VECNORM_FILE, load_run_config


def init_from_run(model, parent_dir: str | Path) -> dict:
    """Load ``parent_dir``'s weights into ``model``; returns the lineage record for the run dir."""
    import pickle

    from stable_baselines3 import PPO

    parent_dir = Path(parent_dir).expanduser().resolve()
    path = parent_dir / MODEL_FILE
    if not path.is_file():
        raise FileNotFoundError(f"init_from: no trained model at {path}")
    parent = PPO.load(path, device="cpu")
    for what in ("observation_space", "action_space"):
        ours, theirs = getattr(model, what), getattr(parent, what)
        if ours.shape != theirs.shape:
            raise ValueError(
                f"init_from: the {what.replace('_', ' ')}s differ: parent {theirs.shape} vs this run {ours.shape} "
                "(e.g. a task with obstacles has a 53-D observation, without 17-D)"
            )
    if type(parent.policy) is not type(model.policy):
        raise ValueError(
            f"init_from: the parent's policy is {type(parent.policy).__name__}, this run's is "
            f"{type(model.policy).__name__}; choose the same agent distribution (agent=ppo or agent=ppo_beta)"
        )
    try:
        model.policy.load_state_dict(parent.policy.state_dict())
    except RuntimeError as err:
        raise ValueError(f"init_from: the networks differ in shape (agent.net_arch must match the parent's): {err}") from None

    copied_stats = False
    venv = model.get_vec_normalize_env()
    stats_path = parent_dir / VECNORM_FILE
    if venv is not None and venv.norm_obs and stats_path.is_file():
        with open(stats_path, "rb") as fh:
            stats = pickle.load(fh)
        if getattr(stats, "norm_obs", False):
            venv.obs_rms = stats.obs_rms
            copied_stats = True
    parent_cfg = load_run_config(parent_dir)
    return {
        "init_from": str(parent_dir),
        "parent_backend": parent_cfg.backend.name,
        "parent_task": parent_cfg.task.name,
        "parent_num_timesteps": int(parent.num_timesteps),
        "copied_obs_normalization": copied_stats,
    }
