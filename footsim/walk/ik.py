"""Analytic leg inverse / forward kinematics (issue 3 fills in IK and FK).

Shared kinematic convention (the robot model builders follow the same one):
base (trunk) frame x forward, y left, z up, origin at the centre of the bottom of the torso.
Joint zero = straight leg, foot flat and parallel to the base.  Axes in the zero pose, in the
base frame, for both legs: HipYaw +z, HipRoll +x, HipPitch +y, Knee +y, AnklePitch +y,
AnkleRoll +x; chain order HipYaw → HipRoll → HipPitch → Knee → AnklePitch → AnkleRoll.
The sole frame (the IK target) is the centre of the bottom of the foot plate, directly below
the ankle axes.
"""

from __future__ import annotations

from dataclasses import dataclass

LEG_JOINTS = ("HipYaw", "HipRoll", "HipPitch", "Knee", "AnklePitch", "AnkleRoll")


@dataclass(frozen=True)
class LegGeometry:
    """Leg chain lengths [m] (Wolfgang-OP defaults from FACTS.md)."""

    hip_offset_y: float = 0.055  # HipYaw axis from the base origin, ±y
    hip_offset_z: float = 0.0414  # HipRoll/HipPitch axes below the HipYaw joint
    thigh: float = 0.169  # HipPitch → Knee
    shin: float = 0.170  # Knee → AnklePitch
    ankle_to_sole: float = 0.0529  # AnkleRoll → sole frame
