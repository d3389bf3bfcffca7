"""A simplified Wolfgang-OP (footsim's model before the URDF-faithful one, kept for comparisons).

Every number comes from the public sources listed in ``shared/FACTS.md`` (URDF masses, centres of
mass, inertia tensors, joint origins and limits, servo classes); where FACTS gives none, the
choice is stated beside it.  The schema these figures fill is :mod:`footsim.robots.spec`.
"""

from __future__ import annotations

import math

from footsim.robots.spec import (
    ARM_JOINTS,
    HEAD_JOINTS,
    MIRRORED_JOINTS,
    Box,
    Capsule,
    Cylinder,
    Inertial,
    Joint,
    Link,
    Origin,
    RobotSpec,
    Sphere,
    box_inertia,
    scaled_servo,
    side_prefix,
    stance_pose,
)
from footsim.robots.wolfgang import FOOT_LENGTH, FOOT_WIDTH, STEP_LIMITS, TORSO_FOOTPRINT
from footsim.walk.footsteps import Side
from footsim.walk.ik import LEG_JOINTS, LegGeometry

# Joint limits of the real robot (left side, its own sign convention), FACTS.md.
_REAL_LEFT_LEG_LIMITS = {
    "HipYaw": (-1.5708, 1.5708),
    "HipRoll": (-1.6, 1.9),
    "HipPitch": (-0.79, 2.77),
    "Knee": (-0.2, 2.8),
    "AnklePitch": (-1.42, 0.37),
    "AnkleRoll": (-1.58, 1.4),
}
# Sign mapping real -> ours, inferred from the real walk-ready pose (HipPitch +16.9° and
# Knee +63.8° crouch, AnklePitch -31.9° keeps the foot flat; HipRoll and AnkleRoll both +5.8°
# spread the feet and keep them flat).  In our convention a crouch is HipPitch < 0, Knee > 0,
# AnklePitch < 0, and a flat, outward-spread left foot is HipRoll > 0, AnkleRoll < 0.  So hip
# pitch and ankle roll flip sign, the others keep it.  The walking workspace lies well inside
# these ranges (checked in tests/test_robot_models.py).
_REAL_TO_OURS_SIGN = {"HipYaw": 1, "HipRoll": 1, "HipPitch": -1, "Knee": 1, "AnklePitch": 1, "AnkleRoll": -1}

LEG_EFFORT = {"HipYaw": 10.0, "HipRoll": 10.0, "HipPitch": 10.0, "Knee": 12.9, "AnklePitch": 10.0, "AnkleRoll": 10.0}
LEG_VELOCITY = {"HipYaw": 5.76, "HipRoll": 5.76, "HipPitch": 5.76, "Knee": 3.87, "AnklePitch": 5.76, "AnkleRoll": 5.76}
UPPER_BODY_EFFORT, UPPER_BODY_VELOCITY = 7.3, 8.17

# Our choices where FACTS gives no number (left side; right mirrored): arms may swing fully in
# pitch, abduct up to straight up and adduct a little; the elbow flexes (negative: forearm
# forward) 90° and over-extends 60° (the real ±1.5708/1.0472 servo range); the head pans ±90°
# and tilts 0.5 rad up / 1.2 rad down.
_LEFT_UPPER_BODY_LIMITS = {
    "ShoulderPitch": (-math.pi, math.pi),
    "ShoulderRoll": (-0.3, math.pi),
    "Elbow": (-1.5708, 1.0472),
    "HeadPan": (-1.5708, 1.5708),
    "HeadTilt": (-0.5, 1.2),
}

LEG_DIMENSIONS = LegGeometry.straight()  # 0.055 / 0.0414 / 0.169 / 0.170 / 0.0529 (FACTS.md)
HIP_OFFSET_Y, HIP_OFFSET_Z, THIGH, SHIN, ANKLE_TO_SOLE = 0.055, 0.0414, 0.169, 0.170, 0.0529
# The foot plate is 3.5 mm on the real robot (plus 14 mm cleats).  We model a 10 mm plate as a
# stand-in for plate + cleats: thicker boxes give MuJoCo/Bullet more robust box-plane contacts.
# The sole (bottom face) stays 0.0529 below the ankle axes either way.
SIM_FOOT_THICKNESS = 0.010
FOOT_CLEATS_MASS = 4 * 0.00166  # four 1.66 g cleats per foot, folded into the foot link


