"""Walking: planar footstep geometry, walk parameters (and, from issue 3, the quintic engine and leg IK)."""

from footsim.walk.footsteps import DoubleStep, FeetState, Footstep, FootstepGeometry, Side, StepLimits
from footsim.walk.params import WalkParams

__all__ = ["DoubleStep", "FeetState", "Footstep", "FootstepGeometry", "Side", "StepLimits", "WalkParams"]
