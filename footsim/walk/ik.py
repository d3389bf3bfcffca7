"""Analytic leg inverse / forward kinematics.

Shared kinematic convention (the robot model builders follow the same one):
base (trunk) frame x forward, y left, z up, origin at the centre of the bottom of the torso.
Joint zero = straight leg, foot flat and parallel to the base.  Axes in the zero pose, in the
base frame, for both legs: HipYaw +z, HipRoll +x, HipPitch +y, Knee +y, AnklePitch +y,
AnkleRoll +x; chain order HipYaw → HipRoll → HipPitch → Knee → AnklePitch → AnkleRoll.
The sole frame (the IK target) is the centre of the bottom of the foot plate, directly below
the ankle axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from footsim.compiled import compiled

LEG_JOINTS = ("HipYaw", "HipRoll", "HipPitch", "Knee", "AnklePitch", "AnkleRoll")


@dataclass(frozen=True)
class LegGeometry:
    """Leg chain lengths [m] (Wolfgang-OP defaults from FACTS.md)."""

    hip_offset_y: float = 0.055  # HipYaw axis from the base origin, ±y
    hip_offset_z: float = 0.0414  # HipRoll/HipPitch axes below the HipYaw joint
    thigh: float = 0.169  # HipPitch → Knee
    shin: float = 0.170  # Knee → AnklePitch
    ankle_to_sole: float = 0.0529  # AnkleRoll → sole frame

    @property
    def straight_leg_length(self) -> float:
        """Base origin → sole, straight leg (vertical)."""
        return self.hip_offset_z + self.thigh + self.shin + self.ankle_to_sole

    def side_sign(self, side) -> float:
        """+1 for the left leg (base +y), -1 for the right; accepts a Side or 'left'/'right'."""
        value = getattr(side, "value", side)
        if value == "left":
            return 1.0
        if value == "right":
            return -1.0
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")


# The 12 leg joints in the order of every joint-target array the walk engine produces.
LEG_JOINT_NAMES = tuple("L" + j for j in LEG_JOINTS) + tuple("R" + j for j in LEG_JOINTS)

# A joint counts as clipped (and the pose unreachable) when it moved more than this.
_LIMIT_TOLERANCE = 1e-9


# --- rotations (batched over a leading axis) -------------------------------------------------


def rotation_from_rpy(rpy) -> np.ndarray:
    """``R = Rz(yaw) Ry(pitch) Rx(roll)`` for ``rpy (..., 3)``; returns ``(..., 3, 3)``."""
    rpy = np.asarray(rpy, dtype=float)
    cr, sr = np.cos(rpy[..., 0]), np.sin(rpy[..., 0])
    cp, sp = np.cos(rpy[..., 1]), np.sin(rpy[..., 1])
    cy, sy = np.cos(rpy[..., 2]), np.sin(rpy[..., 2])
    R = np.empty(rpy.shape[:-1] + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def rpy_from_rotation(R) -> np.ndarray:
    """Inverse of :func:`rotation_from_rpy` (pitch in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=float)
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def _rot_x(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0] = 1.0
    R[..., 1, 1], R[..., 1, 2], R[..., 2, 1], R[..., 2, 2] = c, -s, s, c
    return R


def _rot_y(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 1, 1] = 1.0
    R[..., 0, 0], R[..., 0, 2], R[..., 2, 0], R[..., 2, 2] = c, s, -s, c
    return R


def _rot_z(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 2, 2] = 1.0
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1] = c, -s, s, c
    return R


# --- forward kinematics ----------------------------------------------------------------------


