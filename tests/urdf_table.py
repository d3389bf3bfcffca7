"""The public Wolfgang-OP URDF as tabulated in ``../shared/FACTS.md``, read here independently of
footsim: link inertials, revolute and fixed joints, and a forward kinematics over them written
from the URDF specification (origin = translation, then fixed-axis roll–pitch–yaw; a revolute
joint turns its child about ``axis`` in the joint frame)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shared_facts import facts_text


@dataclass(frozen=True)
class TableJoint:
    name: str
    kind: str  # "revolute" | "fixed"
    parent: str
    child: str
    xyz: np.ndarray
    rpy: tuple[float, float, float]
    axis: np.ndarray | None = None
    lower: float = 0.0
    upper: float = 0.0
    effort: float = 0.0
    velocity: float = 0.0


def _section(text: str, title: str) -> list[list[str]]:
    body = text.split(f"## {title}", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in body.splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def _floats(cell: str) -> list[float]:
    return [float(v) for v in cell.split()]


def links() -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """link -> (mass, COM, 3x3 inertia about the COM)."""
    out = {}
    for row in _section(facts_text(), "URDF: links (mass, COM, inertia about the COM, link frame)")[1:]:
        name, mass, com, ixx, ixy, ixz, iyy, iyz, izz = row[:9]
        i = [float(v) for v in (ixx, ixy, ixz, iyy, iyz, izz)]
        inertia = np.array([[i[0], i[1], i[2]], [i[1], i[3], i[4]], [i[2], i[4], i[5]]])
        out[name] = (float(mass), np.array(_floats(com)), inertia)
    return out


def joints() -> dict[str, TableJoint]:
    out = {}
    for row in _section(facts_text(), "URDF: joints"):
        if len(row) >= 10 and row[1] == "revolute":
            parent, child = (s.strip() for s in row[2].split("->"))
            rpy = tuple(_floats(row[4]))
            out[row[0]] = TableJoint(
                row[0], "revolute", parent, child, np.array(_floats(row[3])), rpy,  # type: ignore[arg-type]
                np.array(_floats(row[5])), float(row[6]), float(row[7]), float(row[8]), float(row[9]),
            )  # fmt: skip
        elif len(row) == 4 and "->" in row[1] and row[0] != "fixed joint":
            parent, child = (s.strip() for s in row[1].split("->"))
            out[row[0]] = TableJoint(row[0], "fixed", parent, child, np.array(_floats(row[2])), tuple(_floats(row[3])))  # type: ignore[arg-type]
    return out


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def forward_kinematics(q: dict[str, float], root: str = "torso") -> dict[str, np.ndarray]:
    """Every frame (4x4) in the ``root`` frame for revolute joint angles ``q`` (missing = 0)."""
    table = joints()
    frames = {root: np.eye(4)}
    grew = True
    while grew:
        grew = False
        for joint in table.values():
            if joint.parent in frames and joint.child not in frames:
                step = np.eye(4)
                step[:3, :3] = _rpy(*joint.rpy)
                step[:3, 3] = joint.xyz
                if joint.kind == "revolute":
                    motion = np.eye(4)
                    motion[:3, :3] = _axis_angle(joint.axis, q.get(joint.name, 0.0))  # type: ignore[arg-type]
                    step = step @ motion
                frames[joint.child] = frames[joint.parent] @ step
                grew = True
    return frames
