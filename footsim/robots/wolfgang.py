"""Wolfgang-OP (Hamburg Bit-Bots) as in its public URDF: a :class:`~footsim.robots.spec.RobotSpec`.

The figures are the URDF's (``shared/FACTS.md``, "URDF: links", "URDF: joints", "Foot, sole and
cleats", "Servo and actuator models"; source bit-bots/bitbots_main ``wolfgang_description``):
every link's mass, centre of mass and full inertia tensor; every joint's origin (xyz + rpy),
axis, limits and servo class; the sole frames; the foot's sole plate and its four cleats.  Joint
angles are the URDF's own (its zeros include the knee's built-in 15°), so a pose from the
Bit-Bots' tools means the same here.

What is not the URDF (each choice stated beside its figure): the links' collision shapes other
than the feet are primitives (the URDF's meshes are not public figures); the cleats (fixed links
in the URDF) and the 0.1 g ``base_link`` are folded into the foot and torso links; the servo
model (:data:`SERVOS`) is the Bit-Bots' MuJoCo servo classes with the URDF's effort limits.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from footsim.robots.spec import (
    Box,
    Capsule,
    Cylinder,
    Inertial,
    Joint,
    Link,
    Origin,
    RobotSpec,
    ServoParams,
    Sphere,
    combined_inertial,
    stance_pose,
)
from footsim.walk.footsteps import StepLimits

# -- servos ------------------------------------------------------------------------------------
# Per motor type: the URDF's effort [Nm] and velocity [rad/s] limits and the Bit-Bots' MuJoCo
# servo class (position actuator kp [Nm/rad], joint damping [Nm s/rad], armature [kg m²],
# frictionloss [Nm]; bitbots_mujoco_sim wolfgang.xml classes mx64 / mx106 / xh-540).  Their
# MuJoCo model gives every actuator ±12 Nm; footsim keeps each servo's own URDF rating, which
# their PyBullet and Webots setups use too.
SERVOS = {
    "MX-64": (7.3, 8.17, ServoParams(kp=25.5, damping=0.66, armature=0.012, frictionloss=0.09)),
    "MX-106": (10.0, 5.76, ServoParams(kp=45.0, damping=1.7, armature=0.025, frictionloss=0.1)),
    "XH540-W270": (12.9, 3.87, ServoParams(kp=45.0, damping=1.7, armature=0.025, frictionloss=0.1)),
}
# The URDF's <dynamics> (damping [Nm s/rad], friction [Nm]) of each motor type, for reference: the
# Webots proto uses them; footsim's MuJoCo servo classes above replace them.
URDF_DYNAMICS = {"MX-64": (0.65, 1.73), "MX-106": (1.23, 2.55), "XH540-W270": (2.92, 1.49)}

# -- links: mass [kg], COM [m], inertia about the COM (ixx, iyy, izz, ixy, ixz, iyz) [kg m²] -------
LINKS = {
    "torso": (2.0839, (-0.00564376, -0.0026297, 0.109553), (0.0183896, 0.0158772, 0.00780317, -6.80173e-05, -0.00140827, 0.000104074)),  # noqa: E501
    "r_shoulder": (0.041445, (-0.0135397, 0.0284022, -1.54699e-06), (1.85473e-05, 2.76649e-05, 3.49573e-05, 7.63058e-06, -9.41386e-10, 8.71825e-10)),  # noqa: E501
    "r_upper_arm": (0.228498, (9.77435e-05, -0.0325821, -0.0239229), (0.000241455, 0.000179491, 0.000371127, 8.09479e-07, 7.57095e-08, -2.7985e-06)),  # noqa: E501
    "r_lower_arm": (0.207774, (0.000436307, -0.0605126, -0.0235553), (0.001088, 8.90324e-05, 0.00110076, -1.16188e-06, -5.01515e-09, -3.22666e-08)),  # noqa: E501
    "l_shoulder": (0.041445, (-0.0135397, 0.0284022, 1.54699e-06), (1.85473e-05, 2.76649e-05, 3.49573e-05, 7.63058e-06, 9.41386e-10, -8.71825e-10)),  # noqa: E501
    "l_upper_arm": (0.228498, (9.77435e-05, -0.0325821, -0.0239229), (0.000241455, 0.000179491, 0.000371127, 8.09479e-07, 7.57095e-08, -2.7985e-06)),  # noqa: E501
    "l_lower_arm": (0.207774, (-0.000436306, -0.0605126, -0.0235553), (0.001088, 8.90324e-05, 0.00110076, -1.14836e-05, 5.01178e-09, -3.22666e-08)),  # noqa: E501
    "r_hip_1": (0.0689735, (1.20984e-11, 0.010315, -1.06799e-07), (2.18955e-05, 0.00010714, 0.000110523, -2.44475e-14, 3.06793e-15, -6.56688e-11)),  # noqa: E501
    "r_hip_2": (0.319807, (1.38724e-05, -0.0155281, -0.0486407), (0.000268627, 0.000268049, 0.000121331, 6.08561e-08, 6.67248e-07, 3.87608e-06)),  # noqa: E501
    "r_upper_leg": (0.242311, (0.00493985, -0.0283223, -0.133144), (0.000501721, 0.000458929, 0.000113409, 8.33582e-06, 1.67743e-05, -4.68914e-06)),  # noqa: E501
    "r_lower_leg": (0.0880635, (0.00142428, 0.0183569, -0.0617082), (0.000284456, 0.000238908, 7.56932e-05, 8.11186e-07, -8.85963e-06, 2.73593e-05)),  # noqa: E501
    "r_ankle": (0.319807, (-0.0204557, -0.0155281, -0.0260036), (0.000116775, 0.000268473, 0.000272856, -4.53798e-06, 6.10986e-07, -7.45081e-07)),  # noqa: E501
    "r_foot": (0.26824, (0.0119697, 0.0911089, -0.0298585), (0.000884107, 0.00031783, 0.00115364, -3.29345e-05, 5.01436e-06, -1.77693e-05)),  # noqa: E501
    "l_hip_1": (0.0689735, (1.20984e-11, 0.010315, -1.06799e-07), (2.18955e-05, 0.00010714, 0.000110523, -2.44475e-14, 3.06793e-15, -6.56688e-11)),  # noqa: E501
    "l_hip_2": (0.319807, (-3.60783e-06, -0.0155281, -0.0486443), (0.000268673, 0.000268098, 0.000121333, -7.40992e-08, -6.18751e-07, 3.88325e-06)),  # noqa: E501
    "l_upper_leg": (0.242311, (-0.00463142, -0.132966, 0.0263223), (0.000495112, 0.000120828, 0.000454597, -2.80704e-05, 2.53373e-06, 4.33405e-06)),  # noqa: E501
    "l_lower_leg": (0.0880635, (0.00142428, -0.0188696, -0.0617069), (0.000284966, 0.000238923, 7.61706e-05, -1.11661e-06, -8.91127e-06, -2.54481e-05)),  # noqa: E501
    "l_ankle": (0.319807, (0.0204593, -0.0155281, -0.0260139), (0.000116773, 0.000268424, 0.00027281, 4.53857e-06, -6.75013e-07, -7.24073e-07)),  # noqa: E501
    "l_foot": (0.26824, (-0.0120399, 0.0911089, -0.0298585), (0.000884107, 0.000317378, 0.00115319, 3.21104e-05, -5.09223e-06, -1.77693e-05)),  # noqa: E501
    "neck": (0.148233, (0.0186912, -7.75177e-05, -0.0220143), (3.89355e-05, 5.76318e-05, 6.25414e-05, -5.28709e-07, 4.95698e-06, -2.28158e-08)),  # noqa: E501
    "head": (0.301358, (0.000411708, 0.0674937, -0.0200647), (0.000344265, 0.000333713, 0.000421898, -2.07263e-05, 1.05826e-06, 5.11722e-05)),  # noqa: E501
}  # fmt: skip
# The cleat links (1.66 g each, fixed to the foot): COM and inertia in the cleat frame; the cleat
# frames' positions in the foot frame (rpy 0 0 -pi/2 for all).
CLEAT = (0.00165976, (0.0, 0.000155519, -0.00775879), (4.3352e-08, 4.44049e-08, 3.04397e-08, 0.0, 0.0, -1.0993e-09))
CLEAT_FRAMES = {
    "r_foot": ((-0.03, -0.007, -0.034), (-0.03, 0.177, -0.034), (0.06, 0.177, -0.034), (0.06, -0.007, -0.034)),
    "l_foot": ((-0.06, -0.007, -0.034), (-0.06, 0.177, -0.034), (0.03, 0.177, -0.034), (0.03, -0.007, -0.034)),
}
CLEAT_RPY = (0.0, 0.0, -math.pi / 2)

# -- joints: parent, child, origin xyz, origin rpy, axis, lower, upper, motor --------------------
JOINTS = {
    "LHipYaw": ("torso", "l_hip_1", (1.82493e-15, 0.055, -4.22839e-18), (-1.5708, -0.0, 0.0), (0, 1, 0), -1.5708, 1.5708, "MX-106"),  # noqa: E501
    "LHipRoll": ("l_hip_1", "l_hip_2", (-0.046, 0.0414, 6.93889e-18), (3.14159, 1.5708, 0.0), (0, 0, -1), -1.6, 1.9, "MX-106"),  # noqa: E501
    "LHipPitch": ("l_hip_2", "l_upper_leg", (0.026, 6.93889e-18, -0.0691), (2.67116e-16, -1.5708, 0.0), (7.95491e-17, -3.00167e-16, -1.0), -0.79, 2.77, "MX-106"),  # noqa: E501
    "LKnee": ("l_upper_leg", "l_lower_leg", (0.00435596, -0.168793, 0.049), (1.5708, -4.90478e-17, 2.87979), (0, 1, 0), -0.2, 2.8, "XH540-W270"),  # noqa: E501
    "LAnklePitch": ("l_lower_leg", "l_ankle", (1.11022e-16, -0.0505, -0.17), (-1.5708, -1.45847e-15, 3.14159), (0, 0, -1), -1.42, 0.37, "MX-106"),  # noqa: E501
    "LAnkleRoll": ("l_ankle", "l_foot", (0.0691, 1.66533e-16, -0.026), (1.5708, -1.5708, 0.0), (0, -1, 0), -1.58, 1.4, "MX-106"),  # noqa: E501
    "RHipYaw": ("torso", "r_hip_1", (7.99361e-15, -0.055, 4.68375e-17), (-1.5708, -0.0, 0.0), (0, 1, 0), -1.5708, 1.5708, "MX-106"),  # noqa: E501
    "RHipRoll": ("r_hip_1", "r_hip_2", (-0.046, 0.0414, 6.93889e-18), (-3.14159, 1.5708, 0.0), (0, 0, -1), -1.9, 1.6, "MX-106"),  # noqa: E501
    "RHipPitch": ("r_hip_2", "r_upper_leg", (-0.0265, -9.71445e-17, -0.0691), (-1.5708, 1.5708, 0.0), (0, 1, 0), -2.77, 0.79, "MX-106"),  # noqa: E501
    "RKnee": ("r_upper_leg", "r_lower_leg", (-0.00392295, -0.051, -0.169043), (1.05132e-15, -0.261799, -2.52921e-15), (0, -1, 0), -2.8, 0.2, "XH540-W270"),  # noqa: E501
    "RAnklePitch": ("r_lower_leg", "r_ankle", (4.16334e-16, 0.0505, -0.17), (-1.5708, 4.23642e-15, 1.2925e-15), (0, 0, -1), -0.37, 1.42, "MX-106"),  # noqa: E501
    "RAnkleRoll": ("r_ankle", "r_foot", (-0.0691, -1.11022e-16, -0.026), (-1.46564e-14, 1.5708, -1.5708), (0, -1, 0), -1.4, 1.58, "MX-106"),  # noqa: E501
    "LShoulderPitch": ("torso", "l_shoulder", (-0.0015, 0.0765, 0.2035), (-3.14159, 1.66533e-16, 3.14159), (0, 1, 0), -3.14159, 3.14159, "MX-64"),  # noqa: E501
    "LShoulderRoll": ("l_shoulder", "l_upper_arm", (-0.01695, 0.042, -2.77556e-17), (-1.5708, -5.19331e-15, 1.5708), (0, 0, -1), -3.1416, 0.33, "MX-64"),  # noqa: E501
    "LElbow": ("l_upper_arm", "l_lower_arm", (-0.024, -0.144, -0.0235), (-1.5708, 3.08909e-14, 1.5708), (0, 0, 1), -1.5708, 0.78, "MX-64"),  # noqa: E501
    "RShoulderPitch": ("torso", "r_shoulder", (-0.0015, -0.0765, 0.2035), (-4.34612e-17, 1.66533e-15, -3.14159), (0, 1, 0), -3.14159, 3.14159, "MX-64"),  # noqa: E501
    "RShoulderRoll": ("r_shoulder", "r_upper_arm", (-0.01695, 0.042, 0.0), (1.5708, 8.32338e-16, -1.5708), (0, 0, -1), -0.33, 3.1416, "MX-64"),  # noqa: E501
    "RElbow": ("r_upper_arm", "r_lower_arm", (0.024, -0.144, -0.0235), (-1.5708, 1.27676e-15, -1.5708), (0, 0, 1), -0.78, 1.5708, "MX-64"),  # noqa: E501
    "HeadPan": ("torso", "neck", (-0.0095, 2.82644e-16, 0.2345), (-3.14159, 3.41087e-16, -4.44089e-16), (0, 0, -1), -2.35619, 2.35619, "MX-64"),  # noqa: E501
    "HeadTilt": ("neck", "head", (0.036, 0.0235, -0.024), (-1.5708, 3.17216e-15, -5.33479e-15), (0, 0, 1), -1.923, 1.24, "MX-64"),  # noqa: E501
}  # fmt: skip
# Sole frames in the foot links (URDF r_sole_frame / l_sole_frame).
SOLES = {
    "right": ("r_foot", Origin((0.0152219, 0.0907683, -0.0529), (0.0, 0.0, 1.5708))),
    "left": ("l_foot", Origin((-0.0152219, 0.0907683, -0.0529), (0.0, 0.0, 1.5708))),
}
# Foot contact geometry in the sole frame (FACTS "Foot, sole and cleats"): the sole plate
# (0.154 × 0.106 × 0.0035 m, bottom 13.4 mm above the sole frame) with strips extending it to
# x ∈ [−0.0948, 0.0942] (0.078 m wide), and per cleat a cylinder (r 6 mm, 10 mm long) ending in a
# sphere (r 6 mm) whose bottom is 2.9 mm above the sole frame.
PLATE_BOTTOM, PLATE_THICKNESS = 0.0134, 0.0035
PLATE = ((0.154, 0.106), (0.0012, 0.0002))
STRIPS = (((0.019, 0.078), (-0.0853, 0.0002)), ((0.016, 0.078), (0.0862, 0.0002)))
CLEAT_CENTRES = {
    "right": ((-0.0978, 0.0452), (0.0862, 0.0452), (0.0862, -0.0448), (-0.0978, -0.0448)),
    "left": ((-0.0978, 0.0448), (0.0862, 0.0448), (0.0862, -0.0452), (-0.0978, -0.0452)),
}
CLEAT_RADIUS, CLEAT_LENGTH, CLEAT_SPHERE_Z = 0.006, 0.010, 0.0089

# Walk-ready arms: upper arms hanging straight down, elbows bent 36° (FACTS' walk-ready elbow
# angle) with the forearms forward.  In this URDF the arm's zero is upper arm down, forearm
# horizontal (elbow at 90°), so a 36° bend is an elbow angle of -(90° - 36°) on the left.  FACTS'
# walk-ready ShoulderPitch of 75° would put the upper arms horizontal backwards here; it belongs to
# an older zero of that joint, so the shoulders stay at 0.
WALK_READY_ARMS = {"LElbow": -0.9425, "RElbow": 0.9425}
# The walk engine's neutral stance of walk=bitbots_sim: trunk height and foot distance [m].
WALK_READY_TRUNK_HEIGHT, WALK_READY_FOOT_DISTANCE = 0.3948, 0.1799

# The planar figures the 2D task uses too (FACTS: step limits, sole plate, torso footprint).
STEP_LIMITS = StepLimits(0.156, 0.103, 0.764)
FOOT_LENGTH, FOOT_WIDTH = 0.154, 0.106  # sole plate [m]
TORSO_FOOTPRINT = (0.15, 0.15)  # planar collision box of the trunk [m]
# The upper body's planar bounding box (torso, head and the arms at walk-ready: the forearms reach
# 0.142 m to each side and 0.164 m ahead, the torso's back 0.074 m behind), length x width [m] and
# its centre's offset ahead of the feet's mean pose, measured on the MuJoCo model standing
# (tests/test_robot_models.py checks it to 5 mm).
UPPER_BODY_FOOTPRINT = (0.238, 0.283, 0.045)

GREY, DARK, LIGHT = (0.55, 0.57, 0.58, 1.0), (0.28, 0.30, 0.32, 1.0), (0.75, 0.75, 0.72, 1.0)


def _to_foot(side: str, xyz, rpy=(0.0, 0.0, 0.0)) -> Origin:
    """A pose given in the sole frame of ``side``, expressed in its foot link's frame."""
    sole = SOLES[side][1].matrix
    local = Origin(xyz, rpy).matrix
    pose = sole @ local
    # Every sole-frame shape here is axis-aligned in the sole frame: the rpy is the sole's.
    return Origin(tuple(pose[:3, 3]), SOLES[side][1].rpy)


