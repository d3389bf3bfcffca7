"""footsim: footstep-planning RL for a small humanoid on four simulators behind one interface.

``import footsim`` registers ``footsim/FootstepNav-v1`` (the Wolfgang-OP of its public URDF, the
Bit-Bots' gait and physics settings) and ``footsim/FootstepNav-v0`` (footsim 0.x's simplified robot
and tuned settings, for comparisons) with gymnasium and stays light: the simulators, torch and
stable-baselines3 are imported only where they are used.
"""

import gymnasium

__version__ = "0.1.0"

if "footsim/FootstepNav-v1" not in gymnasium.registry:
    gymnasium.register(id="footsim/FootstepNav-v1", entry_point="footsim.env:FootstepEnv")
if "footsim/FootstepNav-v0" not in gymnasium.registry:
    gymnasium.register(id="footsim/FootstepNav-v0", entry_point="footsim.env:footstep_nav_v0")


def make_env(*args, **kwargs):
    """Build a ``FootstepEnv`` from a composed Hydra config (see ``footsim.env.make_env``)."""
    from footsim.env import make_env as _make_env

    return _make_env(*args, **kwargs)
