"""What the MuJoCo and dm-control backends share (same engine, same MJCF model): the backend
options and their checks (:class:`MujocoModelOptions`), the obstacle pool's geometry, MuJoCo's
fatal warnings, the sole levelling at reset, the render overlay, and the sim verbs that are the
same on both (:class:`MujocoEngineSim`; the randomization verbs are in
``footsim.backends.mujoco_family.randomization``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from footsim.backends.base import RenderOverlay, TrackingCamera
from footsim.backends.control import ServoFeedForward, all_finite
from footsim.backends.mujoco_family.randomization import MujocoRandomization
from footsim.backends.physics3d import PhysicsSim, levelling_rotation
from footsim.geometry import Pose2D
from footsim.robots.mjcf import CONTACT_FRICTION, import_mujoco, touch_sensor
from footsim.robots.spec import RobotSpec
from footsim.walk.ik import LEG_JOINT_NAMES

# mujoco and dm_control pick their GL backend once, at import (the package sets the headless
# default before either is imported): the value that counts is this one.
_MUJOCO_GL_AT_IMPORT = os.environ.get("MUJOCO_GL", "").lower().strip()
mujoco = import_mujoco()


def require_rendering() -> None:
    """Raise a clear error if this process switched rendering off (GL's own error does not say so)."""
    if _MUJOCO_GL_AT_IMPORT in ("disable", "disabled", "off", "false", "0"):
        raise RuntimeError(
            f"rendering is disabled in this process (MUJOCO_GL={_MUJOCO_GL_AT_IMPORT} when mujoco was "
            "imported); start it with MUJOCO_GL=egl (headless) or unset to render"
        )


#: Size of the obstacle pool (the thesis scenes have up to 3 + 3 obstacles and one ball).
N_CYLINDERS = 6
OBSTACLE_HEIGHT = 0.8  # [m] cylinders stand on the floor, taller than the robot's hips
PARK = np.array([0.0, 0.0, -100.0])  # unused obstacles: far below the floor, collisions off
OBSTACLE_BIT = 1  # the world bit of footsim.robots.mjcf: collides with every robot geom
OBSTACLE_RGBA = [0.55, 0.35, 0.2, 1.0]
BALL_RGBA = [0.95, 0.95, 0.95, 1.0]
#: MuJoCo warnings that mean the state can no longer be trusted (MuJoCo resets mjData itself
#: after a bad qacc, so the counters are the only trace of a blow-up).
FATAL_WARNINGS = (
    "mjWARN_BADQACC",
    "mjWARN_BADQPOS",
    "mjWARN_BADQVEL",
    "mjWARN_BADCTRL",
    "mjWARN_CONTACTFULL",
    "mjWARN_CNSTRFULL",
    "mjWARN_INERTIA",
)
#: Footstep markers of the overlay: right foot, left foot (the 2D drawing's colours).
FOOTSTEP_RGBA = ([0.85, 0.2, 0.2, 0.6], [0.15, 0.65, 0.25, 0.6])


def set_free_camera(cam, model, camera: TrackingCamera, base: Pose2D) -> None:
    """Point the ``mjvCamera`` ``cam`` as ``camera`` over the base's planar pose ``base``: a free
    camera (MuJoCo's lookat / distance / azimuth / elevation are the camera's :meth:`view`), and
    the model's free-camera field of view (``vis.global_.fovy``, a visual setting only)."""
    lookat, distance, azimuth, elevation = camera.view(base)
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = lookat
    cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
    model.vis.global_.fovy = camera.fov


# -- helpers shared with the dm-control backend (same engine, same model options) ----------
def check_model_options(
    torsional_friction: float | None, servo_kp_scale: float, servo_damping_scale: float
) -> tuple[float | None, float, float]:
    """Validate the backend's model options; returns them as floats (torsional friction may be None)."""
    _check_non_negative("torsional_friction", torsional_friction, allow_none=True)
    if not (math.isfinite(servo_kp_scale) and servo_kp_scale > 0):
        raise ValueError(f"backend.servo_kp_scale must be > 0, got {servo_kp_scale!r}")
    if not (math.isfinite(servo_damping_scale) and servo_damping_scale >= 0):
        raise ValueError(f"backend.servo_damping_scale must be >= 0, got {servo_damping_scale!r}")
    return (
        (None if torsional_friction is None else float(torsional_friction)),
        float(servo_kp_scale),
        float(servo_damping_scale),
    )


def _check_non_negative(key: str, value: float | None, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ValueError(f"backend.{key} must be >= 0{' (or null)' if allow_none else ''}, got {value!r}")


def foot_contact(
    friction, torsional_friction: float | None, rolling_friction: float | None
) -> tuple[int, list[float]] | None:
    """``(condim, friction)`` of a foot geom with these options, or None to leave it as built.

    Torsional friction needs condim 4, rolling friction condim 6 (MuJoCo: torque limits of
    ``coefficient × normal force``, like Bullet's spinning / rolling friction)."""
    if torsional_friction is None and rolling_friction is None:
        return None
    friction = list(friction) if friction is not None else list(CONTACT_FRICTION)
    friction += list(CONTACT_FRICTION[len(friction) :])  # MJCF may omit trailing values
    if torsional_friction is not None:
        friction[1] = torsional_friction
    if rolling_friction is not None:
        friction[2] = rolling_friction
    return (4 if rolling_friction is None else 6), [float(f) for f in friction]


# Each pool obstacle is the one geom of its own body, welded to the world and moved by its body
# position: MuJoCo's mid-phase culls with per-body bounding volumes fixed at compile time, so a
# geom moved inside one body (the world) would be culled against multi-geom bodies (the feet).
# The pool geoms are compiled at this radius [m], so that volume bounds every obstacle.
POOL_MAX_RADIUS = 2.0


def pool_compile_size(ball: bool) -> list[float]:
    """Compile-time size of a pool geom: the largest obstacle (see :data:`POOL_MAX_RADIUS`)."""
    return [POOL_MAX_RADIUS, 0.0, 0.0] if ball else [POOL_MAX_RADIUS, OBSTACLE_HEIGHT / 2, 0.0]


def obstacle_geometry(x: float, y: float, r: float, ball: bool):
    """``(size, body pos, rbound, aabb)`` of a pool geom placed as an obstacle cylinder or the ball."""
    if not r <= POOL_MAX_RADIUS:
        raise ValueError(f"obstacle radius {r} m (with the backend's obstacle_inflation) exceeds {POOL_MAX_RADIUS} m")
    if ball:
        return (r, 0.0, 0.0), (x, y, r), r, (0.0, 0.0, 0.0, r, r, r)
    h = OBSTACLE_HEIGHT / 2
    return (r, h, 0.0), (x, y, h), math.hypot(r, h), (0.0, 0.0, 0.0, r, r, h)


def levelling_quat(sole_xmat: np.ndarray) -> np.ndarray:
    """Base orientation (w, x, y, z) that makes a sole level, keeping its yaw.

    ``sole_xmat`` is the sole's world rotation computed with the base at identity orientation.
    """
    base_rot = levelling_rotation(sole_xmat)  # base (identity now) → rotation that makes the sole level
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, base_rot.ravel())
    return quat


def fatal_warning_ids() -> np.ndarray:
    """Indices into ``mjData.warning`` of :data:`FATAL_WARNINGS`."""
    return np.array([int(getattr(mujoco.mjtWarning, w)) for w in FATAL_WARNINGS], dtype=np.intp)


def fatal_warning_message(counts: np.ndarray) -> str | None:
    """``counts``: warning counters at :func:`fatal_warning_ids`; a message if any is set."""
    if counts.any():
        return "MuJoCo warning: " + ", ".join(w for w, c in zip(FATAL_WARNINGS, counts) if c)
    return None


def _add_scene_geom(scene, kind, size, pos, mat, rgba):
    if scene.ngeom >= scene.maxgeom:
        return None
    # The whole buffer through the base class: dm_control's MjvScene subclass trims .geoms to ngeom.
    geom = mujoco.MjvScene.geoms.__get__(scene)[scene.ngeom]
    mujoco.mjv_initGeom(
        geom,
        kind,
        np.asarray(size, float),
        np.asarray(pos, float),
        np.asarray(mat, float).ravel(),
        np.asarray(rgba, np.float32),
    )
    scene.ngeom += 1
    return geom


def _scene_arrow(scene, xy, theta, length, width, rgba) -> None:
    start = np.array([xy[0], xy[1], 0.03])
    end = start + np.array([length * math.cos(theta), length * math.sin(theta), 0.0])
    geom = _add_scene_geom(scene, mujoco.mjtGeom.mjGEOM_ARROW, [1, 1, 1], start, np.eye(3), rgba)
    if geom is not None:
        mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_ARROW, width, start, end)