def _foot_shapes(side: str) -> tuple:
    z = PLATE_BOTTOM + PLATE_THICKNESS / 2.0
    shapes: list = []
    for (length, width), (cx, cy) in (PLATE, *STRIPS):
        shapes.append(Box((length, width, PLATE_THICKNESS), _to_foot(side, (cx, cy, z)), self_collision=True))
    for cx, cy in CLEAT_CENTRES[side]:
        shapes.append(Sphere(CLEAT_RADIUS, _to_foot(side, (cx, cy, CLEAT_SPHERE_Z)), self_collision=True))
        shapes.append(
            Cylinder(CLEAT_RADIUS, CLEAT_LENGTH, _to_foot(side, (cx, cy, CLEAT_SPHERE_Z + CLEAT_LENGTH / 2.0)))
        )
    return tuple(shapes)


def _segment(start, end, radius: float, self_collision: bool = False) -> Capsule:
    """A capsule from ``start`` to ``end`` (link frame), shortened by its caps."""
    a, b = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    z = axis / length
    x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    pose[:3, 3] = (a + b) / 2.0
    return Capsule(radius, max(length - 2 * radius, 1e-3), Origin.from_matrix(pose), self_collision)


def _child_point(link: str) -> tuple[float, float, float]:
    """Origin of the (first) joint below ``link``, in ``link``'s frame."""
    for parent, _child, xyz, *_ in JOINTS.values():
        if parent == link:
            return xyz
    raise KeyError(link)


