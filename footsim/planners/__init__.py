"""Baseline controllers interchangeable with a trained policy in ``footsim-eval``.

* ``velocity``: inflated grid costmap + Lazy Theta* global plan + carrot local planner → velocity
  orders → the walk engine's velocity-order rule (thesis chapter 4).
* ``footstep``: anytime weighted A* over a footstep transition set (classical footstep planning).

Both observe only what the robot believes (``info["pose_estimate"]``), the scene's obstacles
(a known map) and the goal, and act through the env's 6-D action.  ``footsim.planners.controllers.make_controller``
builds one from a ``controller`` config.
"""
