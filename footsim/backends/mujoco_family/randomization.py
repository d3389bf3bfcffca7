"""Physics randomization on a MuJoCo model, shared by the MuJoCo and dm-control backends.

Both backends compile the same MJCF (``footsim.robots.mjcf``), so the terms are edits of the
same ``mjModel`` arrays.  :func:`capture` records the NOMINAL arrays once, after the backend's
own model options are applied; :func:`apply` writes nominal × values every time, so values never
compound across episodes and a term left out is back at nominal.

What each term edits:

* ``link_mass_scale`` — one factor for every robot body: ``body_mass`` and ``body_inertia``
  (the inertia scales with the mass: same shape, denser material), then ``mj_setConst``
  (subtree masses, invweights).
* ``torso_com_offset_x/_y`` — ``body_ipos`` of the torso, in the torso frame [m].
* ``actuator_kp_scale`` — position actuators ``gainprm[0]`` and ``-biasprm[1]`` (kp).
* ``torque_limit_scale`` — ``actuator_forcerange``.
* ``joint_damping_scale`` — ``dof_damping`` of the robot joints.
* ``floor_friction`` / ``foot_friction`` — sliding friction.  MuJoCo combines two geoms'
  friction by the element-wise *max*, so scaling one side alone would often change nothing.
  While either term is active the feet get geom priority 2 and the floor 1 (the higher
  priority's parameters are used): a foot–floor contact then has sliding friction
  ``nominal · floor_friction · foot_friction`` (the product, as in Bullet) — the feet carry
  the product — and other robot–floor contacts ``nominal floor · floor_friction``.  The
  feet's remaining friction components are the nominal max of foot and floor, so at scale 1
  the contacts are the nominal ones.  (Caveat: a foot touching an obstacle also sees the
  floor factor.)
* ``rolling_friction_scale`` — the feet's rolling friction (``geom_friction[:, 2]``, with the
  same priorities: the contact's is the nominal max of foot and floor × this).  MuJoCo uses it
  only in contacts of condim 6, i.e. with ``backend.rolling_friction`` set; at FootstepNav-v1's
  condim 3 the term changes a coefficient no contact uses.
* ``terrain_slope`` — the floor plane's ``geom_quat``: tilted by the value [rad] about the
  horizontal axis perpendicular to ``terrain_slope_direction`` (the downhill azimuth), through
  the origin.  Obstacles stay vertical.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from footsim.backends.physics3d import PHYSICS_TERMS
from footsim.robots.mjcf import FLOOR_GEOM, import_mujoco

if TYPE_CHECKING:
    from footsim.backends.control import ServoFeedForward
    from footsim.robots.spec import RobotSpec

_FRICTION_TERMS = ("floor_friction", "foot_friction", "rolling_friction_scale")
_MASS_TERMS = ("link_mass_scale", "torso_com_offset_x", "torso_com_offset_y")


@dataclass
class MujocoNominal:
    """Indices of what the terms edit and the nominal values of those arrays."""

    robot_bodies: np.ndarray
    torso: int
    foot_geoms: np.ndarray
    floor_geom: int
    actuators: np.ndarray
    dofs: np.ndarray
    body_mass: np.ndarray
    body_inertia: np.ndarray
    torso_ipos: np.ndarray
    geom_friction: np.ndarray  # rows: foot geoms, then the floor
    geom_priority: np.ndarray  # same rows
    gain: np.ndarray
    bias: np.ndarray
    forcerange: np.ndarray
    damping: np.ndarray
    floor_quat: np.ndarray
    floor_sameframe: int
    mass_edited: bool = False
    scratch: object = None  # an mjData for mj_setConst


def capture(model, torso: int, foot_bodies, floor_geom: int, actuators, dofs) -> MujocoNominal:
    """Record the nominal values (call once, after the backend's model options).

    ``model`` is an ``mujoco.MjModel`` (dm-control: ``physics.model.ptr``); ``torso`` the robot's
    root body id, ``foot_bodies`` the foot body ids, ``actuators`` / ``dofs`` the robot's
    actuator and joint-dof ids."""
    parents = np.asarray(model.body_parentid)
    robot = [b for b in range(model.nbody) if _descends(parents, b, torso)]
    feet = set(int(b) for b in foot_bodies)
    foot_geoms = np.array([g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in feet], dtype=np.intp)
    if floor_geom < 0 or not len(foot_geoms):
        raise ValueError("MuJoCo randomization needs the floor geom and the foot geoms")
    rows = np.concatenate([foot_geoms, [floor_geom]])
    actuators, dofs = np.asarray(actuators, dtype=np.intp), np.asarray(dofs, dtype=np.intp)
    return MujocoNominal(
        robot_bodies=np.array(robot, dtype=np.intp),
        torso=int(torso),
        foot_geoms=foot_geoms,
        floor_geom=int(floor_geom),
        actuators=actuators,
        dofs=dofs,
        body_mass=model.body_mass[robot].copy(),
        body_inertia=model.body_inertia[robot].copy(),
        torso_ipos=model.body_ipos[torso].copy(),
        geom_friction=model.geom_friction[rows].copy(),
        geom_priority=model.geom_priority[rows].copy(),
        gain=model.actuator_gainprm[actuators, 0].copy(),
        bias=model.actuator_biasprm[actuators, 1].copy(),
        forcerange=model.actuator_forcerange[actuators].copy(),
        damping=model.dof_damping[dofs].copy(),
        floor_quat=model.geom_quat[floor_geom].copy(),
        floor_sameframe=int(model.geom_sameframe[floor_geom]),
    )


def _descends(parents: np.ndarray, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = int(parents[body])
    return False


def _positive(values: dict, name: str) -> float:
    value = float(values.get(name, 1.0))
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"randomization {name} must be > 0, got {value}")
    return value


def slope_quat(slope: float, direction: float) -> np.ndarray:
    """Quaternion (w, x, y, z) tilting +z by ``slope`` so the plane descends toward azimuth ``direction``."""
    axis = np.array([-math.sin(direction), math.cos(direction), 0.0])  # z tips toward +direction
    half = 0.5 * float(slope)
    return np.concatenate([[math.cos(half)], math.sin(half) * axis])


def apply(model, nominal: MujocoNominal, values: dict[str, float], mujoco) -> None:
    """Set the randomized arrays to nominal × ``values`` (absent terms: nominal).  After a mass
    or COM change ``mj_setConst`` refreshes the derived constants on a scratch ``mjData`` (it
    resets the data it is given), so this is safe mid-episode too."""
    n = nominal
    m = model
    # masses, inertia, torso COM
    if any(k in values for k in _MASS_TERMS) or n.mass_edited:
        scale = _positive(values, "link_mass_scale")
        m.body_mass[n.robot_bodies] = n.body_mass * scale
        m.body_inertia[n.robot_bodies] = n.body_inertia * scale
        m.body_ipos[n.torso] = n.torso_ipos + np.array(
            [values.get("torso_com_offset_x", 0.0), values.get("torso_com_offset_y", 0.0), 0.0]
        )
        if n.scratch is None:
            n.scratch = mujoco.MjData(m)
        mujoco.mj_setConst(m, n.scratch)
        n.mass_edited = any(k in values for k in _MASS_TERMS)
    # servos
    kp = _positive(values, "actuator_kp_scale")
    m.actuator_gainprm[n.actuators, 0] = n.gain * kp
    m.actuator_biasprm[n.actuators, 1] = n.bias * kp
    m.actuator_forcerange[n.actuators] = n.forcerange * _positive(values, "torque_limit_scale")
    m.dof_damping[n.dofs] = n.damping * _positive(values, "joint_damping_scale")
    # friction
    rows = np.concatenate([n.foot_geoms, [n.floor_geom]])
    friction, priority = n.geom_friction.copy(), n.geom_priority.copy()
    if any(k in values for k in _FRICTION_TERMS):
        floor_scale, foot_scale = _positive(values, "floor_friction"), _positive(values, "foot_friction")
        floor = n.geom_friction[-1]
        feet = np.maximum(n.geom_friction[:-1], floor)  # the nominal max combination
        feet[:, 0] *= floor_scale * foot_scale
        feet[:, 2] *= _positive(values, "rolling_friction_scale")
        friction[:-1] = feet
        friction[-1, 0] = floor[0] * floor_scale
        top = int(n.geom_priority.max())
        priority[:-1], priority[-1] = top + 2, top + 1
    m.geom_friction[rows] = friction
    m.geom_priority[rows] = priority
    # terrain
    slope = float(values.get("terrain_slope", 0.0))
    if not math.isfinite(slope) or abs(slope) >= math.pi / 4:
        raise ValueError(f"randomization terrain_slope must be within ±pi/4 rad, got {slope}")
    if slope:
        m.geom_quat[n.floor_geom] = slope_quat(slope, float(values.get("terrain_slope_direction", 0.0)))
        m.geom_sameframe[n.floor_geom] = 0  # else mj_kinematics copies the world body's frame
    else:
        m.geom_quat[n.floor_geom] = n.floor_quat
        m.geom_sameframe[n.floor_geom] = n.floor_sameframe


def total_robot_mass(model, nominal: MujocoNominal) -> float:
    return float(model.body_mass[nominal.robot_bodies].sum())


class MujocoRandomization:
    """The randomization verbs of a MuJoCo-based ``PhysicsSim`` (mixin: list it before
    ``PhysicsSim``).  Finds everything by name in the compiled model — the robot spec's torso,
    feet, joints and actuators, and the floor geom — and captures the nominal arrays the first
    time it is used on a compiled model.  The sim provides ``self.robot`` and either
    ``self.model`` / ``self.data`` (mujoco) or ``self.physics`` (dm_control)."""

    capabilities = PHYSICS_TERMS  # all of them
    # Provided by the sim:
    robot: RobotSpec
    joint_names: tuple[str, ...]
    _feed_forward: ServoFeedForward | None
    # This mixin's own (set on first use):
    _ff_gain: np.ndarray | None  # the nominal feed-forward gain of a sim without a ServoFeedForward
    _mj_rand_state: tuple[Any, MujocoNominal, np.ndarray | None]  # model, its nominal values and gain

    def mj_model_data(self):
        """The raw ``mujoco.MjModel`` and ``MjData`` of this sim (dm-control: its physics' pointers)."""
        physics = getattr(self, "physics", None)
        if physics is not None:
            return physics.model.ptr, physics.data.ptr
        return self.model, self.data

    def mj_nominal(self) -> MujocoNominal:
        """What the randomization terms edit and its nominal values (captured once per compiled model)."""
        model, _ = self.mj_model_data()
        state = getattr(self, "_mj_rand_state", None)
        if state is not None and state[0] is model:
            return state[1]
        mujoco = import_mujoco()
        robot = self.robot

        def ident(kind, name):
            i = mujoco.mj_name2id(model, kind, name)
            if i < 0:
                raise ValueError(f"MuJoCo randomization: the model has no {kind.name[6:].lower()} {name!r}")
            return i

        body, joint, actuator = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_ACTUATOR
        nominal = capture(
            model,
            ident(body, robot.base_link),
            [ident(body, robot.foot_link(s)) for s in ("left", "right")],
            ident(mujoco.mjtObj.mjOBJ_GEOM, FLOOR_GEOM),
            [ident(actuator, n) for n in self.joint_names],  # the joints the model has
            [int(model.jnt_dofadr[ident(joint, n)]) for n in self.joint_names],
        )
        ff = getattr(self, "_feed_forward", None)  # the MuJoCo servo's kv/kp feed-forward, if any
        nominal_ff = None
        if ff is not None:
            nominal_ff = np.array(ff.gain, dtype=float)
        elif getattr(self, "_ff_gain", None) is not None:
            nominal_ff = np.array(self._ff_gain, dtype=float)
        self._mj_rand_state = (model, nominal, nominal_ff)
        return nominal

    def apply_physics_randomization(self, values: dict[str, float]) -> None:
        unknown = sorted(set(values) - self.capabilities - {"terrain_slope_direction"})
        if unknown:
            raise ValueError(f"{type(self).__name__} cannot apply randomization terms {unknown}")
        nominal = self.mj_nominal()
        model, _ = self.mj_model_data()
        apply(model, nominal, values, import_mujoco())
        nominal_ff = self._mj_rand_state[2]
        if nominal_ff is not None:  # keep the D term kv (qdot_t - qdot) with the new kp
            gain = nominal_ff / _positive(values, "actuator_kp_scale")
            ff = getattr(self, "_feed_forward", None)
            if ff is not None:
                ff.gain[:] = gain  # in place: the driver's compiled tick holds the array
            else:
                self._ff_gain = gain

    def apply_base_force(self, force_xyz) -> None:
        nominal = self.mj_nominal()
        _, data = self.mj_model_data()
        data.xfrc_applied[nominal.torso, :3] = np.asarray(force_xyz, dtype=float)
