"""The robot spec: the single description of a humanoid that every backend's model comes from.

Issue 3 grows this into the full kinematic/inertial description (links, joints, limits,
collision shapes, walk-ready pose).  The planar task and the 2D backend need only the foot plate
and the footstep limits, which live here so that every backend reads the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from footsim.walk.footsteps import StepLimits


@dataclass(frozen=True)
class RobotSpec:
    name: str
    step_limits: StepLimits = field(default_factory=StepLimits)
    foot_length: float = 0.154  # sole plate, x [m]
    foot_width: float = 0.106  # sole plate, y [m]
    torso_footprint: tuple[float, float] = (0.15, 0.15)  # planar collision box of the trunk [m]


def wolfgang() -> RobotSpec:
    """Wolfgang-OP (Hamburg Bit-Bots), public numbers from ``shared/FACTS.md``."""
    return RobotSpec(name="wolfgang", step_limits=StepLimits(0.156, 0.103, 0.764))


ROBOTS = {"wolfgang": wolfgang}


def get_robot(name: str) -> RobotSpec:
    try:
        return ROBOTS[name]()
    except KeyError:
        raise ValueError(f"unknown robot {name!r}; valid robots: {sorted(ROBOTS)}") from None
