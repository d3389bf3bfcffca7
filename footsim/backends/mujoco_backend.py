"""MuJoCo backend: the physics verbs of :class:`~footsim.backends.physics3d.PhysicsSim` on the
``mujoco`` bindings, driven by the shared 3D driver.

The model comes from :func:`footsim.robots.mjcf.build_mjcf`.  Before compiling (once) the spec
gets a fixed pool of obstacle geoms in the world body — :data:`N_CYLINDERS` cylinders and one
sphere for the ball.  :meth:`MujocoSim.set_obstacles` moves and resizes them per episode by
editing ``model.geom_pos`` / ``geom_size`` (and the bounding volumes the broad phase uses), and
parks unused ones far below the floor with collisions off: no recompiling per episode.

Joints and actuators are mapped by name once, at :meth:`MujocoSim.build`; per control tick the
sim does one fancy-index write into ``data.ctrl`` and one ``mj_step(model, data, n)``.
"""

from __future__ import annotations

import math
import os

import numpy as np

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"  # headless rendering; must be set before mujoco is imported
# mujoco and dm_control pick their GL backend once, at import: the value that counts is this one.
_MUJOCO_GL_AT_IMPORT = os.environ.get("MUJOCO_GL", "").lower().strip()


def require_rendering() -> None:
    """Raise a clear error if this process switched rendering off (GL's own error does not say so)."""
    if _MUJOCO_GL_AT_IMPORT in ("disable", "disabled", "off", "false", "0"):
        raise RuntimeError(
            f"rendering is disabled in this process (MUJOCO_GL={_MUJOCO_GL_AT_IMPORT} when mujoco was "
            "imported); start it with MUJOCO_GL=egl (headless) or unset to render"
        )


from footsim.backends.base import RenderOverlay
from footsim.backends.control import ServoFeedForward, all_finite
from footsim.backends.mujoco_randomization import MujocoRandomization
from footsim.backends.physics3d import Physics3DBackend, PhysicsSim, SimState, levelling_rotation
from footsim.robots.mjcf import CONTACT_FRICTION, FREE_JOINT, build_mjcf, import_mujoco
from footsim.robots.spec import RobotSpec
from footsim.scene import Scene
from footsim.walk.ik import LEG_JOINT_NAMES

mujoco = import_mujoco()

#: Size of the obstacle pool (the thesis scenes have up to 3 + 3 obstacles and one ball).
N_CYLINDERS = 6
OBSTACLE_HEIGHT = 0.8  # [m] cylinders stand on the floor, taller than the robot's hips
_PARK = np.array([0.0, 0.0, -100.0])  # unused obstacles: far below the floor, collisions off
_OBSTACLE_BIT = 1  # the world bit of footsim.robots.mjcf: collides with every robot geom
_OBSTACLE_RGBA = [0.55, 0.35, 0.2, 1.0]
_BALL_RGBA = [0.95, 0.95, 0.95, 1.0]
#: MuJoCo warnings that mean the state can no longer be trusted (MuJoCo resets mjData itself
#: after a bad qacc, so the counters are the only trace of a blow-up).
_FATAL_WARNINGS = (
    "mjWARN_BADQACC",
    "mjWARN_BADQPOS",
    "mjWARN_BADQVEL",
    "mjWARN_BADCTRL",
    "mjWARN_CONTACTFULL",
    "mjWARN_CNSTRFULL",
    "mjWARN_INERTIA",
)
#: The render camera: tracks the torso from this distance [m], elevation and azimuth [deg].
CAMERA_DISTANCE, CAMERA_ELEVATION, CAMERA_AZIMUTH = 2.5, -30.0, -150.0


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


def obstacle_geometry(x: float, y: float, r: float, ball: bool):
    """``(size, pos, rbound, aabb)`` of a pool geom placed as an obstacle cylinder or the ball."""
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
    """Indices into ``mjData.warning`` of :data:`_FATAL_WARNINGS`."""
    return np.array([int(getattr(mujoco.mjtWarning, w)) for w in _FATAL_WARNINGS], dtype=np.intp)