def draw_overlay(scene, overlay: RenderOverlay) -> None:
    """Draw the task overlay into an ``mjvScene``: goal disc + heading arrow, believed pose, the
    commanded footsteps, rays."""
    goal = overlay.goal
    colour = [0.1, 0.8, 0.1, 0.8] if overlay.reached else [0.9, 0.1, 0.1, 0.8]
    eye = np.eye(3)
    _add_scene_geom(scene, mujoco.mjtGeom.mjGEOM_CYLINDER, [0.12, 0.005, 0], [goal.x, goal.y, 0.005], eye, colour)
    _scene_arrow(scene, (goal.x, goal.y), goal.theta, 0.35, 0.02, colour)
    if overlay.believed is not None:
        b = overlay.believed
        _scene_arrow(scene, (b.x, b.y), b.theta, 0.25, 0.015, [0.2, 0.4, 1.0, 0.8])
    if overlay.foot_size is not None:
        half = [0.5 * overlay.foot_size[0], 0.5 * overlay.foot_size[1], 0.004]
        for foot, rgba in zip(overlay.footsteps, FOOTSTEP_RGBA):
            c, s = math.cos(foot.theta), math.sin(foot.theta)
            turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            _add_scene_geom(scene, mujoco.mjtGeom.mjGEOM_BOX, half, [foot.x, foot.y, 0.006], turn, rgba)
    if overlay.ray_endpoints is not None and overlay.believed is not None:
        start = np.array([overlay.believed.x, overlay.believed.y, 0.02])
        for end in np.asarray(overlay.ray_endpoints, float):
            geom = _add_scene_geom(scene, mujoco.mjtGeom.mjGEOM_LINE, [1, 1, 1], start, eye, [1.0, 0.8, 0.0, 0.6])
            if geom is not None:
                mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_LINE, 2.0, start, np.array([end[0], end[1], 0.02]))


