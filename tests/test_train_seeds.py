"""A run's env workers draw independent streams: across training seeds and across a resume."""

from stable_baselines3 import PPO

from footsim import config as fconf
from footsim.rl.train import build_vec_env, seed_workers, worker_seeds


def _first_goals(seed: int, n_envs: int = 3, resumed_at: int = 0) -> list[tuple[float, float]]:
    """The goal each worker of a run resets to first, built as footsim-train builds it (the model's
    own seeding first, then the workers')."""
    cfg = fconf.compose("config", [f"train.n_envs={n_envs}", f"seed={seed}"])
    venv = build_vec_env(cfg, resumed_at=resumed_at)
    PPO("MlpPolicy", venv, n_steps=64, batch_size=64, seed=seed, device="cpu")  # sets seed + i, as SB3 does
    seed_workers(venv, seed, resumed_at)
    venv.reset()
    goals = [(round(g.x, 9), round(g.y, 9)) for g in (e.unwrapped.scene.goal for e in venv.venv.envs)]
    venv.close()
    return goals


def test_neighbouring_training_seeds_share_no_worker_stream():
    """With SB3's seed + i, run 1's workers 0 and 1 would reset to run 0's workers 1 and 2's goals."""
    run0, run1 = _first_goals(0), _first_goals(1)
    assert len(set(run0)) == 3 and not set(run0) & set(run1)
    assert _first_goals(0) == run0  # and a seed still fixes the run


def test_a_resume_continues_on_fresh_streams():
    assert not set(_first_goals(0, resumed_at=1024)) & set(_first_goals(0))


def test_worker_seeds_are_distinct_32_bit_words():
    seeds = [s for run in range(20) for s in worker_seeds(run, 8)]
    assert len(set(seeds)) == len(seeds) and all(0 <= s < 2**32 for s in seeds)
    assert worker_seeds(3, 8) == worker_seeds(3, 8) and worker_seeds(3, 8)[:4] == worker_seeds(3, 4)
