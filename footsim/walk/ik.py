"""Analytic leg inverse / forward kinematics of a yaw–roll–pitch–pitch–pitch–roll humanoid leg.

The algebra works in the *chain convention*: base (trunk) frame x forward, y left, z up; joint
axes, in the base frame when every chain angle is zero, HipYaw +z, HipRoll +x, HipPitch +y, Knee
+y, AnklePitch +y, AnkleRoll +x; chain angle zero = straight leg, sole parallel to the base.
A robot's own joint angles (its URDF's zeros and axis directions) map to chain angles through
one sign and one offset per joint (:class:`LegChain`): ``robot = sign · (chain − zero)``.

The geometry a :class:`LegChain` describes (one leg, signed for its side):

* the hip-yaw axis is vertical through ``hip_yaw`` (base frame);
* the hip roll and pitch axes intersect in the *hip centre*, ``hip_centre`` from the yaw point in
  the yaw-rotated frame (Wolfgang: 23.1 mm in front of the yaw axis, 41.4 mm below);
* the pitch axes (hip, knee, ankle) are parallel; the ankle centre (pitch/roll intersection)
  lies ``lateral`` along them from the hip centre; ``thigh`` and ``shin`` are the distances hip
  centre → knee axis → ankle centre in the leg plane;
* the IK target, the sole frame, sees the ankle centre at ``ankle`` (sole frame).

A straight, offset-free chain (:meth:`LegGeometry.straight`) is the textbook case the IK solves
in closed form (Kajita et al., *Introduction to Humanoid Robotics*, ch. 2.5).  With a hip-yaw
offset the hip centre moves with the yaw; the solver repeats the closed-form step with the hip
centre of the last yaw and roll until they stop changing (a contraction: the offset is a few
percent of the leg, so each pass shrinks the error by about that factor).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from footsim.compiled import compiled

LEG_JOINTS = ("HipYaw", "HipRoll", "HipPitch", "Knee", "AnklePitch", "AnkleRoll")
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]

# IK passes over the hip-yaw offset: more than enough for 1e-12 rad on Wolfgang (each pass shrinks
# the error by about 0.07); the loop stops as soon as yaw and roll change by less than this.
_IK_PASSES = 12
_IK_CONVERGED = 1e-13


@dataclass(frozen=True)
class LegChain:
    """One leg's kinematics (signed for its side); see the module docstring."""

    hip_yaw: Vec3
    hip_centre: Vec3
    lateral: float
    thigh: float
    shin: float
    ankle: Vec3
    signs: Vec6 = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    zeros: Vec6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("thigh", "shin"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"LegChain.{name} must be a positive length, got {value!r}")
        if any(abs(s) != 1.0 for s in self.signs):
            raise ValueError(f"LegChain.signs must be ±1, got {self.signs!r}")

    @functools.cached_property
    def vector(self) -> np.ndarray:
        """The parameters as one float array (the compiled IK's argument; built once)."""
        return np.array(
            [
                *self.hip_yaw,
                *self.hip_centre,
                self.lateral,
                self.thigh,
                self.shin,
                *self.ankle,
                *self.signs,
                *self.zeros,
            ]
        )

    def to_chain(self, q) -> np.ndarray:
        """Robot joint angles ``(..., 6)`` → chain angles."""
        return np.asarray(self.zeros) + np.asarray(self.signs) * np.asarray(q, dtype=float)

    def to_robot(self, chain) -> np.ndarray:
        """Chain angles ``(..., 6)`` → robot joint angles."""
        return np.asarray(self.signs) * (np.asarray(chain, dtype=float) - np.asarray(self.zeros))

    @property
    def straight_length(self) -> float:
        """Hip-yaw point → sole along the straight leg (vertical)."""
        return -self.hip_centre[2] + self.thigh + self.shin + self.ankle[2]