INTEGRATORS = ("euler", "implicit", "implicitfast", "rk4")
FRICTION_CONES = ("pyramidal", "elliptic")


class MujocoModelOptions:
    """The backend options both MuJoCo-engine sims (raw bindings, dm-control) take, validated once."""

    def __init__(
        self,
        integrator: str = "implicitfast",
        max_render_size: int = 1024,
        torsional_friction: float | None = None,
        rolling_friction: float | None = None,
        servo_kp_scale: float = 1.0,
        servo_damping_scale: float = 1.0,
        servo_kv: float = 0.0,
        servo_force_limit: float | None = None,
        joint_ref: Mapping[str, float] | None = None,
        contact_solref: Sequence[float] | None = None,
        friction_cone: str = "pyramidal",
        impratio: float = 1.0,
        obstacle_inflation: float = 0.0,
        control_dt: float = 0.01,
        rigid_upper_body: bool = True,
    ):
        if integrator not in INTEGRATORS:
            raise ValueError(f"backend.integrator must be one of {', '.join(INTEGRATORS)}; got {integrator!r}")
        self.integrator = integrator
        self.torsional_friction, self.servo_kp_scale, self.servo_damping_scale = check_model_options(
            torsional_friction, servo_kp_scale, servo_damping_scale
        )
        _check_non_negative("rolling_friction", rolling_friction, allow_none=True)
        self.rolling_friction = None if rolling_friction is None else float(rolling_friction)
        _check_non_negative("obstacle_inflation", obstacle_inflation)
        # Obstacles (and the ball) are this much wider in the physics than in the scene: a training
        # option, with collision_ends_episode it ends episodes that pass closer than this.
        # (MuJoCo's geom margin = gap would report near misses without force, but in MuJoCo 3.17
        # the walk still changed when such excluded contacts existed.)
        self.obstacle_inflation = float(obstacle_inflation)
        if contact_solref is not None:
            solref = [float(v) for v in contact_solref]
            if len(solref) != 2 or not all(math.isfinite(v) and v > 0 for v in solref):
                raise ValueError(
                    f"backend.contact_solref must be [time constant, damping ratio] > 0 or null, got {contact_solref!r}"
                )
            contact_solref = solref
        # MuJoCo's contact softness of every geom (the MJCF's value when null: footsim.robots.mjcf).
        self.contact_solref = contact_solref
        # MuJoCo's friction cone and the ratio of frictional to normal constraint impedance: an
        # elliptic cone with impratio > 1 is MuJoCo's documented way to make contacts slip less.
        if friction_cone not in FRICTION_CONES:
            raise ValueError(f"backend.friction_cone must be one of {', '.join(FRICTION_CONES)}; got {friction_cone!r}")
        self.friction_cone = friction_cone
        number = isinstance(impratio, (int, float)) and not isinstance(impratio, bool)
        if not (number and math.isfinite(impratio) and impratio >= 1):
            raise ValueError(f"backend.impratio must be a number >= 1, got {impratio!r}")
        self.impratio = float(impratio)
        ServoFeedForward(servo_kv, np.ones(1), control_dt)  # validates servo_kv and control_dt
        self.servo_kv, self.control_dt = float(servo_kv), float(control_dt)
        self._feed_forward: ServoFeedForward | None = None  # when servo_kv > 0
        if servo_force_limit is not None and not (
            isinstance(servo_force_limit, (int, float)) and math.isfinite(servo_force_limit) and servo_force_limit > 0
        ):
            raise ValueError(f"backend.servo_force_limit must be > 0 [Nm] or null, got {servo_force_limit!r}")
        # Every actuator's force range ±this [Nm] (the Bit-Bots' MuJoCo model: ±12); null: each
        # servo's URDF effort limit (the built model's).
        self.servo_force_limit = None if servo_force_limit is None else float(servo_force_limit)
        # Per joint, MuJoCo's joint reference [rad] (the MJCF attribute ``ref``): the joint's body
        # sits as the built model's does at angle q - ref, so the joint is offset by -ref from the
        # angle it reports and is commanded to.  The Bit-Bots' MuJoCo model has ref 0.15 on RKnee
        # and -0.15 on LKnee (both knees 0.15 rad more flexed).  Empty: none.
        refs: dict[str, float] = {}
        for name, value in dict(joint_ref or {}).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and abs(value) < 1.0):
                raise ValueError(f"backend.joint_ref.{name} must be a number of radians, |ref| < 1, got {value!r}")
            refs[str(name)] = float(value)
        self.joint_ref = refs
        self.max_render_size = int(max_render_size)
        if not isinstance(rigid_upper_body, (bool, np.bool_)):
            raise ValueError(f"backend.rigid_upper_body must be true or false, got {rigid_upper_body!r}")
        self.rigid_upper_body = bool(rigid_upper_body)
        self.joint_names: tuple[str, ...] = ()  # the robot joints the built model has
        self._foot_bodies: tuple[int, ...] = ()  # (left, right) foot body ids
        self._touch_adr: tuple[int, ...] = ()  # (left, right) touch-sensor addresses: sole_forces
        self._rigid_joints: frozenset[str] = frozenset()

    def _model_joints(self, robot: RobotSpec) -> None:
        """Which joints the model has: all, or the legs only when the upper body is welded."""
        self._rigid_joints = frozenset(robot.upper_body_joint_names if self.rigid_upper_body else ())
        self.joint_names = tuple(n for n in robot.joint_names if n not in self._rigid_joints)

    def apply_model_options(self, m: Any, robot: RobotSpec) -> None:
        """Write the model options into the compiled model ``m`` (a ``mujoco.MjModel``: the MuJoCo
        backend's, or dm-control's ``physics.model.ptr``), once, before the first step.

        Both backends run the same code on the same compiled arrays, so the configured values
        reach the solver unrounded (an XML round trip would keep 6 significant digits)."""
        name2id = mujoco.mj_name2id
        if self.contact_solref is not None:
            m.geom_solref[:] = self.contact_solref
        m.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{self.friction_cone.upper()}")
        m.opt.impratio = self.impratio
        self._foot_bodies = tuple(
            name2id(m, mujoco.mjtObj.mjOBJ_BODY, robot.foot_link(side)) for side in ("left", "right")
        )
        self._touch_adr = tuple(
            int(m.sensor_adr[name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, touch_sensor(side))]) for side in ("left", "right")
        )
        feet = set(self._foot_bodies)
        for g in (g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in feet):  # torsional / rolling friction
            contact = foot_contact(m.geom_friction[g], self.torsional_friction, self.rolling_friction)
            if contact is not None:
                m.geom_condim[g], m.geom_friction[g] = contact
        actuators = [name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name) for name in self.joint_names]
        if self.servo_kp_scale != 1.0:  # position actuators (affine bias): force = kp (ctrl - q)
            m.actuator_gainprm[actuators, 0] *= self.servo_kp_scale
            m.actuator_biasprm[actuators, 1] *= self.servo_kp_scale
        if self.servo_kv > 0:
            # The servo's D term acts on the tracking error, kv (target velocity - velocity), like a
            # Dynamixel's PID, not on the absolute joint velocity (that is what joint damping does,
            # and it caps the joint speed).  The position actuator gives kp (ctrl - q) - kv qdot; the
            # servo feed-forward adds the target velocity as kv/kp * qdot_target to ctrl, which
            # makes it kp (q_t - q) + kv (qdot_t - qdot).
            legs = [name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name) for name in LEG_JOINT_NAMES]
            m.actuator_biasprm[legs, 2] = -self.servo_kv
        if self.servo_force_limit is not None:
            m.actuator_forcerange[actuators] = (-self.servo_force_limit, self.servo_force_limit)
        for name, ref in self.joint_ref.items():
            # MuJoCo's hinge kinematics rotate by qpos - qpos0 and a joint's ref is its qpos0, so
            # writing qpos0 on the compiled model is the MJCF attribute.
            joint = name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if joint < 0 or name not in self.joint_names:
                raise ValueError(
                    f"backend.joint_ref: the model has no joint {name!r}; joints: {list(self.joint_names)}"
                )
            m.qpos0[m.jnt_qposadr[joint]] = ref
        if self.servo_damping_scale != 1.0:  # linear joint damping (the servos' back-EMF drag)
            for name in self.joint_names:
                m.dof_damping[m.jnt_dofadr[name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] *= self.servo_damping_scale


class MujocoEngineSim(MujocoModelOptions, MujocoRandomization, PhysicsSim):
    """What both MuJoCo-engine sims do the same way on a built model: the obstacle contact test
    and the sim-error check over the state contract (``state``), the model options and the
    randomization verbs.  A subclass builds the model its own way and sets ``state``,
    ``_obstacle_mask`` (geoms of the obstacle pool) and ``engine_label``."""

    engine_label = "MuJoCo"
    _obstacle_mask: np.ndarray

    def obstacle_contact(self) -> bool:
        _, data = self.mj_model_data()
        if data.ncon == 0:
            return False
        return bool(self._obstacle_mask[data.contact.geom].any())

    def sole_forces(self) -> tuple[float, float]:
        # The feet's touch sensors (footsim.robots.mjcf): MuJoCo sums each foot's contact normal
        # forces during the step, so reading them is two array lookups.
        _, data = self.mj_model_data()
        left, right = self._touch_adr
        return float(data.sensordata[left]), float(data.sensordata[right])

    def sim_error(self) -> str | None:
        s = self.state
        message = fatal_warning_message(s.warnings[s.warning_ids])
        if message is not None:
            return message
        if not all(all_finite(values) for values in s.finite):
            return f"non-finite {self.engine_label} state (qpos/qvel)"
        return None
