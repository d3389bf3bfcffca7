"""Walking: planar footstep geometry, walk parameters, the quintic walk engine and leg IK/FK."""

from footsim.walk.engine import QuinticWalk, WalkState, WalkTrajectory
from footsim.walk.footsteps import DoubleStep, FeetState, Footstep, FootstepGeometry, Side, StepLimits
from footsim.walk.ik import LEG_JOINT_NAMES, LegGeometry, leg_fk, leg_ik
from footsim.walk.params import WalkParams

__all__ = [
    "LEG_JOINT_NAMES",
    "DoubleStep",
    "FeetState",
    "Footstep",
    "FootstepGeometry",
    "LegGeometry",
    "QuinticWalk",
    "Side",
    "StepLimits",
    "WalkParams",
    "WalkState",
    "WalkTrajectory",
    "leg_fk",
    "leg_ik",
]
