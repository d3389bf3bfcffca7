"""Baseline controllers interchangeable with a trained policy in ``footsim-eval``.

* ``velocity``: inflated grid costmap + Lazy Theta* global plan + carrot local planner → velocity
  orders → the walk engine's velocity-order rule (thesis chapter 4).
* ``footstep``: anytime weighted A* over a footstep transition set (classical footstep planning).

Both observe only what the robot believes (``info["pose_estimate"]``), the scene's obstacles
(a known map) and the goal, and act through the env's 6-D action.  ``make_controller`` builds
one from a ``controller`` config.
"""

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
