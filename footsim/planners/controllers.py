"""``make_controller``: a baseline controller from a ``controller`` config."""

from __future__ import annotations

from footsim.planners.footstep import FootstepController
from footsim.planners.velocity import VelocityController


def make_controller(env, cfg: dict):
    """A baseline controller for ``env`` from a ``controller`` config (``name`` + parameters)."""
    cfg = dict(cfg)
    name = cfg.pop("name", None)
    if name == "velocity":
        return VelocityController.from_env(env, cfg)
    if name == "footstep":
        return FootstepController.from_env(env, cfg)
    raise ValueError(f"unknown baseline controller {name!r}; valid: velocity, footstep")