def _limits(joint: str, side: Side) -> tuple[float, float]:
    if joint in _REAL_LEFT_LEG_LIMITS:
        lo, hi = _REAL_LEFT_LEG_LIMITS[joint]
        sign = _REAL_TO_OURS_SIGN[joint]
        lo, hi = sorted((sign * lo, sign * hi))
    else:
        lo, hi = _LEFT_UPPER_BODY_LIMITS[joint]
    if side is Side.RIGHT and joint in MIRRORED_JOINTS:
        lo, hi = -hi, -lo
    return lo, hi


# Walk-ready stance: the walk engine's default trunk height and foot distance (WalkParams).
# This reproduces the real robot's stance (hip roll ≈ 6.6° vs. 5.8° there, a 64° knee bend).
WALK_READY_TRUNK_HEIGHT = 0.3948
WALK_READY_FOOT_DISTANCE = 0.1799
# Arms hang with the elbows bent 36° forward (FACTS' elbow angle; the real shoulder's 75° is in
# a frame we do not model, so our arms hang straight down from the shoulder).
WALK_READY_UPPER_BODY = {
    "ShoulderPitch": 0.0,
    "ShoulderRoll": 0.0,
    "Elbow": -math.radians(36.0),
    "HeadPan": 0.0,
    "HeadTilt": 0.0,
}