def straight_chain(
    sign: float, hip_offset_y: float, hip_offset_z: float, thigh: float, shin: float, ankle_to_sole: float
) -> LegChain:
    """An offset-free chain: hip axes intersecting ``hip_offset_z`` below the yaw point at
    ``(0, sign·hip_offset_y, 0)``, the sole ``ankle_to_sole`` straight below the ankle centre."""
    return LegChain(
        (0.0, sign * hip_offset_y, 0.0), (0.0, 0.0, -hip_offset_z), 0.0, thigh, shin, (0.0, 0.0, ankle_to_sole)
    )


def _default_left() -> LegChain:
    return straight_chain(1.0, 0.055, 0.0414, 0.169, 0.170, 0.0529)


def _default_right() -> LegChain:
    return straight_chain(-1.0, 0.055, 0.0414, 0.169, 0.170, 0.0529)


@dataclass(frozen=True)
class LegGeometry:
    """Both legs' kinematics.  The default is the straight chain with Wolfgang-OP's segment
    lengths (0.055 / 0.0414 / 0.169 / 0.170 / 0.0529 m); a robot's own legs come from its spec
    (``RobotSpec.leg_geometry``)."""

    left: LegChain = field(default_factory=_default_left)
    right: LegChain = field(default_factory=_default_right)

    @classmethod
    def straight(
        cls,
        hip_offset_y: float = 0.055,
        hip_offset_z: float = 0.0414,
        thigh: float = 0.169,
        shin: float = 0.170,
        ankle_to_sole: float = 0.0529,
    ) -> LegGeometry:
        """Mirror-image straight chains (see :func:`straight_chain`)."""
        dims = (hip_offset_y, hip_offset_z, thigh, shin, ankle_to_sole)
        return cls(straight_chain(1.0, *dims), straight_chain(-1.0, *dims))

    def chain(self, side) -> LegChain:
        """The chain of ``side`` (a Side or 'left'/'right')."""
        return self.left if side_sign(side) > 0 else self.right

    @property
    def straight_leg_length(self) -> float:
        """Base origin → sole with the left leg straight and vertical (chain angles zero)."""
        return self.left.straight_length - self.left.hip_yaw[2]

    @property
    def signs(self) -> np.ndarray:
        """(12,) robot-joint sign of each chain axis, in :data:`LEG_JOINT_NAMES` order."""
        return np.array(self.left.signs + self.right.signs)

    @property
    def hip_spacing(self) -> float:
        """Lateral distance between the two hip-yaw axes."""
        return self.left.hip_yaw[1] - self.right.hip_yaw[1]