def _shapes(link: str, side: str | None) -> tuple:
    """Collision primitives: the URDF's meshes are not public figures, so each limb is a capsule
    along the segment between its joints and each servo body a small box at its COM."""
    com = LINKS[link][1]
    if link == "torso":
        return (
            Box((0.12, 0.15, 0.0825), Origin((0.0, 0.0, 0.04125))),  # hip servo bay
            Box((0.15, 0.125, 0.115), Origin((0.0, 0.0, 0.14))),  # main body (FACTS)
        )
    if link == "neck":
        return (Box((0.04, 0.04, 0.04), Origin(com)),)
    if link == "head":
        return (Sphere(0.055, Origin(com)),)
    if link.endswith("_foot"):
        assert side is not None
        return _foot_shapes(side)
    if link.endswith(("_upper_leg", "_lower_leg", "_upper_arm")):
        radius = 0.025 if "leg" in link else 0.022
        return (_segment((0.0, 0.0, 0.0), _child_point(link), radius, self_collision=link.endswith("_lower_leg")),)
    if link.endswith("_lower_arm"):
        wrist = (0.0, -0.225, -0.0235)  # URDF wrist frame (r: -0.226182, l: -0.225182)
        return (_segment((0.0, 0.0, -0.0235), wrist, 0.02),)
    return (Box((0.05, 0.05, 0.05), Origin(com)),)  # shoulder, hip and ankle servo blocks