def fatal_warning_message(counts: np.ndarray) -> str | None:
    """``counts``: warning counters at :func:`fatal_warning_ids`; a message if any is set."""
    if counts.any():
        return "MuJoCo warning: " + ", ".join(w for w, c in zip(_FATAL_WARNINGS, counts) if c)
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
    """Draw the task overlay into an ``mjvScene``: goal disc + heading arrow, believed pose, rays."""
    goal = overlay.goal
    colour = [0.1, 0.8, 0.1, 0.8] if overlay.reached else [0.9, 0.1, 0.1, 0.8]
    eye = np.eye(3)
    _add_scene_geom(scene, mujoco.mjtGeom.mjGEOM_CYLINDER, [0.12, 0.005, 0], [goal.x, goal.y, 0.005], eye, colour)
    _scene_arrow(scene, (goal.x, goal.y), goal.theta, 0.35, 0.02, colour)
    if overlay.believed is not None:
        b = overlay.believed
        _scene_arrow(scene, (b.x, b.y), b.theta, 0.25, 0.015, [0.2, 0.4, 1.0, 0.8])
    if overlay.ray_endpoints is not None and overlay.believed is not None:
        start = np.array([overlay.believed.x, overlay.believed.y, 0.02])
        for end in np.asarray(overlay.ray_endpoints, float):
            geom = _add_scene_geom(scene, mujoco.mjtGeom.mjGEOM_LINE, [1, 1, 1], start, eye, [1.0, 0.8, 0.0, 0.6])
            if geom is not None:
                mujoco.mjv_connector(geom, mujoco.mjtGeom.mjGEOM_LINE, 2.0, start, np.array([end[0], end[1], 0.02]))


INTEGRATORS = ("euler", "implicit", "implicitfast", "rk4")


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
        ServoFeedForward(servo_kv, np.ones(1), control_dt)  # validates servo_kv and control_dt
        self.servo_kv, self.control_dt = float(servo_kv), float(control_dt)
        self._feed_forward: ServoFeedForward | None = None  # when servo_kv > 0
        self.max_render_size = int(max_render_size)
        if not isinstance(rigid_upper_body, (bool, np.bool_)):
            raise ValueError(f"backend.rigid_upper_body must be true or false, got {rigid_upper_body!r}")
        self.rigid_upper_body = bool(rigid_upper_body)
        self.joint_names: tuple[str, ...] = ()  # the robot joints the built model has
        self._rigid_joints: frozenset[str] = frozenset()

    def _model_joints(self, robot: RobotSpec) -> None:
        """Which joints the model has: all, or the legs only when the upper body is welded."""
        self._rigid_joints = frozenset(robot.upper_body_joint_names if self.rigid_upper_body else ())
        self.joint_names = tuple(n for n in robot.joint_names if n not in self._rigid_joints)