def side_sign(side) -> float:
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
    """Sole pose in the base frame for robot joint angles ``q (n, 6)`` (order :data:`LEG_JOINTS`).

    Returns ``(position (n, 3), rotation (n, 3, 3))``; use :func:`rpy_from_rotation` for angles.
    Written as a plain product of the chain's transforms, independent of the IK's algebra.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[-1] != 6:
        raise ValueError(f"leg joint arrays have 6 columns, got shape {q.shape}")
    chain = leg.chain(side)
    c = chain.to_chain(q)
    n = q.shape[0]

    def moved(R: np.ndarray, v) -> np.ndarray:
        return np.einsum("nij,j->ni", R, np.asarray(v, dtype=float))

    R = _rot_z(c[:, 0])
    pos = np.broadcast_to(np.asarray(chain.hip_yaw), (n, 3)) + moved(R, chain.hip_centre)
    R = R @ _rot_x(c[:, 1])
    pos = pos + moved(R, (0.0, chain.lateral, 0.0))
    R = R @ _rot_y(c[:, 2])
    pos = pos + moved(R, (0.0, 0.0, -chain.thigh))
    R = R @ _rot_y(c[:, 3])
    pos = pos + moved(R, (0.0, 0.0, -chain.shin))
    R = R @ _rot_y(c[:, 4]) @ _rot_x(c[:, 5])
    return pos - moved(R, chain.ankle), R


# --- inverse kinematics ----------------------------------------------------------------------


@compiled
def _chain_ik(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, P, out, k):
    """One leg's IK for the sole at ``p`` with rotation ``r`` (both in the base frame); the chain
    parameters ``P`` are :attr:`LegChain.vector`.  Writes the six robot joint angles to
    ``out[k:k + 6]`` and returns whether the pose is reachable (no limits here)."""
    L1, L2 = P[7], P[8]
    # Ankle centre (pitch/roll intersection) in the base frame.
    ax = px + r00 * P[9] + r01 * P[10] + r02 * P[11]
    ay = py + r10 * P[9] + r11 * P[10] + r12 * P[11]
    az = pz + r20 * P[9] + r21 * P[10] + r22 * P[11]
    yaw = roll = pitch = knee = ankle_pitch = ankle_roll = 0.0
    reachable = False
    for _ in range(_IK_PASSES):
        # Hip centre moved by the yaw (offset from the yaw axis) and by the lateral offset along
        # the rolled pitch axis: the point the leg plane's two-link problem starts from.
        cy, sy = math.cos(yaw), math.sin(yaw)
        cr, sr = math.cos(roll), math.sin(roll)
        u = P[3]
        v = P[4] + P[6] * cr
        w = P[5] + P[6] * sr
        hx = P[0] + cy * u - sy * v - ax
        hy = P[1] + sy * u + cy * v - ay
        hz = P[2] + w - az
        # Hip as seen from the ankle, in the foot frame (R^T d): only the knee, ankle pitch and
        # ankle roll lie between them, which decouples the problem.
        vx = r00 * hx + r10 * hy + r20 * hz
        vy = r01 * hx + r11 * hy + r21 * hz
        vz = r02 * hx + r12 * hy + r22 * hz
        ankle_roll = math.atan2(vy, vz)
        cos_knee = (vx * vx + vy * vy + vz * vz - (L1 * L1 + L2 * L2)) / (2.0 * L1 * L2)
        reachable = abs(cos_knee) <= 1.0
        knee = math.acos(min(max(cos_knee, -1.0), 1.0))  # clamped: out of reach → straight/folded
        # In the leg plane (ankle roll undone) the hip is at (v_x, 0, |v_yz|); with the knee bent
        # the same point is at (-L1 sin k, 0, L1 cos k + L2) before the ankle pitch turns it.
        ankle_pitch = math.atan2(-L1 * math.sin(knee), L1 * math.cos(knee) + L2) - math.atan2(vx, math.hypot(vy, vz))
        # Remaining hip rotation M = Rz(yaw) Rx(roll) Ry(pitch) = R Rx(-ankle_roll) Ry(-b),
        # b = knee + ankle pitch; only the entries the ZXY decomposition needs are formed.
        car, sar = math.cos(ankle_roll), math.sin(ankle_roll)
        b = knee + ankle_pitch
        cb, sb = math.cos(b), math.sin(b)
        m01 = r01 * car - r02 * sar
        m11 = r11 * car - r12 * sar
        m21 = r21 * car - r22 * sar
        r2_rolled = r21 * sar + r22 * car
        m20 = r20 * cb + r2_rolled * sb
        m22 = r2_rolled * cb - r20 * sb
        new_yaw = math.atan2(-m01, m11)
        new_roll = math.asin(min(max(m21, -1.0), 1.0))
        pitch = math.atan2(-m20, m22)
        change = abs(new_yaw - yaw) + abs(new_roll - roll)
        yaw, roll = new_yaw, new_roll
        if change < _IK_CONVERGED:
            break
    chain = (yaw, roll, pitch, knee, ankle_pitch, ankle_roll)
    for j in range(6):
        out[k + j] = P[12 + j] * (chain[j] - P[18 + j])
    return reachable


@compiled
def _batch_ik(p, R, P, use_limits, limits, q, reachable):
    """:func:`_chain_ik` over rows of ``p (n, 3)`` / ``R (n, 3, 3)``; limits ``(6, 2)``."""
    for i in range(p.shape[0]):
        ok = _chain_ik(
            p[i, 0], p[i, 1], p[i, 2],
            R[i, 0, 0], R[i, 0, 1], R[i, 0, 2], R[i, 1, 0], R[i, 1, 1], R[i, 1, 2], R[i, 2, 0], R[i, 2, 1], R[i, 2, 2],
            P, q[i], 0,
        )  # fmt: skip
        if use_limits:
            for j in range(6):
                clipped = min(max(q[i, j], limits[j, 0]), limits[j, 1])
                if abs(clipped - q[i, j]) > _LIMIT_TOLERANCE:
                    ok = False
                q[i, j] = clipped
        reachable[i] = ok


def leg_ik_rotation(foot_pos, foot_rot, side, leg: LegGeometry = LegGeometry(), limits=None):
    """:func:`leg_ik` with the target orientation as rotation matrices ``(n, 3, 3)``."""
    p = np.atleast_2d(np.asarray(foot_pos, dtype=float))
    R = np.asarray(foot_rot, dtype=float).reshape(-1, 3, 3)
    if p.shape[-1] != 3 or R.shape[0] != p.shape[0]:
        raise ValueError(f"foot_pos must be (n, 3) and foot_rot (n, 3, 3); got {p.shape} and {R.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
        raise ValueError("leg IK target contains NaN or inf")
    n = p.shape[0]
    q, reachable = np.empty((n, 6)), np.empty(n, dtype=np.bool_)
    lim = np.zeros((6, 2)) if limits is None else np.ascontiguousarray(limits, dtype=float).reshape(6, 2)
    _batch_ik(
        np.ascontiguousarray(p), np.ascontiguousarray(R), leg.chain(side).vector, limits is not None, lim, q, reachable
    )
    return q, reachable


def leg_ik(foot_pos, foot_rpy, side, leg: LegGeometry = LegGeometry(), limits=None):
    """Robot joint angles that put the sole at ``foot_pos (n, 3)`` with orientation ``foot_rpy (n, 3)``.

    The target is the sole frame relative to the base (trunk) frame; rpy is ``Rz Ry Rx``.
    ``limits`` is ``(6, 2)`` [lower, upper] in :data:`LEG_JOINTS` order (this leg's robot
    angles).  Returns ``(q (n, 6), reachable (n,) bool)``.  Out-of-reach targets get the nearest
    straight/folded knee and are flagged; joints beyond their limits are clipped and flagged; the
    result never contains NaN.
    """
    rpy = np.atleast_2d(np.asarray(foot_rpy, dtype=float))
    if not np.all(np.isfinite(rpy)):
        raise ValueError("leg IK target contains NaN or inf")
    return leg_ik_rotation(foot_pos, rotation_from_rpy(rpy), side, leg, limits)


# --- both legs along a trajectory, compiled ----------------------------------------------------

# The legs as the compiled IK takes them (:func:`ik_legs`): left and right chain vectors, limits, whether to apply them.
IkLegs = tuple[np.ndarray, np.ndarray, np.ndarray, bool]


def legs_ik(
    trunk: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    leg: LegGeometry = LegGeometry(),
    limits: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint targets of both legs for trunk and sole poses ``(6, n)`` (x, y, z, roll, pitch, yaw;
    rpy as ``Rz Ry Rx``) in one common frame: the walk engine's IK over a whole double step.

    Per sample the soles are taken into the trunk frame and solved as :func:`leg_ik`, in one
    compiled loop.  ``limits`` is ``(12, 2)`` in :data:`LEG_JOINT_NAMES` order; clipped samples
    become unreachable.  Returns ``(joints (n, 12), reachable (n,))``, both legs reachable and
    within limits.
    """
    n = trunk.shape[1]
    joints, reachable = np.empty((n, 12)), np.empty(n, dtype=np.bool_)
    _legs_ik(
        np.ascontiguousarray(trunk, dtype=float),
        np.ascontiguousarray(left, dtype=float),
        np.ascontiguousarray(right, dtype=float),
        0,
        n,
        *ik_legs(leg, limits),
        joints,
        reachable,
    )
    return joints, reachable