def _inertial(link: str, torso_extra_mass: float) -> Inertial:
    mass, com, inertia = LINKS[link]
    own = Inertial(mass, com, inertia)
    if link.endswith("_foot"):
        cleat = Inertial(*CLEAT)
        parts = [(own, np.eye(4))] + [(cleat, Origin(xyz, CLEAT_RPY).matrix) for xyz in CLEAT_FRAMES[link]]
        return combined_inertial(parts)
    if link == "torso" and torso_extra_mass:
        # Extra mass (cables, electronics the CAD lacks) at the torso's COM, scaling its tensor.
        scale = (mass + torso_extra_mass) / mass
        return Inertial(mass + torso_extra_mass, com, tuple(v * scale for v in own.inertia))
    return own


def _side_of(link: str) -> str | None:
    return {"l": "left", "r": "right"}.get(link.split("_")[0]) if "_" in link else None


def wolfgang(torso_extra_mass: float = 0.0) -> RobotSpec:
    """Wolfgang-OP from its public URDF (6.117 kg).

    ``torso_extra_mass`` [kg] adds mass at the torso's COM: the real robot weighs about 7.5 kg with
    cables (the thesis), and the Bit-Bots' MuJoCo model adds 1.0 kg there.  The default 0 is the
    URDF, which their PyBullet and Webots simulators load and which their simulator walk
    parameters were tuned on.
    """
    if not (math.isfinite(torso_extra_mass) and torso_extra_mass >= 0):
        raise ValueError(f"robot.torso_extra_mass must be a non-negative number [kg], got {torso_extra_mass!r}")
    links = [
        Link(name, _inertial(name, torso_extra_mass), _shapes(name, _side_of(name)), LIGHT if "foot" in name else GREY)
        for name in LINKS
    ]
    joints = []
    for name, (parent, child, xyz, rpy, axis, lower, upper, motor) in JOINTS.items():
        effort, velocity, servo = SERVOS[motor]
        joints.append(Joint(name, parent, child, axis, lower, upper, effort, velocity, servo, Origin(xyz, rpy)))
    spec = RobotSpec(
        name="wolfgang",
        step_limits=STEP_LIMITS,
        foot_length=FOOT_LENGTH,
        foot_width=FOOT_WIDTH,
        foot_thickness=PLATE_THICKNESS,
        torso_footprint=TORSO_FOOTPRINT,
        upper_body_footprint=UPPER_BODY_FOOTPRINT,
        base_link="torso",
        links=tuple(links),
        joints=tuple(joints),
        soles=SOLES,
    )
    walk_ready = stance_pose(spec.leg_geometry, WALK_READY_TRUNK_HEIGHT, WALK_READY_FOOT_DISTANCE)
    walk_ready.update(WALK_READY_ARMS)
    return dataclasses.replace(spec, walk_ready=walk_ready)


__all__ = ["SERVOS", "STEP_LIMITS", "URDF_DYNAMICS", "wolfgang"]