def leg_fk(q, side, leg: LegGeometry = LegGeometry()) -> tuple[np.ndarray, np.ndarray]:
    """Sole pose in the base frame for joint angles ``q (n, 6)`` (order :data:`LEG_JOINTS`).

    Returns ``(position (n, 3), rotation (n, 3, 3))``; use :func:`rpy_from_rotation` for angles.
    Written as a plain product of the chain's transforms, independent of the IK's algebra.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[-1] != 6:
        raise ValueError(f"leg joint arrays have 6 columns, got shape {q.shape}")
    sign = leg.side_sign(side)
    n = q.shape[0]
    down = lambda length: np.broadcast_to(np.array([0.0, 0.0, -length]), (n, 3))  # noqa: E731
    R = _rot_z(q[:, 0])
    pos = np.broadcast_to(np.array([0.0, sign * leg.hip_offset_y, 0.0]), (n, 3)) + np.einsum(
        "nij,nj->ni", R, down(leg.hip_offset_z)
    )
    R = R @ _rot_x(q[:, 1]) @ _rot_y(q[:, 2])
    pos = pos + np.einsum("nij,nj->ni", R, down(leg.thigh))
    R = R @ _rot_y(q[:, 3])
    pos = pos + np.einsum("nij,nj->ni", R, down(leg.shin))
    R = R @ _rot_y(q[:, 4]) @ _rot_x(q[:, 5])
    pos = pos + np.einsum("nij,nj->ni", R, down(leg.ankle_to_sole))
    return pos, R


# --- inverse kinematics ----------------------------------------------------------------------


def solve_leg_ik(p, R, side_sign, leg: LegGeometry = LegGeometry()):
    """IK core on component-major arrays: ``p (3, n)``, ``R (3, 3, n)`` (rows, columns, samples).

    Component-major keeps every coordinate a contiguous vector, which is what makes a whole
    half step of IK cost tens of microseconds.  ``side_sign`` is +1 (left) / -1 (right), scalar
    or ``(n,)``.  Returns ``(q (6, n), reachable (n,))`` with no limit handling; callers check
    finiteness.
    """
    L1, L2 = leg.thigh, leg.shin
    a2s = leg.ankle_to_sole
    # Ankle (pitch/roll intersection) sits ankle_to_sole above the sole along the foot's z
    # axis; hip = HipRoll/HipPitch intersection, independent of the hip yaw.  d = hip - ankle.
    dx = -p[0] - a2s * R[0, 2]
    dy = side_sign * leg.hip_offset_y - p[1] - a2s * R[1, 2]
    dz = -leg.hip_offset_z - p[2] - a2s * R[2, 2]
    # Hip as seen from the ankle, in the foot frame (R^T d): only the knee, ankle pitch and
    # ankle roll lie between them, which decouples the problem.
    vx = R[0, 0] * dx + R[1, 0] * dy + R[2, 0] * dz
    vy = R[0, 1] * dx + R[1, 1] * dy + R[2, 1] * dz
    vz = R[0, 2] * dx + R[1, 2] * dy + R[2, 2] * dz
    ankle_roll = np.arctan2(vy, vz)
    cos_knee = (vx * vx + vy * vy + vz * vz - (L1 * L1 + L2 * L2)) / (2.0 * L1 * L2)
    reachable = np.abs(cos_knee) <= 1.0
    knee = np.arccos(np.clip(cos_knee, -1.0, 1.0))  # clamped: out of reach → straight/folded
    # In the plane of the leg (after undoing the ankle roll) the hip is at w = (v_x, 0, |v_yz|);
    # with the knee bent the same point is at u = (-L1 sin k, 0, L1 cos k + L2) before the
    # ankle pitch rotates it, so the ankle pitch is the angle between u and w (about +y).
    ankle_pitch = np.arctan2(-L1 * np.sin(knee), L1 * np.cos(knee) + L2) - np.arctan2(vx, np.hypot(vy, vz))
    # Remaining hip rotation M = Rz(yaw) Rx(roll) Ry(pitch) = R Rx(-ankle_roll) Ry(-b), b = knee +
    # ankle pitch; only the entries the ZXY decomposition needs are formed.
    cr, sr = np.cos(ankle_roll), np.sin(ankle_roll)
    b = knee + ankle_pitch
    cb, sb = np.cos(b), np.sin(b)
    m01 = R[0, 1] * cr - R[0, 2] * sr
    m11 = R[1, 1] * cr - R[1, 2] * sr
    m21 = R[2, 1] * cr - R[2, 2] * sr
    r2_rolled = R[2, 1] * sr + R[2, 2] * cr
    m20 = R[2, 0] * cb + r2_rolled * sb
    m22 = r2_rolled * cb - R[2, 0] * sb
    q = np.empty((6,) + np.shape(cos_knee))
    q[0] = np.arctan2(-m01, m11)  # hip yaw
    q[1] = np.arcsin(np.clip(m21, -1.0, 1.0))  # hip roll
    q[2] = np.arctan2(-m20, m22)  # hip pitch
    q[3] = knee
    q[4] = ankle_pitch
    q[5] = ankle_roll
    return q, reachable


def apply_joint_limits(q: np.ndarray, reachable: np.ndarray, limits) -> tuple[np.ndarray, np.ndarray]:
    """Clip ``q (n, 6)`` to ``limits (6, 2)`` (or ``(n, 6, 2)``); clipped rows become unreachable."""
    lim = np.asarray(limits, dtype=float)
    clipped = np.clip(q, lim[..., 0], lim[..., 1])
    reachable = reachable & np.all(np.abs(clipped - q) <= _LIMIT_TOLERANCE, axis=-1)
    return clipped, reachable


def leg_ik_rotation(foot_pos, foot_rot, side_sign, leg: LegGeometry = LegGeometry(), limits=None):
    """:func:`leg_ik` with the target orientation as rotation matrices ``(n, 3, 3)``.

    ``side_sign`` is +1 (left) / -1 (right), a scalar or one per row, so both legs can be
    solved in one batch.
    """
    p = np.atleast_2d(np.asarray(foot_pos, dtype=float))
    R = np.asarray(foot_rot, dtype=float).reshape(-1, 3, 3)
    if p.shape[-1] != 3 or R.shape[0] != p.shape[0]:
        raise ValueError(f"foot_pos must be (n, 3) and foot_rot (n, 3, 3); got {p.shape} and {R.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
        raise ValueError("leg IK target contains NaN or inf")
    q, reachable = solve_leg_ik(p.T, R.transpose(1, 2, 0), np.asarray(side_sign, dtype=float), leg)
    q = q.T
    if limits is not None:
        q, reachable = apply_joint_limits(q, reachable, limits)
    return q, reachable


def leg_ik(foot_pos, foot_rpy, side, leg: LegGeometry = LegGeometry(), limits=None):
    """Joint angles that put the sole at ``foot_pos (n, 3)`` with orientation ``foot_rpy (n, 3)``.

    The target is the sole frame relative to the base (trunk) frame; rpy is ``Rz Ry Rx``.
    ``limits`` is ``(6, 2)`` [lower, upper] in :data:`LEG_JOINTS` order (this leg's, in the
    shared convention).  Returns ``(q (n, 6), reachable (n,) bool)``.  Out-of-reach targets get
    the nearest straight/folded knee and are flagged; joints beyond their limits are clipped
    and flagged; the result never contains NaN.
    """
    rpy = np.atleast_2d(np.asarray(foot_rpy, dtype=float))
    if not np.all(np.isfinite(rpy)):
        raise ValueError("leg IK target contains NaN or inf")
    return leg_ik_rotation(foot_pos, rotation_from_rpy(rpy), leg.side_sign(side), leg, limits)


# --- both legs along a trajectory, compiled ----------------------------------------------------


def legs_ik(
    trunk: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    leg: LegGeometry = LegGeometry(),
    limits: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint targets of both legs for trunk and sole poses ``(6, n)`` (x, y, z, roll, pitch, yaw;
    rpy as ``Rz Ry Rx``) in one common frame: the walk engine's IK over a whole double step.

    The same algebra as :func:`solve_leg_ik` (sole in the trunk frame, then the decoupled
    solution) in one compiled loop over the samples: the numpy version's ~100 array operations
    on 2n-vectors cost more than the rest of the walk engine together.  ``limits`` is ``(12, 2)``
    in :data:`LEG_JOINT_NAMES` order; clipped samples become unreachable (as
    :func:`apply_joint_limits`).  Returns ``(joints (n, 12), reachable (n,))``, both legs
    reachable and within limits.
    """
    n = trunk.shape[1]
    joints, reachable = np.empty((n, 12)), np.empty(n, dtype=np.bool_)
    lim = np.zeros((12, 2)) if limits is None else np.ascontiguousarray(limits, dtype=float)
    _legs_ik(
        np.ascontiguousarray(trunk, dtype=float),
        np.ascontiguousarray(left, dtype=float),
        np.ascontiguousarray(right, dtype=float),
        leg.hip_offset_y,
        leg.hip_offset_z,
        leg.thigh,
        leg.shin,
        leg.ankle_to_sole,
        lim,
        limits is not None,
        joints,
        reachable,
    )
    return joints, reachable