def legs_ik_ticks(
    local: np.ndarray, start: int, stop: int, legs: IkLegs, joints: np.ndarray, reachable: np.ndarray
) -> None:
    """:func:`legs_ik` of ticks ``start … stop − 1`` of a walk trajectory's support-frame poses
    ``local`` (3, 6, n) (left sole, right sole, trunk; ``WalkTrajectory.local_poses``), written
    into those rows of ``joints`` (n, 12) and ``reachable`` (n,); ``legs`` as :func:`ik_legs`
    returns them.  The walk engine solves a trajectory's ticks this way, a part at a time."""
    _legs_ik(local[2], local[0], local[1], start, stop, *legs, joints, reachable)


def ik_legs(leg: LegGeometry, limits: np.ndarray | None = None) -> IkLegs:
    """The legs as the compiled IK takes them (:func:`legs_ik`, :func:`legs_ik_tick`): the left and
    right :attr:`LegChain.vector`, ``limits`` (12, 2) (zeros when None) and whether to apply them."""
    lim = np.zeros((12, 2)) if limits is None else np.ascontiguousarray(limits, dtype=float)
    return leg.left.vector, leg.right.vector, lim, limits is not None


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
def _legs_ik(trunk, left, right, start, stop, left_chain, right_chain, limits, use_limits, joints, reachable):
    """:func:`legs_ik`'s loop: :func:`_legs_sample` per sample ``start … stop − 1``."""
    for i in range(start, stop):
        reachable[i] = _legs_sample(
            trunk[0, i], trunk[1, i], trunk[2, i], trunk[3, i], trunk[4, i], trunk[5, i],
            left, right, i, left_chain, right_chain, limits, use_limits, joints[i],
        )  # fmt: skip