class MujocoSim(MujocoModelOptions, MujocoRandomization, PhysicsSim):  # randomization verbs: mujoco_randomization
    """``PhysicsSim`` on the ``mujoco`` bindings (position actuators, implicitfast)."""

    model = data = None  # set by build()
    _renderer = None

    # -- world ------------------------------------------------------------------------------
    def build(self, robot: RobotSpec, physics_dt: float) -> None:
        self._model_joints(robot)
        built = build_mjcf(robot, floor=True, timestep=physics_dt, rigid_upper_body=self.rigid_upper_body)
        spec = built.spec
        spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{self.integrator.upper()}")
        spec.visual.global_.offwidth = self.max_render_size
        spec.visual.global_.offheight = self.max_render_size
        world = spec.worldbody
        names = [f"obstacle{i}" for i in range(N_CYLINDERS)] + ["ball"]
        for name in names:
            is_ball = name == "ball"
            geom = world.add_geom(
                name=name,
                type=mujoco.mjtGeom.mjGEOM_SPHERE if is_ball else mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=[0.1, 0.0, 0.0] if is_ball else [0.1, OBSTACLE_HEIGHT / 2, 0.0],
                pos=_PARK.tolist(),
                rgba=_BALL_RGBA if is_ball else _OBSTACLE_RGBA,
            )
            geom.contype = geom.conaffinity = _OBSTACLE_BIT
        self.model = m = spec.compile()
        self.robot = robot
        feet = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, robot.foot_link(s)) for s in ("left", "right")}
        for g in (g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in feet):  # torsional / rolling friction
            contact = foot_contact(m.geom_friction[g], self.torsional_friction, self.rolling_friction)
            if contact is not None:
                m.geom_condim[g], m.geom_friction[g] = contact
        if self.servo_kp_scale != 1.0:  # position actuators: force = kp (ctrl - q)
            m.actuator_gainprm[:, 0] *= self.servo_kp_scale
            m.actuator_biasprm[:, 1] *= self.servo_kp_scale
        if self.servo_damping_scale != 1.0:  # joint damping (the servos' back-EMF drag) of the robot joints
            for name in self.joint_names:
                m.dof_damping[m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] *= (
                    self.servo_damping_scale
                )
        self.data = d = mujoco.MjData(m)

        def jid(name):
            i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            if i < 0:
                raise ValueError(f"MuJoCo model has no joint {name!r}")
            return i

        def aid(name):
            i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
            if i < 0:
                raise ValueError(f"MuJoCo model has no actuator {name!r}")
            return i

        free = jid(FREE_JOINT)
        self._free_q = int(m.jnt_qposadr[free])
        self._free_v = int(m.jnt_dofadr[free])
        self.joint_qpos = {n: int(m.jnt_qposadr[jid(n)]) for n in self.joint_names}
        self.joint_dof = {n: int(m.jnt_dofadr[jid(n)]) for n in self.joint_names}
        self.actuator = {n: aid(n) for n in self.joint_names}
        for n, a in self.actuator.items():  # each actuator drives the joint of its name
            if m.actuator_trnid[a, 0] != jid(n):
                raise ValueError(f"actuator {n!r} does not drive joint {n!r}")
        self._leg_ctrl = np.array([self.actuator[n] for n in LEG_JOINT_NAMES], dtype=np.intp)
        if self.servo_kv > 0:
            # The servo's D term acts on the tracking error, kv (target velocity - velocity), like a
            # Dynamixel's PID, not on the absolute joint velocity (that is what joint damping
            # does, and it caps the joint speed).  MuJoCo's position actuator gives
            # kp (ctrl - q) - kv qdot; set_leg_targets adds the target velocity as a feed-forward
            # kv/kp * qdot_target to ctrl, which makes it kp (q_t - q) + kv (qdot_t - qdot).
            m.actuator_biasprm[self._leg_ctrl, 2] = -self.servo_kv
            self._feed_forward = ServoFeedForward(self.servo_kv, m.actuator_gainprm[self._leg_ctrl, 0], self.control_dt)
        self._obstacle_geoms = np.array(
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in names], dtype=np.intp
        )
        self._ball_geom = int(self._obstacle_geoms[-1])
        self._obstacle_mask = np.zeros(m.ngeom, dtype=bool)
        self._obstacle_mask[self._obstacle_geoms] = True
        self.torso = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, robot.base_link)
        self._sole_sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n) for n in ("l_sole", "r_sole")]
        self._warning_ids = fatal_warning_ids()
        self._warnings = d.warning.number  # a view: d.warning builds a new wrapper per access
        q = self._free_q
        self.state = SimState(
            quat=d.qpos[q + 3 : q + 7],
            position=d.qpos[q : q + 3],
            command=d.ctrl,
            leg_ids=self._leg_ctrl,
            finite=(d.qpos, d.qvel),
            warnings=self._warnings,
            warning_ids=self._warning_ids,
            feed_forward=None if self._feed_forward is None else self._feed_forward.state,
        )
        self._rot = np.zeros(9)
        self._step = mujoco.mj_step
        self._park_all()
        mujoco.mj_forward(m, d)

    def _place(self, geom: int, x: float, y: float, r: float, ball: bool) -> None:
        m = self.model
        m.geom_size[geom], m.geom_pos[geom], m.geom_rbound[geom], m.geom_aabb[geom] = obstacle_geometry(
            x, y, r + self.obstacle_inflation, ball
        )
        m.geom_contype[geom] = m.geom_conaffinity[geom] = _OBSTACLE_BIT
        m.geom_rgba[geom, 3] = 1.0

    def _park(self, geom: int) -> None:
        m = self.model
        m.geom_pos[geom] = _PARK
        m.geom_contype[geom] = m.geom_conaffinity[geom] = 0
        m.geom_rgba[geom, 3] = 0.0  # invisible

    def _park_all(self) -> None:
        for g in self._obstacle_geoms:
            self._park(int(g))

    def set_obstacles(self, scene: Scene) -> None:
        if len(scene.obstacles) > N_CYLINDERS:
            raise ValueError(
                f"the MuJoCo backend holds at most {N_CYLINDERS} obstacles, scene has {len(scene.obstacles)}"
            )
        self._park_all()
        for geom, obstacle in zip(self._obstacle_geoms[:-1], scene.obstacles):
            self._place(int(geom), obstacle.x, obstacle.y, obstacle.r, ball=False)
        if scene.ball is not None:
            self._place(self._ball_geom, scene.ball.x, scene.ball.y, scene.ball.r, ball=True)

    # -- robot ------------------------------------------------------------------------------
    def reset_robot(self, base_position: np.ndarray, joint_positions: dict[str, float]) -> None:
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)  # zero velocities, clear warnings, time, contacts
        d.qpos[self._free_q : self._free_q + 3] = base_position
        d.qpos[self._free_q + 3 : self._free_q + 7] = (1.0, 0.0, 0.0, 0.0)
        for name, angle in joint_positions.items():
            if name in self._rigid_joints:
                continue  # welded at its walk-ready angle
            d.qpos[self.joint_qpos[name]] = angle
            d.ctrl[self.actuator[name]] = angle
        if self._feed_forward is not None:  # target velocities restart from rest at these angles
            self._feed_forward.reset([joint_positions.get(n, d.qpos[self.joint_qpos[n]]) for n in LEG_JOINT_NAMES])
        # "Upright" means soles flat: the walk's standing pose pitches the trunk (trunk_pitch),
        # so tilt the base by the inverse of the left sole's roll/pitch (yaw kept), then lower
        # the robot so the lowest sole touches the floor.  Otherwise it starts on a heel or toe
        # and is still rocking when the first step begins.
        mujoco.mj_kinematics(m, d)
        d.qpos[self._free_q + 3 : self._free_q + 7] = levelling_quat(d.site_xmat[self._sole_sites[0]])
        mujoco.mj_kinematics(m, d)
        lowest = min(self._sole_height(s) for s in ("l_sole", "r_sole"))
        d.qpos[self._free_q + 2] -= lowest
        mujoco.mj_forward(m, d)

    def _sole_height(self, site: str) -> float:
        sid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, site)
        return float(self.data.site_xpos[sid, 2])  # the sole site is on the bottom face

    def advance(self, n_steps: int) -> None:
        self._step(self.model, self.data, n_steps)

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        q = self.data.qpos
        mujoco.mju_quat2Mat(self._rot, q[self._free_q + 3 : self._free_q + 7])
        return q[self._free_q : self._free_q + 3].copy(), self._rot.reshape(3, 3).copy()

    def obstacle_contact(self) -> bool:
        d = self.data
        if d.ncon == 0:
            return False
        return bool(self._obstacle_mask[d.contact.geom].any())

    def sim_error(self) -> str | None:
        d = self.data
        message = fatal_warning_message(self._warnings[self._warning_ids])
        if message is not None:
            return message
        if not (all_finite(d.qpos) and all_finite(d.qvel)):
            return "non-finite MuJoCo state (qpos/qvel)"
        return None

    # -- rendering --------------------------------------------------------------------------
    def render(self, overlay: RenderOverlay | None, width: int, height: int) -> np.ndarray | None:
        require_rendering()
        width, height = min(int(width), self.max_render_size), min(int(height), self.max_render_size)
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = mujoco.Renderer(self.model, height=height, width=width)
            self._camera = mujoco.MjvCamera()
            self._camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
            self._camera.trackbodyid = self.torso
            self._camera.distance = CAMERA_DISTANCE
            self._camera.elevation = CAMERA_ELEVATION
            self._camera.azimuth = CAMERA_AZIMUTH  # in front-left of a robot facing +x, looking back at it
        renderer = self._renderer
        renderer.update_scene(self.data, camera=self._camera)
        if overlay is not None:
            draw_overlay(renderer.scene, overlay)
        return renderer.render().copy()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.model = self.data = self._warnings = None


class MujocoBackend(Physics3DBackend):
    """The MuJoCo backend (``backend=mujoco``; options in ``conf/backend/mujoco.yaml``)."""

    name = "mujoco"
    sim_class = MujocoSim
    default_control_dt = 0.01
    default_physics_dt = 0.005
