"""footsim: footstep-planning RL for a small humanoid on four simulators."""
