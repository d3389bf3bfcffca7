"""The robot spec: the single description of a humanoid that every backend's model comes from.

A :class:`RobotSpec` holds a kinematic tree of :class:`Link` s (mass, centre of mass, inertia,
primitive collision shapes) joined by revolute :class:`Joint` s (origin, axis, limits, effort and
velocity limits, servo parameters), the foot plate, the walk-ready pose and the footstep limits.
The model builders (``footsim.robots.mjcf``, ``footsim.robots.urdf``) turn it into MJCF and URDF;
nothing else keeps a copy of these numbers.

Conventions (shared with ``footsim.walk.ik``):

* Base (trunk) frame x forward, y left, z up, origin at the centre of the bottom of the torso.
* Every link frame sits on the joint that moves it and is parallel to its parent's frame in the
  zero pose, so in the zero pose every frame is parallel to the base frame and each joint axis
  is a base axis.  Zero = straight legs, feet flat, arms hanging down.
* Leg axes for both legs: HipYaw +z, HipRoll +x, HipPitch +y, Knee +y, AnklePitch +y,
  AnkleRoll +x.  So a negative HipPitch swings the thigh forward, a positive Knee bends the
  knee, a positive HipRoll moves the foot towards +y (outward for the left leg, inward for the
  right one).  Arm axes: ShoulderPitch +y, ShoulderRoll +x, Elbow +y; head: HeadPan +z,
  HeadTilt +y (positive looks down).
* Sole frame = centre of the bottom face of the foot plate, straight below the ankle axes.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from footsim.walk.footsteps import Side, StepLimits
from footsim.walk.ik import LEG_JOINTS, LegChain, LegGeometry, leg_fk, leg_ik

Vec3 = tuple[float, float, float]

ARM_JOINTS = ("ShoulderPitch", "ShoulderRoll", "Elbow")
HEAD_JOINTS = ("HeadPan", "HeadTilt")
# Roll and yaw joints: the right side's angle (and limit range) is the left side's negated.
MIRRORED_JOINTS = ("HipYaw", "HipRoll", "AnkleRoll", "ShoulderRoll", "HeadPan")


def _vec3(value, what: str) -> Vec3:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be three finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _positive(value: float, what: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be a positive finite number, got {value!r}")
    return float(value)


def _non_negative(value: float, what: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{what} must be a non-negative finite number, got {value!r}")
    return float(value)


def rpy_to_matrix(rpy: Vec3) -> np.ndarray:
    """URDF convention: fixed-axis roll about x, then pitch about y, then yaw about z."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


