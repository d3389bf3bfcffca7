"""Build a MuJoCo model (MJCF) from a :class:`~footsim.robots.spec.RobotSpec` with ``mujoco.MjSpec``.

The output serves MuJoCo directly and dm-control (``dm_control.mjcf.from_xml_string`` parses the
XML).  What a backend can rely on:

* body ``spec.base_link`` ("torso") carries a free joint named :data:`FREE_JOINT`;
* every other link is a body of the same name; every revolute joint keeps its spec name and is
  driven by a position actuator of the same name (kp = servo kp, force range ±effort, control
  range = joint range);
* sites ``l_sole`` / ``r_sole`` (:func:`sole_site`) at the sole frames and ``imu`` on the
  torso, with sensors ``imu_gyro``, ``imu_accel`` and ``imu_quat``;
* keyframe ``walk_ready``: standing in the walk-ready pose with the soles on the floor;
* contact filtering by bit masks: the world (floor, obstacles with MuJoCo's default
  contype = conaffinity = 1) collides with every robot geom; robot geoms do not collide with
  each other, except the lower legs and feet of one leg with those of the other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from footsim.robots.spec import Box, Capsule, Cylinder, Link, RobotSpec, Side, Sphere, sole_frame_name

if TYPE_CHECKING:  # pragma: no cover
    pass

FREE_JOINT = "root"
IMU_SITE = "imu"
FLOOR_GEOM = "floor"
WALK_READY_KEY = "walk_ready"
TIMESTEP = 0.002

# Contact bit masks (see the module docstring).
_WORLD_BIT, _LEFT_LEG_BIT, _RIGHT_LEG_BIT = 1, 2, 4
# Contact softness: 4 ms time constant (≥ 2 timesteps, as MuJoCo advises), critically damped —
# the OP3 Menagerie value.  Friction: lateral 1.0 like the team's PyBullet setup; MuJoCo's
# default torsional/rolling coefficients (its units differ from Bullet's).
CONTACT_SOLREF = (0.004, 1.0)
CONTACT_FRICTION = (1.0, 0.005, 0.0001)


def sole_site(side: Side | str) -> str:
    """Name of the sole site of ``side``: ``'l_sole'`` or ``'r_sole'``."""
    return sole_frame_name(side)


def touch_site(side: Side | str) -> str:
    """Name of the touch-sensor site of ``side``'s foot: ``'l_foot_touch'`` / ``'r_foot_touch'``."""
    return sole_frame_name(side)[0] + "_foot_touch"


def touch_sensor(side: Side | str) -> str:
    """Name of the touch sensor of ``side``'s foot (MuJoCo's summed contact normal force [N])."""
    return touch_site(side)


# The touch box reaches this far above the sole plane and beyond the foot's shapes [m].
_TOUCH_HEIGHT, _TOUCH_MARGIN = 0.03, 0.01


