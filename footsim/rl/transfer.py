"""Transfer learning: start a run from another run's policy (``footsim-train init_from=RUN_DIR``).

Policy and value weights (Gaussian or Beta) are copied, and the parent's observation
normalization statistics when both runs normalize observations.  The backend may differ —
that is the point (2D → 3D, MuJoCo → PyBullet) — but the action space, the action
distribution and the network shapes must match.  One observation change is allowed: a run
without obstacles (17-D) can seed a run with obstacles (53-D), whose observation starts with
the same 17 values; the 36 ray inputs then start with zero weights, so the child begins as
the parent's goal-reaching policy and learns to use the rays (a curriculum that avoids the
"stand still, never collide" local optimum of the obstacle task).  The same holds for the
3 IMU inputs of ``task.observe_imu`` (17 → 20, or 17 → 56 with rays): a 2D policy seeds a 3D
run that observes its trunk tilt.
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
    if model.action_space.shape != parent.action_space.shape:
        raise ValueError(f"init_from: the action spaces differ: parent {parent.action_space.shape} "
                         f"vs this run {model.action_space.shape}")
    ours, theirs = model.observation_space.shape, parent.observation_space.shape
    expand = ours != theirs
    if expand and not (len(ours) == len(theirs) == 1 and theirs[0] == OBS_WITHOUT_RAYS and ours[0] > theirs[0]):
        raise ValueError(
            f"init_from: the observation spaces differ: parent {theirs} vs this run {ours} "
            f"(only a {OBS_WITHOUT_RAYS}-D obstacle-free parent can seed a larger observation with rays)"
        )
    if type(parent.policy) is not type(model.policy):
        raise ValueError(
            f"init_from: the parent's policy is {type(parent.policy).__name__}, this run's is "
            f"{type(model.policy).__name__}; choose the same agent distribution (agent=ppo or agent=ppo_beta)"
        )
    state = parent.policy.state_dict()
    if expand:
        state = _widen_first_layers(state, model.policy.state_dict())
    try:
        model.policy.load_state_dict(state)
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
        "observation_expanded": f"{theirs[0]} -> {ours[0]}" if expand else None,
    }


OBS_WITHOUT_RAYS = 17


def _widen_first_layers(parent_state: dict, child_state: dict) -> dict:
    """Copy the parent's weights; input layers get zero columns for the extra observation values."""
    out = {}
    for key, value in parent_state.items():
        target = child_state.get(key)
        if target is not None and value.dim() == 2 and target.shape[0] == value.shape[0] and target.shape[1] > value.shape[1]:
            widened = target.new_zeros(target.shape)
            widened[:, : value.shape[1]] = value
            value = widened
        out[key] = value
    return out