@compiled
def legs_ik_tick(local, k, dx, dy, left_chain, right_chain, limits, use_limits, joints):
    """Both legs' joint targets at tick ``k`` of a walk trajectory with its trunk moved by
    (``dx``, ``dy``) [m]: the walk node's trunk-PID correction (``QuinticWalk.trunk_shifted_targets``).

    ``local`` (3, 6, n): the trajectory's support-frame poses (left sole, right sole, trunk;
    ``WalkTrajectory.local_poses``); the chains, ``limits`` (12, 2) and ``use_limits`` as
    :func:`legs_ik` passes them (``QuinticWalk.ik_legs``).  Writes the 12 targets into ``joints``
    and returns whether the pose is reachable within the limits; the same float operations as
    :func:`legs_ik` of the shifted poses (one shared per-sample function)."""
    return _legs_sample(
        local[2, 0, k] + dx, local[2, 1, k] + dy, local[2, 2, k], local[2, 3, k], local[2, 4, k], local[2, 5, k],
        local[0], local[1], k, left_chain, right_chain, limits, use_limits, joints,
    )  # fmt: skip


@compiled
def _legs_sample(tx, ty, tz, troll, tpitch, tyaw, left, right, i, left_chain, right_chain, limits, use_limits, joints):
    """One sample of :func:`legs_ik`: the trunk at (``tx`` … ``tyaw``), the soles in column ``i``
    of ``left`` / ``right`` (6, n); the trunk rotation, then each leg's sole in the trunk frame
    (p = Rt^T d, R = Rt^T Rf) and :func:`_chain_ik`, into ``joints`` (12,).  Returns whether both
    legs are reachable and within the limits."""
    t00, t01, t02, t10, t11, t12, t20, t21, t22 = _rpy_matrix(troll, tpitch, tyaw)
    ok = True
    for side in range(2):
        feet = left if side == 0 else right
        dx, dy, dz = feet[0, i] - tx, feet[1, i] - ty, feet[2, i] - tz
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
        chain = left_chain if side == 0 else right_chain
        ok = _chain_ik(px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, chain, joints, 6 * side) and ok
    if use_limits:
        for j in range(12):
            q = joints[j]
            clipped = min(max(q, limits[j, 0]), limits[j, 1])
            if abs(clipped - q) > _LIMIT_TOLERANCE:
                ok = False
            joints[j] = clipped
    return ok