def _foot_touch_box(spec: RobotSpec, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(half sizes, centre in the foot frame) of the box, in sole-frame axes, that holds every
    foot shape's centre ± its extent from ``_TOUCH_MARGIN`` below the lowest point up to
    ``_TOUCH_HEIGHT`` above the sole frame."""
    foot, origin = spec.sole(side)
    to_sole = np.linalg.inv(origin.matrix)
    points = []
    for shape in spec.link(foot).shapes:
        centre = (to_sole @ shape.origin.matrix)[:3, 3]
        reach = max(getattr(shape, "size", (0.0, 0.0, 0.0))[:2]) / 2.0 + getattr(shape, "radius", 0.0)
        points += [centre[:2] + reach, centre[:2] - reach]
    xy = np.array(points)
    low = spec.sole_clearance(side) - _TOUCH_MARGIN
    lo = np.array([*xy.min(axis=0) - _TOUCH_MARGIN, low])
    hi = np.array([*xy.max(axis=0) + _TOUCH_MARGIN, _TOUCH_HEIGHT])
    centre_sole = (lo + hi) / 2.0
    return (hi - lo) / 2.0, origin.matrix[:3, :3] @ centre_sole + np.asarray(origin.xyz)


def import_mujoco():
    """Import mujoco, or fail with the extra to install."""
    try:
        import mujoco
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "building or loading the MuJoCo model needs the 'mujoco' package: pip install 'footsim[mujoco]'"
        ) from exc
    return mujoco


@dataclass
class MjcfModel:
    """The outputs of :func:`build_mjcf`: the editable spec, the compiled model and its XML."""

    spec: Any  # mujoco.MjSpec
    model: Any  # mujoco.MjModel
    xml: str


def _quat(rotation: np.ndarray) -> list[float]:
    mujoco = import_mujoco()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rotation, dtype=float).ravel())
    return quat.tolist()


def _add_shape(body, link: Link, index: int, shape, side: Side | None) -> None:
    mujoco = import_mujoco()
    geom_type = mujoco.mjtGeom
    if isinstance(shape, Box):
        kind, size = geom_type.mjGEOM_BOX, [s / 2.0 for s in shape.size]
    elif isinstance(shape, Sphere):
        kind, size = geom_type.mjGEOM_SPHERE, [shape.radius, 0.0, 0.0]
    elif isinstance(shape, Capsule):
        kind, size = geom_type.mjGEOM_CAPSULE, [shape.radius, shape.length / 2.0, 0.0]
    elif isinstance(shape, Cylinder):
        kind, size = geom_type.mjGEOM_CYLINDER, [shape.radius, shape.length / 2.0, 0.0]
    else:  # pragma: no cover - RobotSpec validates shapes
        raise TypeError(f"unsupported shape {shape!r}")
    if shape.self_collision and side is not None:
        own, other = (_LEFT_LEG_BIT, _RIGHT_LEG_BIT) if side is Side.LEFT else (_RIGHT_LEG_BIT, _LEFT_LEG_BIT)
        contype, conaffinity = _WORLD_BIT | own, other
    else:
        contype, conaffinity = _WORLD_BIT, 0  # touches the world, never the robot itself
    geom = body.add_geom(
        name=f"{link.name}_collision{index}",
        type=kind,
        size=size,
        pos=list(shape.origin.xyz),
        quat=_quat(shape.origin.rotation),
        rgba=list(link.rgba),
    )
    geom.contype, geom.conaffinity = contype, conaffinity
    geom.condim = 3
    geom.friction = list(CONTACT_FRICTION)
    geom.solref = list(CONTACT_SOLREF)
    geom.mass = 0.0  # link inertia comes from the spec, not from geom volumes


def _link_side(spec: RobotSpec, link_name: str) -> Side | None:
    """The leg a link belongs to (walking up to the hip yaw joint), or None."""
    joint = spec.parent_joint(link_name)
    while joint is not None:
        for side in (Side.LEFT, Side.RIGHT):
            if joint.name in spec.leg_joint_names(side):
                return side
        joint = spec.parent_joint(joint.parent)
    return None


def build_mjcf(
    spec: RobotSpec, *, floor: bool = True, timestep: float = TIMESTEP, rigid_upper_body: bool = False
) -> MjcfModel:
    """Build the MuJoCo model of ``spec``.

    ``floor`` adds a ground plane named :data:`FLOOR_GEOM` and a light (a backend that makes
    its own world passes ``floor=False``).  ``rigid_upper_body`` welds the arm and head links
    at their walk-ready angles (no joint, no actuator), as the PyBullet backend's model does:
    the walk holds them there anyway, and 8 fewer degrees of freedom make ``mj_step`` cheaper.
    Returns the ``MjSpec``, the compiled ``MjModel`` and the MJCF XML.
    """
    mujoco = import_mujoco()
    if not spec.joints:
        raise ValueError(f"robot {spec.name!r} has no kinematic model to build")
    if not (math.isfinite(timestep) and timestep > 0):
        raise ValueError(f"timestep must be a positive number, got {timestep!r}")

    mj = mujoco.MjSpec()
    mj.modelname = spec.name
    mj.compiler.degree = False  # the spec is in radians
    mj.compiler.autolimits = True
    mj.option.timestep = timestep
    # implicitfast integrates joint damping implicitly: stable stiff position servos at 2 ms.
    mj.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST

    world = mj.worldbody
    if floor:
        world.add_light(name="top", pos=[0.0, 0.0, 3.0], dir=[0.0, 0.0, -1.0])
        ground = world.add_geom(
            name=FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 0.05], rgba=[0.35, 0.45, 0.35, 1.0]
        )
        ground.contype, ground.conaffinity = _WORLD_BIT, _WORLD_BIT
        ground.friction = list(CONTACT_FRICTION)
        ground.solref = list(CONTACT_SOLREF)

    straight_leg_height = -spec.sole_transform(Side.LEFT)[2, 3]
    base = world.add_body(name=spec.base_link, pos=[0.0, 0.0, straight_leg_height])
    base.add_freejoint(name=FREE_JOINT)

    def fill(body, link: Link) -> None:
        inertial = link.inertial
        body.mass = inertial.mass
        body.ipos = list(inertial.com)
        body.fullinertia = list(inertial.inertia)  # ixx iyy izz ixy ixz iyz
        body.explicitinertial = True
        side = _link_side(spec, link.name)
        for i, shape in enumerate(link.shapes):
            _add_shape(body, link, i, shape, side)

    fill(base, spec.link(spec.base_link))
    base.add_site(name=IMU_SITE, pos=list(spec.link(spec.base_link).inertial.com), size=[0.01, 0.0, 0.0])

    rigid = set(spec.upper_body_joint_names) if rigid_upper_body else set()

    def add_children(parent_body, parent_link: str) -> None:
        for joint in spec.child_joints(parent_link):
            welded = joint.name in rigid  # the walk-ready angle folded into the body's frame
            rotation = spec.walk_ready_rotation(joint.name) if welded else joint.origin.rotation
            body = parent_body.add_body(name=joint.child, pos=list(joint.origin.xyz), quat=_quat(rotation))
            if not welded:
                body.add_joint(
                    name=joint.name,
                    type=mujoco.mjtJoint.mjJNT_HINGE,
                    axis=list(joint.axis),
                    range=[joint.lower, joint.upper],
                    limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                    damping=joint.servo.damping,
                    armature=joint.servo.armature,
                    frictionloss=joint.servo.frictionloss,
                )
            fill(body, spec.link(joint.child))
            add_children(body, joint.child)

    add_children(base, spec.base_link)

    for side_name, (foot, origin) in spec.soles.items():
        mj.body(foot).add_site(
            name=sole_site(side_name), pos=list(origin.xyz), quat=_quat(origin.rotation), size=[0.005, 0.0, 0.0]
        )
        # The foot's contact sensor: a box site around every foot shape's lowest part; MuJoCo's touch
        # sensor sums the normal forces of the contacts inside it (what the phase reset reads).
        half, centre = _foot_touch_box(spec, side_name)
        touch = mj.body(foot).add_site(
            name=touch_site(side_name),
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=list(centre),
            quat=_quat(origin.rotation),
            size=list(half),
            rgba=[0.0, 0.0, 0.0, 0.0],
        )
        touch.group = 5
        mj.add_sensor(
            name=touch_sensor(side_name),
            type=mujoco.mjtSensor.mjSENS_TOUCH,
            objtype=mujoco.mjtObj.mjOBJ_SITE,
            objname=touch_site(side_name),
        )

    for joint in (j for j in spec.joints if j.name not in rigid):
        actuator = mj.add_actuator(name=joint.name, target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.set_to_position(kp=joint.servo.kp)
        actuator.ctrlrange = [joint.lower, joint.upper]
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-joint.effort, joint.effort]
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE

    mj.add_sensor(
        name="imu_gyro", type=mujoco.mjtSensor.mjSENS_GYRO, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE
    )
    mj.add_sensor(
        name="imu_accel", type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE
    )
    mj.add_sensor(
        name="imu_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE
    )

    # Keyframe: walk-ready pose, base lowered so the soles rest on the floor.
    model = mj.compile()
    qpos = model.qpos0.copy()
    ctrl = np.zeros(model.nu)
    sole_height = -spec.sole_transform(Side.LEFT, spec.walk_ready)[2, 3] - spec.sole_clearance(Side.LEFT)
    free_adr = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, FREE_JOINT)]
    qpos[free_adr : free_adr + 7] = [0.0, 0.0, sole_height, 1.0, 0.0, 0.0, 0.0]
    for name in (n for n in spec.joint_names if n not in rigid):
        angle = spec.walk_ready.get(name, 0.0)
        qpos[model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)]] = angle
        ctrl[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)] = angle
    mj.add_key(name=WALK_READY_KEY, qpos=qpos.tolist(), ctrl=ctrl.tolist())

    model = mj.compile()
    return MjcfModel(spec=mj, model=model, xml=mj.to_xml())


def mjcf_xml(spec: RobotSpec, **kwargs) -> str:
    """Just the MJCF XML of ``spec`` (see :func:`build_mjcf`)."""
    return build_mjcf(spec, **kwargs).xml