def wolfgang_simplified() -> RobotSpec:
    """Wolfgang-OP (Hamburg Bit-Bots), public numbers from ``shared/FACTS.md``.

    Simplifications (documented so the backends know): the real knee's built-in 15° offset and
    the sole's 0.021 m forward offset from the ankle axis are dropped, so the legs are the pure
    chain of :class:`LegGeometry`; masses are the URDF's (each foot includes its four cleats,
    which brings the total to the URDF's 6.117 kg), inertias are those of solid boxes of each
    link's size except the torso (the public tensor about the COM); collision shapes are boxes
    and capsules; the foot plate is 10 mm thick (see ``SIM_FOOT_THICKNESS``).
    """
    legs = LEG_DIMENSIONS
    grey, dark, light = (0.55, 0.57, 0.58, 1.0), (0.28, 0.30, 0.32, 1.0), (0.75, 0.75, 0.72, 1.0)
    links: list[Link] = [
        Link(
            "torso",
            # COM 0.110 m above the base (FACTS); inertia tensor of the public URDF's torso.
            Inertial(
                2.084, (0.0, 0.0, 0.110), (0.0183896, 0.0158772, 0.00780317, -6.80173e-05, -0.00140827, 0.000104074)
            ),
            (
                Box((0.12, 0.15, 0.0825), Origin((0.0, 0.0, 0.04125))),  # hip servo bay
                Box((0.15, 0.125, 0.115), Origin((0.0, 0.0, 0.14))),  # main body (FACTS)
            ),
            grey,
        ),
        Link(
            "neck",
            Inertial(0.148, (0.0, 0.0, 0.02), box_inertia(0.148, (0.04, 0.05, 0.04))),
            (Cylinder(0.02, 0.04, Origin((0.0, 0.0, 0.02))),),
            dark,
        ),
        Link(
            "head",
            Inertial(0.301, (0.01, 0.0, 0.055), box_inertia(0.301, (0.09, 0.11, 0.10))),
            (Sphere(0.055, Origin((0.01, 0.0, 0.06))),),
            light,
        ),
    ]
    joints: list[Joint] = [
        Joint(
            "HeadPan",
            "torso",
            "neck",
            (0, 0, 1),
            *_limits("HeadPan", Side.LEFT),
            UPPER_BODY_EFFORT,
            UPPER_BODY_VELOCITY,
            scaled_servo(UPPER_BODY_EFFORT),
            Origin((0.0, 0.0, 0.2)),
        ),
        Joint(
            "HeadTilt",
            "neck",
            "head",
            (0, 1, 0),
            *_limits("HeadTilt", Side.LEFT),
            UPPER_BODY_EFFORT,
            UPPER_BODY_VELOCITY,
            scaled_servo(UPPER_BODY_EFFORT),
            Origin((0.0, 0.0, 0.04)),
        ),
    ]
    for side in (Side.LEFT, Side.RIGHT):
        s, p, lower = side.sign, side_prefix(side), side.value[0]  # +1/-1, "L"/"R", "l"/"r"

        def joint(name, parent, child, axis, xyz, effort, velocity, p=p, side=side):
            return Joint(
                p + name, parent, child, axis, *_limits(name, side), effort, velocity, scaled_servo(effort), Origin(xyz)
            )

        # Arms: shoulder at the top corner of the torso, upper arm 0.144 m, forearm to the wrist 0.225 m.
        links += [
            Link(
                f"{lower}_shoulder",
                Inertial(0.041, (0.0, s * 0.02, 0.0), box_inertia(0.041, (0.03, 0.04, 0.03))),
                (Box((0.03, 0.04, 0.03), Origin((0.0, s * 0.02, 0.0))),),
                dark,
            ),
            Link(
                f"{lower}_upper_arm",
                Inertial(0.229, (0.0, 0.0, -0.07), box_inertia(0.229, (0.05, 0.05, 0.144))),
                (Capsule(0.025, 0.094, Origin((0.0, 0.0, -0.072))),),
                grey,
            ),
            Link(
                f"{lower}_lower_arm",
                Inertial(0.208, (0.0, 0.0, -0.09), box_inertia(0.208, (0.04, 0.04, 0.2))),
                (Capsule(0.02, 0.165, Origin((0.0, 0.0, -0.1225))),),
                grey,
            ),
        ]
        effort, velocity = UPPER_BODY_EFFORT, UPPER_BODY_VELOCITY
        joints += [
            joint("ShoulderPitch", "torso", f"{lower}_shoulder", (0, 1, 0), (0.0, s * 0.0765, 0.2), effort, velocity),
            joint(
                "ShoulderRoll",
                f"{lower}_shoulder",
                f"{lower}_upper_arm",
                (1, 0, 0),
                (0.0, s * 0.042, 0.0),
                effort,
                velocity,
            ),
            joint("Elbow", f"{lower}_upper_arm", f"{lower}_lower_arm", (0, 1, 0), (0.0, 0.0, -0.144), effort, velocity),
        ]
        # Legs: the pure LegGeometry chain.  The lower legs and feet collide with the other leg's.
        plate_z = -ANKLE_TO_SOLE + SIM_FOOT_THICKNESS / 2.0
        foot_mass = 0.268 + FOOT_CLEATS_MASS
        links += [
            Link(
                f"{lower}_hip_1",
                Inertial(0.069, (0.0, 0.0, -0.02), box_inertia(0.069, (0.05, 0.04, 0.04))),
                (Box((0.05, 0.04, 0.03), Origin((0.0, 0.0, -0.015))),),
                dark,
            ),
            Link(
                f"{lower}_hip_2",
                Inertial(0.320, (0.0, 0.0, -0.01), box_inertia(0.320, (0.06, 0.05, 0.07))),
                (Box((0.06, 0.05, 0.07), Origin((0.0, 0.0, -0.005))),),
                dark,
            ),
            Link(
                f"{lower}_upper_leg",
                Inertial(0.242, (0.0, 0.0, -0.11), box_inertia(0.242, (0.05, 0.05, THIGH))),
                (Capsule(0.025, 0.10, Origin((0.0, 0.0, -THIGH / 2))),),
                grey,
            ),
            Link(
                f"{lower}_lower_leg",
                Inertial(0.088, (0.0, 0.0, -0.06), box_inertia(0.088, (0.04, 0.04, SHIN))),
                (Capsule(0.022, 0.10, Origin((0.0, 0.0, -SHIN / 2)), self_collision=True),),
                grey,
            ),
            Link(
                f"{lower}_ankle",
                Inertial(0.320, (0.0, 0.0, 0.0), box_inertia(0.320, (0.06, 0.05, 0.07))),
                (Box((0.06, 0.05, 0.06), Origin((0.0, 0.0, 0.005)), self_collision=True),),
                dark,
            ),
            Link(
                f"{lower}_foot",
                Inertial(foot_mass, (0.0, 0.0, -0.035), box_inertia(foot_mass, (0.154, 0.106, 0.03))),
                (Box((0.154, 0.106, SIM_FOOT_THICKNESS), Origin((0.0, 0.0, plate_z)), self_collision=True),),
                light,
            ),
        ]
        le, lv = LEG_EFFORT, LEG_VELOCITY
        joints += [
            joint(
                "HipYaw",
                "torso",
                f"{lower}_hip_1",
                (0, 0, 1),
                (0.0, s * HIP_OFFSET_Y, 0.0),
                le["HipYaw"],
                lv["HipYaw"],
            ),
            joint(
                "HipRoll",
                f"{lower}_hip_1",
                f"{lower}_hip_2",
                (1, 0, 0),
                (0.0, 0.0, -HIP_OFFSET_Z),
                le["HipRoll"],
                lv["HipRoll"],
            ),
            joint(
                "HipPitch",
                f"{lower}_hip_2",
                f"{lower}_upper_leg",
                (0, 1, 0),
                (0.0, 0.0, 0.0),
                le["HipPitch"],
                lv["HipPitch"],
            ),
            joint(
                "Knee",
                f"{lower}_upper_leg",
                f"{lower}_lower_leg",
                (0, 1, 0),
                (0.0, 0.0, -THIGH),
                le["Knee"],
                lv["Knee"],
            ),
            joint(
                "AnklePitch",
                f"{lower}_lower_leg",
                f"{lower}_ankle",
                (0, 1, 0),
                (0.0, 0.0, -SHIN),
                le["AnklePitch"],
                lv["AnklePitch"],
            ),
            joint(
                "AnkleRoll",
                f"{lower}_ankle",
                f"{lower}_foot",
                (1, 0, 0),
                (0.0, 0.0, 0.0),
                le["AnkleRoll"],
                lv["AnkleRoll"],
            ),
        ]

    walk_ready = stance_pose(legs, WALK_READY_TRUNK_HEIGHT, WALK_READY_FOOT_DISTANCE)
    for side in (Side.LEFT, Side.RIGHT):
        for joint_name, angle in WALK_READY_UPPER_BODY.items():
            if joint_name.startswith("Head"):
                walk_ready[joint_name] = angle
            else:
                mirrored = side is Side.RIGHT and joint_name in MIRRORED_JOINTS
                walk_ready[side_prefix(side) + joint_name] = (-angle if mirrored else angle) + 0.0

    # Order joints as the real robot lists them: legs, arms, head.
    order = [side_prefix(sd) + j for sd in (Side.LEFT, Side.RIGHT) for j in LEG_JOINTS]
    order += [side_prefix(sd) + j for sd in (Side.LEFT, Side.RIGHT) for j in ARM_JOINTS]
    order += list(HEAD_JOINTS)
    joints.sort(key=lambda j: order.index(j.name))

    return RobotSpec(
        name="wolfgang_simplified",
        step_limits=STEP_LIMITS,  # the planar figures are the URDF robot's
        foot_length=FOOT_LENGTH,
        foot_width=FOOT_WIDTH,
        foot_thickness=SIM_FOOT_THICKNESS,
        torso_footprint=TORSO_FOOTPRINT,
        base_link="torso",
        links=tuple(links),
        joints=tuple(joints),
        soles={
            "left": ("l_foot", Origin((0.0, 0.0, -ANKLE_TO_SOLE))),
            "right": ("r_foot", Origin((0.0, 0.0, -ANKLE_TO_SOLE))),
        },
        walk_ready=walk_ready,
    )
