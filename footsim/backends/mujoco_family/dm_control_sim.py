"""dm-control backend: the physics verbs of :class:`~footsim.backends.physics3d.PhysicsSim` in
dm_control's own idiom, driven by the shared 3D driver.

* **Model** — an ``mjcf`` object model: ``mjcf.from_xml_string`` of the robot spec's MJCF
  (:func:`footsim.robots.mjcf.build_mjcf`, floor and light included).  The backend edits that
  tree with the ``mjcf`` API before compiling: integrator and offscreen buffer size, the model
  options it shares with the MuJoCo backend (torsional friction on the feet, servo kp and
  damping scales, servo_kv — validated by the same helpers), and the obstacle pool
  (:data:`~footsim.backends.mujoco_family.engine.N_CYLINDERS` cylinders and a sphere for the
  ball, added to the world body).
* **Physics** — ``mjcf.Physics.from_mjcf_model``.  Everything is addressed through
  ``physics.bind(element)`` of the mjcf elements found by name (the bindings are made once at
  :meth:`DmControlSim.build`); a new episode moves / resizes / parks the pool geoms through
  their binding, without recompiling.  ``physics.step(n)`` advances.
* **Faults** — dm_control raises ``PhysicsError`` when a step raises a MuJoCo warning
  (bad qacc / qpos / qvel, …); the sim records it and reports it as ``sim_error``, as it does
  for the MuJoCo backend's fatal warning counters and a non-finite state.
* **Rendering** — a dm_control ``MovableCamera`` (EGL headless, opened at the first frame rather
  than when dm_control is imported: ``_defer_headless_gl_backend``) posed each frame as the shared
  tracking camera (``backend.camera``, :class:`~footsim.backends.base.TrackingCamera`), the
  MuJoCo backend's free-camera pose; the overlay (goal disc and heading arrow, believed pose,
  commanded footsteps, rays) is drawn by its ``scene_callback`` with the MuJoCo backend's code.

Physics is MuJoCo in both backends, so ``conf/walk/dm_control.yaml`` starts from the MuJoCo
walk; the one difference in the model is the MJCF's float round trip through XML text.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys
from typing import Any

import numpy as np

_HEADLESS_GL = ("egl", "osmesa")


def _defer_headless_gl_backend() -> None:
    """Open dm_control's headless OpenGL backend at its first rendering context, not at import.

    ``dm_control._render`` imports the backend that ``MUJOCO_GL`` names when it is imported, and
    the EGL one opens a display then: 53 MB resident in every process, rendering or not
    (docs/BENCHMARKS.md).  Import it with rendering off, then let the first context request
    re-import it (``importlib.reload``) under the chosen ``MUJOCO_GL``; dm_control looks
    ``_render.Renderer`` up at that moment, so its own rendering (``physics.render``, suite
    environments) works as before.  Only for the headless backends (no viewer needs them), and
    only if nothing imported ``dm_control._render`` yet.
    """
    chosen = os.environ.get("MUJOCO_GL", "")
    if "dm_control._render" in sys.modules or chosen.strip().lower() not in _HEADLESS_GL:
        return

    def with_mujoco_gl(value: str, action):
        os.environ["MUJOCO_GL"] = value
        try:
            return action()
        finally:
            os.environ["MUJOCO_GL"] = chosen

    absl_log = logging.getLogger("absl")  # would announce "MUJOCO_GL=off", which is not the user's choice
    level = absl_log.level
    absl_log.setLevel(logging.WARNING)
    try:
        importlib.import_module("mujoco")  # reads MUJOCO_GL too: import it with the real choice first
        render = with_mujoco_gl("disable", lambda: importlib.import_module("dm_control._render"))
    except ImportError:
        return  # dm_control is missing: the import below names the extra to install
    finally:
        absl_log.setLevel(level)

    def open_backend(*args, **kwargs):
        with_mujoco_gl(chosen, lambda: importlib.reload(render))  # replaces this function
        return render.Renderer(*args, **kwargs)

    render.Renderer = open_backend


_defer_headless_gl_backend()

# The imports below come after the deferral: dm_control's GL backend is chosen when it is imported.
from dm_control import mjcf  # noqa: E402 - a missing package: backend_class names the extra to install
from dm_control.mujoco.engine import MovableCamera  # noqa: E402
from dm_control.rl.control import PhysicsError  # noqa: E402

from footsim.backends.base import RenderOverlay, TrackingCamera  # noqa: E402
from footsim.backends.control import ServoFeedForward  # noqa: E402
from footsim.backends.mujoco_family.engine import (  # noqa: E402
    BALL_RGBA,
    N_CYLINDERS,
    OBSTACLE_BIT,
    OBSTACLE_RGBA,
    PARK,
    MujocoEngineSim,
    draw_overlay,
    fatal_warning_ids,
    levelling_quat,
    obstacle_geometry,
    pool_compile_size,
    require_rendering,
)
from footsim.backends.physics3d import Physics3DBackend, SimState, quat_to_matrix  # noqa: E402
from footsim.geometry import Pose2D  # noqa: E402
from footsim.robots.mjcf import FREE_JOINT, build_mjcf, sole_site  # noqa: E402
from footsim.robots.spec import RobotSpec  # noqa: E402
from footsim.scene import Scene  # noqa: E402
from footsim.walk.ik import LEG_JOINT_NAMES  # noqa: E402


class DmControlSim(MujocoEngineSim):
    """``PhysicsSim`` on dm_control: an ``mjcf`` model, ``mjcf.Physics``, bindings by name."""

    mjcf_model: Any = None  # dm_control's mjcf.RootElement and mjcf.Physics (untyped), set by build()
    physics: Any = None
    engine_label = "dm_control"
    _error: str | None = None
    _view: Any = None  # the dm_control MovableCamera frames come from (made at the first frame)
    _overlay: RenderOverlay | None = None

    # -- world ------------------------------------------------------------------------------
    def build(self, robot: RobotSpec, physics_dt: float) -> None:
        self.robot = robot
        self._model_joints(robot)
        model = mjcf.from_xml_string(
            build_mjcf(robot, floor=True, timestep=physics_dt, rigid_upper_body=self.rigid_upper_body).xml
        )
        model.option.integrator = self.integrator
        offscreen = model.visual.get_children("global")
        offscreen.offwidth = offscreen.offheight = self.max_render_size

        # One body per obstacle (see footsim.backends.mujoco_family.engine.POOL_MAX_RADIUS).
        names = [f"obstacle{i}" for i in range(N_CYLINDERS)] + ["ball"]
        self._pool_bodies = [model.worldbody.add("body", name=name, pos=PARK) for name in names]
        self._pool = [
            body.add(
                "geom",
                name=name,
                type="sphere" if name == "ball" else "cylinder",
                size=pool_compile_size(name == "ball")[: 1 if name == "ball" else 2],
                rgba=BALL_RGBA if name == "ball" else OBSTACLE_RGBA,
                contype=OBSTACLE_BIT,
                conaffinity=OBSTACLE_BIT,
            )
            for body, name in zip(self._pool_bodies, names)
        ]
        self.mjcf_model = model
        self.physics = physics = mjcf.Physics.from_mjcf_model(model)
        # physics.step(n) is one mj_step(n); the default legacy step adds an mj_step1 per call to
        # refresh position-dependent fields (~20 % of the physics time), which nothing here reads:
        # the base pose comes from qpos, contacts may be one timestep old, as in the MuJoCo backend.
        physics.legacy_step = False
        self.apply_model_options(physics.model.ptr, robot)  # before anything reads the gains

        # Name mapping, once: mjcf elements by name → bindings into the compiled model / data.
        def find(kind, name):
            element = model.find(kind, name)
            if element is None:
                raise ValueError(f"dm_control model has no {kind} {name!r}")
            return element

        self.joints = {n: find("joint", n) for n in self.joint_names}
        self.actuators = {n: find("actuator", n) for n in self.joint_names}
        for n, actuator in self.actuators.items():  # each actuator drives the joint of its name
            if actuator.joint is not self.joints[n]:
                raise ValueError(f"actuator {n!r} does not drive joint {n!r}")
        self._root = physics.bind(find("joint", FREE_JOINT))
        self._legs = physics.bind([self.actuators[n] for n in LEG_JOINT_NAMES])
        if self.servo_kv > 0:  # the servo D term on the tracking error (the MuJoCo backend's helper)
            self._feed_forward = ServoFeedForward(self.servo_kv, self._legs.gainprm[:, 0], self.control_dt)
        # Hot path (every control tick / check): views into mjData at the bound elements' addresses
        # (a Binding attribute access costs ~20 µs; these are plain numpy views).
        data = physics.data
        self._ctrl, self._leg_ids = data.ctrl, np.asarray(self._legs.element_id, dtype=np.intp)
        adr = int(self._root.qposadr)
        self._qpos, self._qvel, self._root_q = data.qpos, data.qvel, data.qpos[adr : adr + 7]
        self._warnings = data.warning.number
        self._soles = physics.bind([find("site", sole_site(s)) for s in ("left", "right")])
        self._pool_bound = physics.bind(self._pool)
        self._pool_ids = np.asarray(self._pool_bound.element_id, dtype=np.intp)
        self._obstacle_mask = np.zeros(physics.model.ngeom, dtype=bool)
        self._obstacle_mask[self._pool_ids] = True
        self._warning_ids = fatal_warning_ids()
        self.state = SimState(
            quat=self._root_q[3:7],
            position=self._root_q[:3],
            command=self._ctrl,
            leg_ids=self._leg_ids,
            finite=(self._qpos, self._qvel),
            warnings=self._warnings,
            warning_ids=self._warning_ids,
            feed_forward=None if self._feed_forward is None else self._feed_forward.state,
        )
        self._park_all()
        physics.forward()

    def _park_all(self) -> None:
        pool = self._pool_bound
        self.physics.bind(self._pool_bodies).pos = np.tile(PARK, (len(self._pool), 1))
        pool.contype = pool.conaffinity = 0
        pool.rgba[:, 3] = 0.0  # invisible

    def set_obstacles(self, scene: Scene) -> None:
        if len(scene.obstacles) > N_CYLINDERS:
            raise ValueError(
                f"the dm_control backend holds at most {N_CYLINDERS} obstacles, scene has {len(scene.obstacles)}"
            )
        self._park_all()
        placed = [(geom, o, False) for geom, o in zip(self._pool[:-1], scene.obstacles)]
        if scene.ball is not None:
            placed.append((self._pool[-1], scene.ball, True))
        for geom, obstacle, ball in placed:
            bound = self.physics.bind(geom)
            bound.size, pos, bound.rbound, bound.aabb = obstacle_geometry(
                obstacle.x, obstacle.y, obstacle.r + self.obstacle_inflation, ball
            )
            self.physics.bind(geom.parent).pos = pos
            bound.contype = bound.conaffinity = OBSTACLE_BIT
            bound.rgba[3] = 1.0

    # -- robot ------------------------------------------------------------------------------
    def reset_robot(self, base_position: np.ndarray, joint_positions: dict[str, float]) -> None:
        physics = self.physics
        self._error = None
        self.state.fault[0] = 0
        names = [n for n in joint_positions if n not in self._rigid_joints]  # welded ones stay put
        angles = np.array([joint_positions[n] for n in names], dtype=float)
        root = np.concatenate([np.asarray(base_position, dtype=float), [1.0, 0.0, 0.0, 0.0]])
        with physics.reset_context():  # mj_resetData: zero velocities, warnings, time, contacts
            physics.bind([self.joints[n] for n in names]).qpos = angles
            physics.bind([self.actuators[n] for n in names]).ctrl = angles
            self._root.qpos = root
        if self._feed_forward is not None:  # target velocities restart from rest at these angles
            self._feed_forward.reset(physics.bind([self.actuators[n] for n in LEG_JOINT_NAMES]).ctrl)
        # "Upright" means soles flat: the standing pose pitches the trunk, so tilt the base to
        # level the left sole (yaw kept), then lower it until the lowest sole touches the floor
        # (the MuJoCo backend's levelling, shared helper).
        root[3:] = levelling_quat(self._soles.xmat[0])
        self._root.qpos = root
        physics.forward()
        root[2] -= float(self._soles.xpos[:, 2].min()) + self.robot.sole_clearance("left")  # lowest point on the floor
        self._root.qpos = root
        physics.forward()

    def advance(self, n_steps: int) -> None:
        if self._error is not None:
            return  # the state is no longer valid; the driver ends the episode at its next check
        try:
            self.physics.step(n_steps)
        except PhysicsError as err:
            self._error = f"dm_control PhysicsError: {err}"
            self.state.fault[0] = 1

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        q = self._root_q.copy()  # free joint: position, unit quaternion (w, x, y, z)
        return q[:3], quat_to_matrix(q[3:7])

    def sim_error(self) -> str | None:
        return self._error if self._error is not None else super().sim_error()

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
        view = self._view
        if view is None or (view.width, view.height) != (width, height):
            self._free_view()
            view = self._view = MovableCamera(
                self.physics, height=height, width=width, scene_callback=self._draw_overlay
            )
        self._overlay = overlay
        lookat, distance, azimuth, elevation = camera.view(base)
        self.physics.model.vis.global_.fovy = camera.fov  # the free camera's field of view (visual only)
        view.set_pose(lookat, distance, azimuth, elevation)
        return np.array(view.render(render_flag_overrides={"shadow": camera.shadows}))

    def _draw_overlay(self, physics, scene) -> None:
        if self._overlay is not None:
            draw_overlay(scene, self._overlay)

    def _free_view(self) -> None:
        if self._view is not None:
            self._view._scene.free()  # its mjvScene (dm_control's Physics.render frees it the same way)
            self._view = None

    def close(self) -> None:
        self._free_view()
        if self.physics is not None:
            self.physics.free()  # rendering contexts and the native model / data
        self.physics = self.mjcf_model = None
        self._root = self._legs = self._soles = self._pool_bound = None
        self._ctrl = self._qpos = self._qvel = self._root_q = self._warnings = None
        self.state = None  # type: ignore[assignment]  # closed: drop the views of the freed mjData
        self._pool, self.joints, self.actuators = [], {}, {}


class DmControlBackend(Physics3DBackend):
    """The dm-control backend (``backend=dm_control``; options in ``conf/backend/dm_control.yaml``)."""

    name = "dm_control"
    sim_class = DmControlSim
    default_control_dt = 0.01
    default_physics_dt = 0.005
