"""Tiny ``footsim-train`` budgets for the tests that run the command line (PPO on two envs, one
epoch of 64-step batches, no progress bar): the overrides in one place."""

from __future__ import annotations


def tiny_training(total_timesteps: int, *extra: str, tensorboard: bool = False) -> list[str]:
    """The overrides of a tiny training of ``total_timesteps`` steps, then ``extra``."""
    out = [
        f"train.total_timesteps={total_timesteps}",
        "train.n_envs=2",
        "agent.n_steps=64",
        "agent.batch_size=64",
        "agent.n_epochs=1",
        "train.progress_bar=false",
    ]
    if not tensorboard:
        out.append("train.tensorboard=false")
    return out + list(extra)