@compiled
def _rpy_matrix(roll, pitch, yaw):
    """``Rz(yaw) Ry(pitch) Rx(roll)`` as 9 floats, row by row."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )


@compiled
def _legs_ik(trunk, left, right, hip_y, hip_z, L1, L2, a2s, limits, use_limits, joints, reachable):
    """:func:`legs_ik`'s loop: per sample the trunk rotation, then each leg's sole in the trunk
    frame (p = Rt^T d, R = Rt^T Rf) and :func:`solve_leg_ik`'s formulas on scalars."""
    for i in range(trunk.shape[1]):
        t00, t01, t02, t10, t11, t12, t20, t21, t22 = _rpy_matrix(trunk[3, i], trunk[4, i], trunk[5, i])
        ok = True
        for side in range(2):
            feet = left if side == 0 else right
            sign = 1.0 if side == 0 else -1.0
            dx, dy, dz = feet[0, i] - trunk[0, i], feet[1, i] - trunk[1, i], feet[2, i] - trunk[2, i]
            px = t00 * dx + t10 * dy + t20 * dz
            py = t01 * dx + t11 * dy + t21 * dz
            pz = t02 * dx + t12 * dy + t22 * dz
            fr, fp, fy = feet[3, i], feet[4, i], feet[5, i]
            if fr == 0.0 and fp == 0.0:  # flat sole: Rf = Rz(yaw)
                c, s = math.cos(fy), math.sin(fy)
                r00, r01, r02 = t00 * c + t10 * s, t10 * c - t00 * s, t20
                r10, r11, r12 = t01 * c + t11 * s, t11 * c - t01 * s, t21
                r20, r21, r22 = t02 * c + t12 * s, t12 * c - t02 * s, t22
            else:
                f00, f01, f02, f10, f11, f12, f20, f21, f22 = _rpy_matrix(fr, fp, fy)
                r00 = t00 * f00 + t10 * f10 + t20 * f20
                r01 = t00 * f01 + t10 * f11 + t20 * f21
                r02 = t00 * f02 + t10 * f12 + t20 * f22
                r10 = t01 * f00 + t11 * f10 + t21 * f20
                r11 = t01 * f01 + t11 * f11 + t21 * f21
                r12 = t01 * f02 + t11 * f12 + t21 * f22
                r20 = t02 * f00 + t12 * f10 + t22 * f20
                r21 = t02 * f01 + t12 * f11 + t22 * f21
                r22 = t02 * f02 + t12 * f12 + t22 * f22
            # solve_leg_ik, one sample
            hx = -px - a2s * r02
            hy = sign * hip_y - py - a2s * r12
            hz = -hip_z - pz - a2s * r22
            vx = r00 * hx + r10 * hy + r20 * hz
            vy = r01 * hx + r11 * hy + r21 * hz
            vz = r02 * hx + r12 * hy + r22 * hz
            ankle_roll = math.atan2(vy, vz)
            cos_knee = (vx * vx + vy * vy + vz * vz - (L1 * L1 + L2 * L2)) / (2.0 * L1 * L2)
            ok = ok and abs(cos_knee) <= 1.0
            knee = math.acos(min(max(cos_knee, -1.0), 1.0))
            ankle_pitch = math.atan2(-L1 * math.sin(knee), L1 * math.cos(knee) + L2) - math.atan2(
                vx, math.hypot(vy, vz)
            )
            car, sar = math.cos(ankle_roll), math.sin(ankle_roll)
            b = knee + ankle_pitch
            cb, sb = math.cos(b), math.sin(b)
            m01 = r01 * car - r02 * sar
            m11 = r11 * car - r12 * sar
            m21 = r21 * car - r22 * sar
            r2_rolled = r21 * sar + r22 * car
            m20 = r20 * cb + r2_rolled * sb
            m22 = r2_rolled * cb - r20 * sb
            k = 6 * side
            joints[i, k] = math.atan2(-m01, m11)
            joints[i, k + 1] = math.asin(min(max(m21, -1.0), 1.0))
            joints[i, k + 2] = math.atan2(-m20, m22)
            joints[i, k + 3] = knee
            joints[i, k + 4] = ankle_pitch
            joints[i, k + 5] = ankle_roll
        if use_limits:
            for j in range(12):
                q = joints[i, j]
                clipped = min(max(q, limits[j, 0]), limits[j, 1])
                if abs(clipped - q) > _LIMIT_TOLERANCE:
                    ok = False
                joints[i, j] = clipped
        reachable[i] = ok