# --------------------------------------------------------------------------------------------
# Geometry and inertia
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Origin:
    """A pose relative to a parent frame: translation [m] and URDF roll-pitch-yaw [rad]."""

    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "xyz", _vec3(self.xyz, "Origin.xyz"))
        object.__setattr__(self, "rpy", _vec3(self.rpy, "Origin.rpy"))

    @property
    def rotation(self) -> np.ndarray:
        return rpy_to_matrix(self.rpy)

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> Origin:
        """The Origin of a homogeneous 4x4 transform (rpy with the pitch in [-pi/2, pi/2])."""
        R = np.asarray(matrix, dtype=float)
        pitch = math.asin(max(-1.0, min(1.0, -float(R[2, 0]))))
        rpy = (math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0]))
        return cls(tuple(float(v) for v in R[:3, 3]), rpy)  # type: ignore[arg-type]

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 transform."""
        out = np.eye(4)
        out[:3, :3] = self.rotation
        out[:3, 3] = self.xyz
        return out


@dataclass(frozen=True)
class Box:
    size: Vec3  # full extents x, y, z [m]
    origin: Origin = Origin()
    self_collision: bool = False  # collides with the other leg's self-colliding shapes

    def __post_init__(self) -> None:
        size = _vec3(self.size, "Box.size")
        for v in size:
            _positive(v, "Box.size entries")
        object.__setattr__(self, "size", size)


@dataclass(frozen=True)
class Sphere:
    radius: float
    origin: Origin = Origin()
    self_collision: bool = False

    def __post_init__(self) -> None:
        _positive(self.radius, "Sphere.radius")


@dataclass(frozen=True)
class Capsule:
    """A cylinder of ``length`` along the local z axis with hemispherical caps (total length
    ``length + 2 radius``)."""

    radius: float
    length: float
    origin: Origin = Origin()
    self_collision: bool = False

    def __post_init__(self) -> None:
        _positive(self.radius, "Capsule.radius")
        _positive(self.length, "Capsule.length")


@dataclass(frozen=True)
class Cylinder:
    """A cylinder of ``length`` along the local z axis."""

    radius: float
    length: float
    origin: Origin = Origin()
    self_collision: bool = False

    def __post_init__(self) -> None:
        _positive(self.radius, "Cylinder.radius")
        _positive(self.length, "Cylinder.length")


Shape = Box | Sphere | Capsule | Cylinder


@dataclass(frozen=True)
class Inertial:
    """Mass [kg], centre of mass in the link frame [m] and the inertia tensor about the COM in
    link-frame axes [kg m²]: ``(ixx, iyy, izz)`` or ``(ixx, iyy, izz, ixy, ixz, iyz)``."""

    mass: float
    com: Vec3 = (0.0, 0.0, 0.0)
    inertia: tuple[float, ...] = (1e-6, 1e-6, 1e-6)

    def __post_init__(self) -> None:
        _positive(self.mass, "Inertial.mass")
        object.__setattr__(self, "com", _vec3(self.com, "Inertial.com"))
        values = tuple(float(v) for v in self.inertia)
        if len(values) == 3:
            values = values + (0.0, 0.0, 0.0)
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise ValueError(f"Inertial.inertia must be 3 or 6 finite numbers, got {self.inertia!r}")
        object.__setattr__(self, "inertia", values)
        eig = np.linalg.eigvalsh(self.matrix)
        # A physical rigid body has positive principal moments obeying the triangle inequality.
        if eig.min() <= 0 or eig[2] > eig[0] + eig[1] + 1e-12:
            raise ValueError(f"Inertial.inertia {values} is not a physical inertia tensor")

    @property
    def matrix(self) -> np.ndarray:
        ixx, iyy, izz, ixy, ixz, iyz = self.inertia
        return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])

    @property
    def is_diagonal(self) -> bool:
        return not any(self.inertia[3:])


def combined_inertial(parts) -> Inertial:
    """One rigid body's :class:`Inertial` from ``parts``: ``(Inertial, pose)`` pairs, each pose
    (4x4) placing the part's frame in the combined body's frame (parallel-axis theorem)."""
    mass = sum(part.mass for part, _ in parts)
    coms = [pose[:3, :3] @ np.asarray(part.com) + pose[:3, 3] for part, pose in parts]
    com = sum(part.mass * c for (part, _), c in zip(parts, coms)) / mass
    total = np.zeros((3, 3))
    for (part, pose), c in zip(parts, coms):
        R, d = pose[:3, :3], c - com
        total += R @ part.matrix @ R.T + part.mass * (float(d @ d) * np.eye(3) - np.outer(d, d))
    inertia = (total[0, 0], total[1, 1], total[2, 2], total[0, 1], total[0, 2], total[1, 2])
    return Inertial(float(mass), tuple(float(v) for v in com), tuple(float(v) for v in inertia))  # type: ignore[arg-type]


def box_inertia(mass: float, size: Vec3) -> tuple[float, float, float]:
    """Principal moments of a solid box of full extents ``size``."""
    x, y, z = size
    return (mass * (y * y + z * z) / 12.0, mass * (x * x + z * z) / 12.0, mass * (x * x + y * y) / 12.0)


# --------------------------------------------------------------------------------------------
# Links and joints
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Link:
    name: str
    inertial: Inertial
    shapes: tuple[Shape, ...] = ()
    rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.65, 1.0)

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("Link.name must be a non-empty string")
        object.__setattr__(self, "shapes", tuple(self.shapes))
        for shape in self.shapes:
            if not isinstance(shape, (Box, Sphere, Capsule, Cylinder)):
                raise TypeError(f"link {self.name!r}: unsupported collision shape {shape!r}")


@dataclass(frozen=True)
class ServoParams:
    """Position servo model: proportional gain kp [Nm/rad] of the position actuator, and the
    joint's passive damping [Nm s/rad], armature (reflected rotor inertia) [kg m²] and dry
    friction [Nm]."""

    kp: float
    damping: float
    armature: float
    frictionloss: float

    def __post_init__(self) -> None:
        _positive(self.kp, "ServoParams.kp")
        _non_negative(self.damping, "ServoParams.damping")
        _non_negative(self.armature, "ServoParams.armature")
        _non_negative(self.frictionloss, "ServoParams.frictionloss")


# Reference servo (ROBOTIS OP3 in MuJoCo Menagerie, XM430 servos, force range ±5 Nm).
OP3_REFERENCE_EFFORT = 5.0
OP3_REFERENCE_SERVO = ServoParams(kp=21.1, damping=1.084, armature=0.045, frictionloss=0.03)


def scaled_servo(effort: float) -> ServoParams:
    """Servo parameters for a servo of peak torque ``effort`` [Nm], scaled from the OP3 reference.

    Larger Dynamixels (Wolfgang's MX-106/XH540 class legs) have proportionally stiffer position
    loops, more reflected rotor inertia and more gearbox friction; scaling all four linearly
    with the torque rating keeps the closed-loop bandwidth (kp / inertia) of the reference model,
    which is stable under position control at a 2 ms timestep.
    """
    ratio = _positive(effort, "effort") / OP3_REFERENCE_EFFORT
    ref = OP3_REFERENCE_SERVO
    return ServoParams(
        kp=ref.kp * ratio,
        damping=ref.damping * ratio,
        armature=ref.armature * ratio,
        frictionloss=ref.frictionloss * ratio,
    )


@dataclass(frozen=True)
class Joint:
    """A revolute joint.  ``origin`` places the child link frame in the parent link frame (in the
    zero pose); ``axis`` is a unit vector in the child (= joint) frame."""

    name: str
    parent: str
    child: str
    axis: Vec3
    lower: float
    upper: float
    effort: float  # peak torque [Nm]
    velocity: float  # peak speed [rad/s]
    servo: ServoParams
    origin: Origin = Origin()

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("Joint.name must be a non-empty string")
        axis = np.asarray(_vec3(self.axis, f"joint {self.name!r} axis"))
        norm = float(np.linalg.norm(axis))
        if norm < 1e-9:
            raise ValueError(f"joint {self.name!r}: axis must be non-zero")
        object.__setattr__(self, "axis", tuple(float(v) for v in axis / norm))
        for attr in ("lower", "upper"):
            value = getattr(self, attr)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"joint {self.name!r}: {attr} must be a finite number, got {value!r}")
        if not self.lower < self.upper:
            raise ValueError(f"joint {self.name!r}: lower limit {self.lower} must be below upper {self.upper}")
        _positive(self.effort, f"joint {self.name!r} effort")
        _positive(self.velocity, f"joint {self.name!r} velocity")

    @property
    def range(self) -> tuple[float, float]:
        return (self.lower, self.upper)


def _side(side: Side | str) -> Side:
    if isinstance(side, Side):
        return side
    key = str(side).strip().lower()
    aliases = {"left": Side.LEFT, "l": Side.LEFT, "right": Side.RIGHT, "r": Side.RIGHT}
    if key not in aliases:
        raise ValueError(f"side must be 'left' or 'right' (or Side), got {side!r}")
    return aliases[key]


def side_prefix(side: Side | str) -> str:
    """Joint-name prefix of a side: ``'L'`` or ``'R'``."""
    return "L" if _side(side) is Side.LEFT else "R"


def sole_frame_name(side: Side | str) -> str:
    """Name of the sole frame of ``side`` in every generated model: ``'l_sole'`` / ``'r_sole'``
    (a MuJoCo site, a massless URDF link on a fixed joint)."""
    return "l_sole" if _side(side) is Side.LEFT else "r_sole"


# --------------------------------------------------------------------------------------------
# The robot
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RobotSpec:
    """A humanoid: kinematic tree, masses, collision shapes, servo models and walking limits.

    The planar (2D) task needs only ``name``, ``step_limits`` and the foot/torso footprints, so
    a spec without links is valid; the 3D accessors then raise ``ValueError``.
    """

    name: str
    step_limits: StepLimits = field(default_factory=StepLimits)
    foot_length: float = 0.154  # sole plate, x [m]
    foot_width: float = 0.106  # sole plate, y [m]
    torso_footprint: tuple[float, float] = (0.15, 0.15)  # planar collision box of the trunk [m]
    # The planar box bounding the upper body with the arms at walk-ready: length, width [m] and its
    # centre's offset ahead of the feet's mean pose [m] (the 2D collision_model=upper_body); None: unknown.
    upper_body_footprint: tuple[float, float, float] | None = None
    foot_thickness: float = 0.0035  # sole plate, z [m]
    base_link: str = "torso"
    links: tuple[Link, ...] = ()
    joints: tuple[Joint, ...] = ()
    # Sole frame per side: (foot link, sole pose in that link's frame: an Origin, or a position
    # for a sole frame parallel to the foot link frame).  The walk engine's IK targets it.
    soles: Mapping[str, tuple[str, Origin]] = field(default_factory=dict)
    walk_ready: Mapping[str, float] = field(default_factory=dict)  # joint name -> angle [rad]

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("RobotSpec.name must be a non-empty string")
        for attr in ("foot_length", "foot_width", "foot_thickness"):
            _positive(getattr(self, attr), f"RobotSpec.{attr}")
        for value in self.torso_footprint:
            _positive(value, "RobotSpec.torso_footprint entries")
        if self.upper_body_footprint is not None:
            length, width, offset = self.upper_body_footprint
            _positive(length, "RobotSpec.upper_body_footprint length")
            _positive(width, "RobotSpec.upper_body_footprint width")
            if not math.isfinite(offset):
                raise ValueError(f"RobotSpec.upper_body_footprint offset must be finite, got {offset!r}")
        object.__setattr__(self, "links", tuple(self.links))
        object.__setattr__(self, "joints", tuple(self.joints))
        object.__setattr__(
            self,
            "soles",
            {
                str(k): (v[0], v[1] if isinstance(v[1], Origin) else Origin(_vec3(v[1], f"sole {k}")))
                for k, v in self.soles.items()
            },
        )
        object.__setattr__(self, "walk_ready", {str(k): float(v) for k, v in self.walk_ready.items()})
        if self.links or self.joints:
            self._validate_tree()

    # ---- validation -------------------------------------------------------------------------

    def _validate_tree(self) -> None:
        link_names = [link.name for link in self.links]
        duplicates = sorted({n for n in link_names if link_names.count(n) > 1})
        if duplicates:
            raise ValueError(f"robot {self.name!r}: duplicate link names {duplicates}")
        joint_names = [joint.name for joint in self.joints]
        duplicates = sorted({n for n in joint_names if joint_names.count(n) > 1})
        if duplicates:
            raise ValueError(f"robot {self.name!r}: duplicate joint names {duplicates}")
        known = set(link_names)
        if self.base_link not in known:
            raise ValueError(f"robot {self.name!r}: base link {self.base_link!r} is not among the links")
        parents: dict[str, str] = {}
        for joint in self.joints:
            for role, link in (("parent", joint.parent), ("child", joint.child)):
                if link not in known:
                    raise ValueError(f"joint {joint.name!r}: {role} link {link!r} does not exist")
            if joint.child in parents:
                raise ValueError(f"link {joint.child!r} is the child of more than one joint")
            if joint.child == self.base_link:
                raise ValueError(f"joint {joint.name!r}: the base link {self.base_link!r} cannot be a child")
            parents[joint.child] = joint.parent
        orphans = sorted(known - set(parents) - {self.base_link})
        if orphans:
            raise ValueError(f"robot {self.name!r}: links {orphans} are not connected to the base")
        for link in parents:  # every chain must end at the base (no cycles)
            seen, cur = set(), link
            while cur != self.base_link:
                if cur in seen:
                    raise ValueError(f"robot {self.name!r}: kinematic loop through link {cur!r}")
                seen.add(cur)
                cur = parents[cur]
        for side, (foot, _) in self.soles.items():
            _side(side)
            if foot not in known:
                raise ValueError(f"sole {side!r}: foot link {foot!r} does not exist")
        by_name = {j.name: j for j in self.joints}
        for name, angle in self.walk_ready.items():
            if name not in by_name:
                raise ValueError(f"walk_ready: unknown joint {name!r}")
            joint = by_name[name]
            if not (math.isfinite(angle) and joint.lower <= angle <= joint.upper):
                raise ValueError(f"walk_ready[{name!r}] = {angle} is outside [{joint.lower}, {joint.upper}]")

    def _require_model(self) -> None:
        if not self.joints:
            raise ValueError(f"robot {self.name!r} has no kinematic model (links/joints)")

    # ---- lookup -----------------------------------------------------------------------------

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def link_names(self) -> tuple[str, ...]:
        return tuple(link.name for link in self.links)

    def joint(self, name: str) -> Joint:
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(f"robot {self.name!r} has no joint {name!r}; joints: {list(self.joint_names)}")

    def link(self, name: str) -> Link:
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(f"robot {self.name!r} has no link {name!r}; links: {list(self.link_names)}")

    def parent_joint(self, link_name: str) -> Joint | None:
        """The joint whose child is ``link_name`` (None for the base)."""
        for joint in self.joints:
            if joint.child == link_name:
                return joint
        return None

    def child_joints(self, link_name: str) -> tuple[Joint, ...]:
        return tuple(j for j in self.joints if j.parent == link_name)

    @property
    def total_mass(self) -> float:
        return float(sum(link.inertial.mass for link in self.links))

    @property
    def dof(self) -> int:
        return len(self.joints)

    def leg_joint_names(self, side: Side | str) -> tuple[str, ...]:
        """The six leg joints of ``side`` in chain order (hip yaw ... ankle roll)."""
        self._require_model()
        names = tuple(side_prefix(side) + j for j in LEG_JOINTS)
        for name in names:
            self.joint(name)  # raises naming the missing joint
        return names

    @property
    def upper_body_joint_names(self) -> tuple[str, ...]:
        """Every joint that is not a leg joint (arms, head), in ``joint_names`` order."""
        legs = set(self.leg_joint_names(Side.LEFT) + self.leg_joint_names(Side.RIGHT))
        return tuple(name for name in self.joint_names if name not in legs)

    def with_rigid_upper_body(self) -> RobotSpec:
        """This robot with the arms and head merged into the base link at their walk-ready angles:
        one rigid body (mass, COM and inertia combined exactly, the shapes moved into the base frame)
        and only the leg joints left.  For loaders whose own merging of fixed links is not exact
        (PyBullet's ``URDF_MERGE_FIXED_LINKS`` misplaces the COM of rotated children)."""
        self._require_model()
        upper_joints = set(self.upper_body_joint_names)
        frames = self.link_transforms(self.walk_ready)
        merged = [self.link(self.base_link)]
        pending = [j.child for j in self.child_joints(self.base_link) if j.name in upper_joints]
        while pending:
            name = pending.pop()
            merged.append(self.link(name))
            pending += [j.child for j in self.child_joints(name)]
        shapes = []
        for link in merged:
            for shape in link.shapes:
                pose = Origin.from_matrix(frames[link.name] @ shape.origin.matrix)
                shapes.append(dataclasses.replace(shape, origin=pose))
        base = Link(
            self.base_link,
            combined_inertial([(link.inertial, frames[link.name]) for link in merged]),
            tuple(shapes),
            self.link(self.base_link).rgba,
        )
        merged_names = {link.name for link in merged}
        return dataclasses.replace(
            self,
            links=(base, *(link for link in self.links if link.name not in merged_names)),
            joints=tuple(j for j in self.joints if j.name not in upper_joints),
            walk_ready={k: v for k, v in self.walk_ready.items() if k not in upper_joints},
        )

    def walk_ready_rotation(self, name: str) -> np.ndarray:
        """Rotation of joint ``name``'s child frame in its parent's at the walk-ready angle: the
        fixed origin of that joint in a model whose upper body is rigid."""
        joint = self.joint(name)
        return joint.origin.rotation @ _axis_angle(np.asarray(joint.axis), self.walk_ready.get(name, 0.0))

    def leg_limits(self, side: Side | str) -> np.ndarray:
        """``(6, 2)`` [lower, upper] of the leg joints of ``side`` in chain order (the form
        ``footsim.walk.ik.leg_ik(..., limits=)`` takes)."""
        return np.array([self.joint(n).range for n in self.leg_joint_names(side)])

    def sole(self, side: Side | str) -> tuple[str, Origin]:
        """(foot link, sole frame pose in the foot link frame)."""
        key = _side(side).value
        if key not in self.soles:
            raise ValueError(f"robot {self.name!r} has no sole frame for the {key} foot")
        return self.soles[key]

    def foot_link(self, side: Side | str) -> str:
        return self.sole(side)[0]

    def walk_ready_vector(self) -> np.ndarray:
        """Walk-ready angles in ``joint_names`` order (unlisted joints at 0)."""
        return np.array([self.walk_ready.get(name, 0.0) for name in self.joint_names])

    # ---- kinematics -------------------------------------------------------------------------

    def link_transforms(self, q: Mapping[str, float] | None = None) -> dict[str, np.ndarray]:
        """Pose (4x4) of every link frame in the base frame for joint angles ``q`` (default 0).

        Plain numpy forward kinematics straight from the spec: the reference the model builders'
        outputs are checked against.
        """
        q = dict(q or {})
        unknown = sorted(set(q) - set(self.joint_names))
        if unknown:
            raise ValueError(f"unknown joint(s) {unknown}")
        out = {self.base_link: np.eye(4)}
        pending = list(self.child_joints(self.base_link))
        while pending:
            joint = pending.pop()
            angle = float(q.get(joint.name, 0.0))
            if not math.isfinite(angle):
                raise ValueError(f"joint {joint.name!r}: angle must be finite, got {angle!r}")
            motion = np.eye(4)
            motion[:3, :3] = _axis_angle(np.asarray(joint.axis), angle)
            out[joint.child] = out[joint.parent] @ joint.origin.matrix @ motion
            pending.extend(self.child_joints(joint.child))
        return out

    def sole_transform(self, side: Side | str, q: Mapping[str, float] | None = None) -> np.ndarray:
        """Pose (4x4) of the sole frame of ``side`` in the base frame."""
        foot, origin = self.sole(side)
        return self.link_transforms(q)[foot] @ origin.matrix

    def sole_clearance(self, side: Side | str) -> float:
        """Height of the foot's lowest collision point above its sole frame, with the sole level
        (0 for a sole frame on the bottom face of a flat plate; Wolfgang's sole frame lies below
        the cleat tips).  The backends place a standing robot with this point on the floor."""
        foot, origin = self.sole(side)
        to_sole = np.linalg.inv(origin.matrix)
        lowest = math.inf
        for shape in self.link(foot).shapes:
            pose = to_sole @ shape.origin.matrix
            lowest = min(lowest, _lowest_point(shape, pose))
        if not math.isfinite(lowest):
            raise ValueError(f"robot {self.name!r}: foot link {foot!r} has no collision shape")
        return float(lowest)

    @functools.cached_property
    def leg_geometry(self) -> LegGeometry:
        """The legs' kinematics for the analytic IK, read from the joints (see
        :mod:`footsim.walk.ik`): axis points, segment lengths, the sole's offset from the ankle
        centre and each joint's sign and zero in the IK's chain convention.

        Raises ``ValueError`` if a leg is not a yaw–roll–pitch–pitch–pitch–roll chain with
        intersecting hip roll/pitch and ankle pitch/roll axes (the check: the chain's FK must
        reproduce :meth:`sole_transform` at random angles to ``_CHAIN_TOLERANCE``).
        """
        self._require_model()
        return LegGeometry(self._leg_chain(Side.LEFT), self._leg_chain(Side.RIGHT))

    def _leg_chain(self, side: Side) -> LegChain:
        names = self.leg_joint_names(side)
        frames = self.link_transforms()
        axes, points = [], []
        for name in names:
            joint = self.joint(name)
            frame = frames[joint.child]  # the joint frame in the zero pose
            axes.append(frame[:3, :3] @ np.asarray(joint.axis))
            points.append(frame[:3, 3])
        if self.sole(side)[0] != self.joint(names[-1]).child:
            raise ValueError(f"the {side.value} sole must be on link {self.joint(names[-1]).child!r}")
        sole = self.sole_transform(side)
        sole_rot, sole_pos = sole[:3, :3], sole[:3, 3]
        foot_pitch = math.atan2(sole_rot[0, 2], sole_rot[0, 0])
        if not np.allclose(sole_rot, _axis_angle(np.array([0.0, 1.0, 0.0]), foot_pitch), atol=_CHAIN_TOLERANCE):
            raise ValueError(f"the {side.value} sole frame must be level up to a pitch in the zero pose")
        expected = (
            np.array([0.0, 0.0, 1.0]),
            np.array([1.0, 0.0, 0.0]),
            np.array([0.0, 1.0, 0.0]),
            np.array([0.0, 1.0, 0.0]),
            np.array([0.0, 1.0, 0.0]),
            sole_rot[:, 0],  # the ankle roll turns about the foot's x axis
        )
        signs = []
        for name, axis, want in zip(names, axes, expected):
            dot = float(axis @ want)
            if abs(abs(dot) - 1.0) > _CHAIN_TOLERANCE:
                raise ValueError(
                    f"joint {name!r}: axis {np.round(axis, 4).tolist()} is not along ±{np.round(want, 4).tolist()} "
                    "in the zero pose; the analytic IK needs a yaw–roll–pitch–pitch–pitch–roll leg"
                )
            signs.append(1.0 if dot > 0 else -1.0)
        hip = _intersection(points[1], axes[1], points[2], axes[2], f"the {side.value} hip roll and pitch axes")
        ankle = _intersection(points[4], axes[4], points[5], axes[5], f"the {side.value} ankle pitch and roll axes")
        knee = points[3]
        thigh, shin = (knee - hip)[[0, 2]], (ankle - knee)[[0, 2]]
        hip_pitch0 = math.atan2(-thigh[0], -thigh[1])
        knee0 = math.atan2(-shin[0], -shin[1]) - hip_pitch0
        chain = LegChain(
            hip_yaw=_vec3(points[0], "hip yaw point"),
            hip_centre=_vec3(hip - points[0], "hip centre"),
            lateral=float(ankle[1] - hip[1]),
            thigh=float(np.linalg.norm(thigh)),
            shin=float(np.linalg.norm(shin)),
            ankle=_vec3(sole_rot.T @ (ankle - sole_pos), "ankle centre"),
            signs=tuple(signs),  # type: ignore[arg-type]
            zeros=(0.0, 0.0, hip_pitch0, knee0, foot_pitch - hip_pitch0 - knee0, 0.0),
        )
        rng = np.random.default_rng(0)
        limits = self.leg_limits(side)
        for q in rng.uniform(limits[:, 0], limits[:, 1], (8, 6)):
            pos, rot = leg_fk(q[None], side, LegGeometry(chain, chain))
            want_pose = self.sole_transform(side, dict(zip(names, q)))
            error = max(np.abs(pos[0] - want_pose[:3, 3]).max(), np.abs(rot[0] - want_pose[:3, :3]).max())
            if error > _CHAIN_TOLERANCE:
                raise ValueError(
                    f"the {side.value} leg is not the chain the analytic IK solves (FK differs by {error:.2e})"
                )
        return chain


# How far a leg may be from the ideal chain [m, and rad for directions]: URDFs round their angles
# (Wolfgang's 1.5708 for pi/2 tilts axes by ~4e-6 rad), which moves the sole by micrometres.
_CHAIN_TOLERANCE = 2e-5


def _intersection(p1: np.ndarray, a1: np.ndarray, p2: np.ndarray, a2: np.ndarray, what: str) -> np.ndarray:
    """The point where two (non-parallel) lines meet; ``ValueError`` if they miss by > 1 µm."""
    n = np.cross(a1, a2)
    t1 = np.dot(np.cross(p2 - p1, a2), n) / np.dot(n, n)
    t2 = np.dot(np.cross(p2 - p1, a1), n) / np.dot(n, n)
    c1, c2 = p1 + t1 * a1, p2 + t2 * a2
    if np.linalg.norm(c1 - c2) > _CHAIN_TOLERANCE:
        raise ValueError(f"{what} do not intersect (they miss by {np.linalg.norm(c1 - c2):.2e} m)")
    return (c1 + c2) / 2.0


def _lowest_point(shape: Shape, pose: np.ndarray) -> float:
    """Lowest z of ``shape`` placed at ``pose`` (4x4) in a frame with z up."""
    R, centre = pose[:3, :3], pose[:3, 3]
    if isinstance(shape, Sphere):
        return float(centre[2] - shape.radius)
    if isinstance(shape, Box):
        half = np.array(shape.size) / 2.0
        return float(centre[2] - np.abs(R[2, :]) @ half)
    # Capsule / cylinder along local z: the lower end of the axis, then the radius (the capsule's
    # cap; for a cylinder the rim's drop is radius·|sin(tilt)|).
    axis_z = abs(R[2, 2]) * shape.length / 2.0
    if isinstance(shape, Capsule):
        return float(centre[2] - axis_z - shape.radius)
    return float(centre[2] - axis_z - shape.radius * math.sqrt(max(0.0, 1.0 - R[2, 2] ** 2)))


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation about a unit axis."""
    x, y, z = axis
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def stance_pose(legs: LegGeometry, trunk_height: float, foot_distance: float) -> dict[str, float]:
    """Robot leg angles for standing with the trunk upright ``trunk_height`` above the soles, the
    soles level, ``foot_distance`` apart and straight below the base origin in x (the walk
    engine's neutral stance, solved by its IK)."""
    pose = {}
    for side in (Side.LEFT, Side.RIGHT):
        target = np.array([[0.0, side.sign * foot_distance / 2.0, -trunk_height]])
        q, reachable = leg_ik(target, np.zeros((1, 3)), side, legs)
        if not reachable[0]:
            raise ValueError(f"trunk_height {trunk_height} / foot_distance {foot_distance} is out of the leg's reach")
        pose.update({side_prefix(side) + joint: float(angle) + 0.0 for joint, angle in zip(LEG_JOINTS, q[0])})
    return pose
