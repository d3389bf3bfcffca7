"""MuJoCo backend: the physics verbs of :class:`~footsim.backends.physics3d.PhysicsSim` on the
``mujoco`` bindings, driven by the shared 3D driver.

The model comes from :func:`footsim.robots.mjcf.build_mjcf`.  Before compiling (once) the spec
gets a fixed pool of obstacle geoms in the world body — ``engine.N_CYLINDERS`` cylinders and one
sphere for the ball.  :meth:`MujocoSim.set_obstacles` moves and resizes them per episode by
editing ``model.geom_pos`` / ``geom_size`` (and the bounding volumes the broad phase uses), and
parks unused ones far below the floor with collisions off: no recompiling per episode.

Joints and actuators are mapped by name once, at :meth:`MujocoSim.build`.  The state contract is
views of ``mjData``: the driver's control law writes the leg actuators' ``data.ctrl`` entries
itself, and a control tick's physics is one ``mj_step(model, data, n)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from footsim.backends.base import RenderOverlay, TrackingCamera
from footsim.backends.control import ServoFeedForward
from footsim.backends.mujoco_family.engine import (
    BALL_RGBA,
    N_CYLINDERS,
    OBSTACLE_BIT,
    OBSTACLE_RGBA,
    PARK,
    MujocoEngineSim,
    draw_overlay,
    fatal_warning_ids,
    levelling_quat,
    mujoco,
    obstacle_geometry,
    pool_compile_size,
    require_rendering,
    set_free_camera,
)
from footsim.backends.physics3d import Physics3DBackend, SimState
from footsim.geometry import Pose2D
from footsim.robots.mjcf import FREE_JOINT, build_mjcf
from footsim.robots.spec import RobotSpec
from footsim.scene import Scene
from footsim.walk.ik import LEG_JOINT_NAMES


class MujocoSim(MujocoEngineSim):
    """``PhysicsSim`` on the ``mujoco`` bindings (position actuators, implicitfast)."""

    model: Any = None  # mujoco.MjModel (untyped bindings), set by build()
    data: Any = None  # mujoco.MjData
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
        for name in names:  # one body per obstacle (see footsim.backends.mujoco_family.engine.POOL_MAX_RADIUS)
            is_ball = name == "ball"
            geom = world.add_body(name=name, pos=PARK.tolist()).add_geom(
                name=name,
                type=mujoco.mjtGeom.mjGEOM_SPHERE if is_ball else mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=pool_compile_size(is_ball),
                rgba=BALL_RGBA if is_ball else OBSTACLE_RGBA,
            )
            geom.contype = geom.conaffinity = OBSTACLE_BIT
        self.model = m = spec.compile()
        self.apply_model_options(m, robot)
        self.robot = robot
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
        if self.servo_kv > 0:  # the servo D term on the tracking error (see apply_model_options)
            self._feed_forward = ServoFeedForward(self.servo_kv, m.actuator_gainprm[self._leg_ctrl, 0], self.control_dt)
        # The obstacle pool's geom ids: the cylinders, then the ball.
        self.obstacle_geoms = np.array(
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in names], dtype=np.intp
        )
        self._ball_geom = int(self.obstacle_geoms[-1])
        self._obstacle_mask = np.zeros(m.ngeom, dtype=bool)
        self._obstacle_mask[self.obstacle_geoms] = True
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
        size, pos, rbound, aabb = obstacle_geometry(x, y, r + self.obstacle_inflation, ball)
        m.geom_size[geom], m.geom_rbound[geom], m.geom_aabb[geom] = size, rbound, aabb
        m.body_pos[m.geom_bodyid[geom]] = pos
        m.geom_contype[geom] = m.geom_conaffinity[geom] = OBSTACLE_BIT
        m.geom_rgba[geom, 3] = 1.0

    def _park(self, geom: int) -> None:
        m = self.model
        m.body_pos[m.geom_bodyid[geom]] = PARK
        m.geom_contype[geom] = m.geom_conaffinity[geom] = 0
        m.geom_rgba[geom, 3] = 0.0  # invisible

    def _park_all(self) -> None:
        for g in self.obstacle_geoms:
            self._park(int(g))

    def set_obstacles(self, scene: Scene) -> None:
        if len(scene.obstacles) > N_CYLINDERS:
            raise ValueError(
                f"the MuJoCo backend holds at most {N_CYLINDERS} obstacles, scene has {len(scene.obstacles)}"
            )
        self._park_all()
        for geom, obstacle in zip(self.obstacle_geoms[:-1], scene.obstacles):
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
        d.qpos[self._free_q + 2] -= lowest + self.robot.sole_clearance("left")  # the feet's lowest points on the floor
        mujoco.mj_forward(m, d)

    def _sole_height(self, site: str) -> float:
        sid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, site)
        return float(self.data.site_xpos[sid, 2])

    def advance(self, n_steps: int) -> None:
        self._step(self.model, self.data, n_steps)

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        q = self.data.qpos
        mujoco.mju_quat2Mat(self._rot, q[self._free_q + 3 : self._free_q + 7])
        return q[self._free_q : self._free_q + 3].copy(), self._rot.reshape(3, 3).copy()

    # -- rendering --------------------------------------------------------------------------
    def render(
        self,
        overlay: RenderOverlay | None,
        width: int,
        height: int,
        camera: TrackingCamera | None = None,
        base: Pose2D | None = None,
    ) -> np.ndarray | None:
        require_rendering()
        camera, base = self.camera_view(camera, base)
        width, height = min(int(width), self.max_render_size), min(int(height), self.max_render_size)
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = mujoco.Renderer(self.model, height=height, width=width)
            self._camera = mujoco.MjvCamera()
        renderer = self._renderer
        set_free_camera(self._camera, self.model, camera, base)
        renderer.update_scene(self.data, camera=self._camera)
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = camera.shadows
        if overlay is not None:
            draw_overlay(renderer.scene, overlay)
        return renderer.render().copy()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.model = self.data = self._warnings = None
        self.state = None  # type: ignore[assignment]  # closed: no state until the next build()


class MujocoBackend(Physics3DBackend):
    """The MuJoCo backend (``backend=mujoco``; options in ``conf/backend/mujoco.yaml``)."""

    name = "mujoco"
    sim_class = MujocoSim
    default_control_dt = 0.01
    default_physics_dt = 0.005
