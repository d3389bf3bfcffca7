"""Build a URDF (PyBullet, RViz) from a :class:`~footsim.robots.spec.RobotSpec` with ElementTree.

Mapping from the spec:

* every link becomes a ``<link>`` with ``<inertial>`` (mass, COM, full inertia tensor) and one
  ``<visual>`` + ``<collision>`` pair per primitive shape;
* URDF has no capsule, so a capsule becomes a cylinder plus two spheres at its ends (exact
  same volume; PyBullet builds a compound shape from them);
* every joint becomes a ``revolute`` joint with ``<limit lower upper effort velocity>`` and
  ``<dynamics damping friction>`` (friction = the servo's frictionloss).  URDF has no armature
  and no actuator gains: a PyBullet backend reads ``kp``/armature from the spec itself;
* each sole frame is a link ``l_sole`` / ``r_sole`` on a fixed joint ``l_sole_frame`` /
  ``r_sole_frame`` below its foot, with an explicit zero-mass ``<inertial>`` (without one
  PyBullet would give the link 1 kg);
* the file is self-contained: no meshes, materials inline.

PyBullet ignores self-collision unless loaded with ``URDF_USE_SELF_COLLISION``; the MJCF model
restricts self-collision to the two lower legs/feet (see ``footsim.robots.mjcf``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from footsim.robots.spec import Box, Capsule, Cylinder, Link, Origin, RobotSpec, Side, Sphere, sole_frame_name


def _fmt(*values: float) -> str:
    return " ".join(f"{v:.9g}" for v in values)


def _origin(parent: ET.Element, origin: Origin) -> None:
    ET.SubElement(parent, "origin", xyz=_fmt(*origin.xyz), rpy=_fmt(*origin.rpy))


def _primitives(shape) -> list[tuple[Origin, str, dict[str, str]]]:
    """(origin, URDF geometry tag, attributes) for one spec shape."""
    if isinstance(shape, Box):
        return [(shape.origin, "box", {"size": _fmt(*shape.size)})]
    if isinstance(shape, Sphere):
        return [(shape.origin, "sphere", {"radius": _fmt(shape.radius)})]
    if isinstance(shape, Cylinder):
        return [(shape.origin, "cylinder", {"radius": _fmt(shape.radius), "length": _fmt(shape.length)})]
    if isinstance(shape, Capsule):
        out = [(shape.origin, "cylinder", {"radius": _fmt(shape.radius), "length": _fmt(shape.length)})]
        rotation = shape.origin.rotation
        for end in (-0.5, 0.5):  # sphere centres on the capsule axis (local z)
            cx, cy, cz = (float(v) for v in shape.origin.xyz + rotation @ (0.0, 0.0, end * shape.length))
            out.append((Origin((cx, cy, cz), shape.origin.rpy), "sphere", {"radius": _fmt(shape.radius)}))
        return out
    raise TypeError(f"unsupported shape {shape!r}")  # pragma: no cover - RobotSpec validates shapes


def _link(robot: ET.Element, link: Link) -> None:
    element = ET.SubElement(robot, "link", name=link.name)
    inertial = ET.SubElement(element, "inertial")
    _origin(inertial, Origin(link.inertial.com))
    ET.SubElement(inertial, "mass", value=_fmt(link.inertial.mass))
    ixx, iyy, izz, ixy, ixz, iyz = link.inertial.inertia
    ET.SubElement(
        inertial, "inertia", ixx=_fmt(ixx), ixy=_fmt(ixy), ixz=_fmt(ixz), iyy=_fmt(iyy), iyz=_fmt(iyz), izz=_fmt(izz)
    )
    index = 0
    for shape in link.shapes:
        for origin, tag, attrs in _primitives(shape):
            visual = ET.SubElement(element, "visual", name=f"{link.name}_visual{index}")
            _origin(visual, origin)
            ET.SubElement(ET.SubElement(visual, "geometry"), tag, attrs)
            material = ET.SubElement(visual, "material", name=f"{link.name}_color")
            ET.SubElement(material, "color", rgba=_fmt(*link.rgba))
            collision = ET.SubElement(element, "collision", name=f"{link.name}_collision{index}")
            _origin(collision, origin)
            ET.SubElement(ET.SubElement(collision, "geometry"), tag, attrs)
            index += 1


def build_urdf(spec: RobotSpec, rigid_upper_body: bool = False, sole_frames: bool = True) -> ET.Element:
    """The ``<robot>`` element of ``spec``'s URDF; with ``rigid_upper_body`` the arm and head
    joints are welded at their walk-ready angles (as the MJCF's ``rigid_upper_body``): the arm and
    head links are merged into the torso link (:meth:`RobotSpec.with_rigid_upper_body`).
    ``sole_frames=False`` leaves out the massless sole-frame links: PyBullet's
    ``URDF_MERGE_FIXED_LINKS`` misplaces the foot's centre of mass when it merges a child whose
    fixed joint is rotated (Wolfgang's sole frames are yawed 90° in the foot links; measured: the
    foot COM 9 cm off), and the PyBullet backend takes the sole poses from the spec anyway."""
    if not spec.joints:
        raise ValueError(f"robot {spec.name!r} has no kinematic model to build")
    if rigid_upper_body:
        spec = spec.with_rigid_upper_body()
    robot = ET.Element("robot", name=spec.name)
    # Base first: URDF loaders take the link that is no joint's child as the root.
    _link(robot, spec.link(spec.base_link))
    for link in spec.links:
        if link.name != spec.base_link:
            _link(robot, link)
    for joint in spec.joints:
        element = ET.SubElement(robot, "joint", name=joint.name, type="revolute")
        ET.SubElement(element, "parent", link=joint.parent)
        ET.SubElement(element, "child", link=joint.child)
        _origin(element, joint.origin)
        ET.SubElement(element, "axis", xyz=_fmt(*joint.axis))
        ET.SubElement(
            element,
            "limit",
            lower=_fmt(joint.lower),
            upper=_fmt(joint.upper),
            effort=_fmt(joint.effort),
            velocity=_fmt(joint.velocity),
        )
        ET.SubElement(element, "dynamics", damping=_fmt(joint.servo.damping), friction=_fmt(joint.servo.frictionloss))
    for side in (Side.LEFT, Side.RIGHT) if sole_frames else ():
        if side.value not in spec.soles:
            continue
        foot, origin = spec.sole(side)
        name = sole_frame_name(side)
        sole = ET.SubElement(robot, "link", name=name)
        inertial = ET.SubElement(sole, "inertial")
        _origin(inertial, Origin())
        ET.SubElement(inertial, "mass", value="0")
        ET.SubElement(inertial, "inertia", ixx="0", ixy="0", ixz="0", iyy="0", iyz="0", izz="0")
        frame_joint = ET.SubElement(robot, "joint", name=f"{name}_frame", type="fixed")
        ET.SubElement(frame_joint, "parent", link=foot)
        ET.SubElement(frame_joint, "child", link=name)
        _origin(frame_joint, origin)
    return robot


def urdf_xml(spec: RobotSpec, rigid_upper_body: bool = False, sole_frames: bool = True) -> str:
    """The URDF of ``spec`` as an indented XML document (options: see :func:`build_urdf`)."""
    robot = build_urdf(spec, rigid_upper_body, sole_frames)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"
