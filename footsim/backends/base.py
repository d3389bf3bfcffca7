"""The backend interface: execute one double step, report the truth.

A backend knows physics (or planar geometry) and nothing about rewards or observations.
"""

from __future__ import annotations

import importlib
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, fields
from typing import Protocol

import numpy as np

from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.walk.footsteps import DoubleStep, FeetState


@dataclass
class StepResult:
    """What happened while one double step was executed: truth only (the task decides what it means)."""

    pose: Pose2D  # ground-truth navigation pose after the step
    duration_s: float  # simulated seconds the step took
    feet: FeetState | None = None  # planar foot poses after the step
    executed: DoubleStep | None = None  # the double step actually executed (after clipping/interference)
    collided: bool = False
    sim_error: str | None = None  # why the simulation became invalid, if it did
    info: dict = field(default_factory=dict)
    tilt: tuple[float, float] = (0.0, 0.0)  # fused (roll, pitch) of the base at the end [rad]; 0 in 2D
    max_tilt: float = 0.0  # largest |roll| or |pitch| seen during the step [rad]; π/2 lying down; 0 walking in 2D


@dataclass(frozen=True)
class RenderOverlay:
    """Task information a backend may draw on top of its scene (it does not know the task)."""

    goal: Pose2D
    ray_endpoints: np.ndarray | None = None  # (n, 2) world coordinates, from the believed pose
    believed: Pose2D | None = None
    reached: bool = False
    #: The current double step's commanded put-downs (right foot, then left), world frame.
    footsteps: tuple[Pose2D, ...] = ()
    foot_size: tuple[float, float] | None = None  # (length, width) of the footstep markers [m]; None: not drawn


@dataclass(frozen=True)
class TrackingCamera:
    """The render camera of every 3D backend (``backend.camera``): it looks at the point
    ``height`` above the base's ground projection from ``distance`` [m], ``elevation`` [deg]
    (negative: from above) and ``azimuth`` [deg] relative to the robot's heading (the viewing
    direction; −150: in front-left of the robot, looking back at it), with a vertical field of
    view ``fov`` [deg].  MuJoCo, dm-control and PyBullet render from the same :meth:`view`."""

    distance: float = 2.5
    elevation: float = -35.0
    azimuth: float = -150.0
    fov: float = 45.0
    height: float = 0.4  # about the torso origin's height walking (0.39 m)
    #: Shadows cost ~5× the time of a frame with software OpenGL (EGL on a machine without a GPU:
    #: 0.27 s vs 0.055 s for a 480 × 480 MuJoCo frame, measured on this 2-core machine under load).
    shadows: bool = False

    def __post_init__(self) -> None:
        ranges = {
            "distance": lambda v: v > 0,
            "elevation": lambda v: -90.0 < v < 90.0,
            "azimuth": math.isfinite,
            "fov": lambda v: 0.0 < v < 180.0,
            "height": math.isfinite,
        }
        for key, ok in ranges.items():
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not ok(value):
                raise ValueError(f"backend.camera.{key}: invalid value {value!r}")
        if not isinstance(self.shadows, bool):
            raise ValueError(f"backend.camera.shadows must be true or false, got {self.shadows!r}")

    @classmethod
    def from_config(cls, values: dict | None) -> TrackingCamera:
        values = dict(values or {})
        unknown = sorted(set(values) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"backend.camera: unknown key(s) {unknown}; keys: {[f.name for f in fields(cls)]}")
        return cls(**values)

    def view(self, base: Pose2D) -> tuple[np.ndarray, float, float, float]:
        """``(lookat (3,), distance, azimuth, elevation)`` in the world (degrees; MuJoCo's
        free-camera convention: the camera sits at ``lookat − distance · forward``)."""
        lookat = np.array([base.x, base.y, self.height])
        return lookat, self.distance, math.degrees(base.theta) + self.azimuth, self.elevation

    def eye(self, base: Pose2D) -> tuple[np.ndarray, np.ndarray]:
        """Camera position and the point it looks at, world frame."""
        lookat, distance, azimuth, elevation = self.view(base)
        az, el = math.radians(azimuth), math.radians(elevation)
        forward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        return lookat - distance * forward, lookat

    def project(self, points: np.ndarray, base: Pose2D, width: int, height: int) -> np.ndarray:
        """Pixel (column, row) of world points (n, 3) in a ``width`` × ``height`` frame: the
        pinhole model of this camera (square pixels, vertical field of view ``fov``)."""
        eye, target = self.eye(base)
        forward = (target - eye) / np.linalg.norm(target - eye)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        rel = np.atleast_2d(np.asarray(points, dtype=float)) - eye
        depth = rel @ forward
        focal = 0.5 * height / math.tan(math.radians(self.fov) / 2)
        column = 0.5 * width + focal * (rel @ right) / depth
        row = 0.5 * height - focal * (rel @ up) / depth
        return np.stack([column, row], axis=1)


class FrameHook(Protocol):
    """Frames while a 3D double step runs (``Physics3DBackend.frame_hook``; ``footsim.rl.video``).

    At the start of each double step the driver calls ``begin(control_dt, footsteps)`` (the
    step's commanded put-downs in the world); it returns after how many control ticks of the
    step the first frame is due.  After that many ticks the driver calls ``frame(ticks)``, which
    renders and returns the tick count of the next frame (larger).  A frame due after the step's
    last tick waits for the next step's ``begin``.  The hook must not change the simulation."""

    def begin(self, control_dt: float, footsteps: tuple[Pose2D, Pose2D]) -> int: ...

    def frame(self, ticks: int) -> int: ...


class Backend(ABC):
    name: str = "base"
    #: "2d" or "3d": which section of a randomization preset applies (terms_2d / terms_3d).
    kind: str = "3d"
    #: Names of randomization terms this backend supports (see ``footsim.randomization.TERMS``).
    #: Asking for anything else is an error (never a silent no-op).
    capabilities: frozenset[str] = frozenset()
    #: The box over torso, head and arms (length, width, centre offset ahead of the navigation pose)
    #: that the collision check tests besides the feet and trunk, or None (the 2D upper_body model
    #: sets it; the footstep planner plans against it).
    upper_body_box: tuple[float, float, float] | None = None

    @abstractmethod
    def reset(self, scene: Scene, rng: np.random.Generator) -> Pose2D:
        """Place the robot at the origin in ``scene``; return the navigation pose."""

    @abstractmethod
    def execute(self, double_step: DoubleStep) -> StepResult:
        """Execute one double step."""

    def apply_randomization(self, values: dict[str, float]) -> None:
        """Apply drawn randomization values (called before ``reset`` and, for per-step terms,
        before ``execute``).  Only terms in ``capabilities`` are ever passed."""
        if values:
            raise ValueError(f"backend {self.name!r} cannot apply randomization terms {sorted(values)}")

    def render(self, overlay: RenderOverlay | None = None) -> np.ndarray | None:
        return None

    def close(self) -> None:
        """Release what the simulator holds (nothing by default)."""
        return None


@dataclass(frozen=True)
class BackendEntry:
    target: str  # "module:Class"
    extra: str | None  # pip extra that installs the simulator


BACKENDS: dict[str, BackendEntry] = {
    "pymunk": BackendEntry("footsim.backends.pymunk2d:Pymunk2DBackend", None),
    "mujoco": BackendEntry("footsim.backends.mujoco_family.mujoco_sim:MujocoBackend", "mujoco"),
    "dm_control": BackendEntry("footsim.backends.mujoco_family.dm_control_sim:DmControlBackend", "dm_control"),
    "pybullet": BackendEntry("footsim.backends.bullet.sim:PybulletBackend", "pybullet"),
}

_SIMULATOR_MODULES = {"mujoco": "mujoco", "dm_control": "dm_control", "pybullet": "pybullet"}


def register_backend(name: str, target: str, extra: str | None = None) -> None:
    """Make ``backend=name`` build ``target`` ("module:Class", imported when first used).  ``extra``
    is the pip extra that installs its simulator, named in the error when that is missing.  The
    backend's config preset is registered separately (a ``conf/backend/<name>.yaml`` file or a
    ConfigStore node in the ``backend`` group; docs/ARCHITECTURE.md, "Add a backend")."""
    if ":" not in target:
        raise ValueError(f"register_backend({name!r}): target must be 'module:Class', got {target!r}")
    BACKENDS[name] = BackendEntry(target, extra)


def require_known_backends(names, command: str) -> None:
    """A command-line check before any work: exit with a message naming unknown backends."""
    unknown = [n for n in names if n not in BACKENDS]
    if unknown:
        raise SystemExit(f"{command}: unknown backend(s) {', '.join(unknown)}; valid backends: {', '.join(BACKENDS)}")


def backend_class(name: str) -> type[Backend]:
    """Resolve a backend name, with clear errors for unknown names and missing simulators."""
    try:
        entry = BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown backend {name!r}; valid backends: {', '.join(BACKENDS)}") from None
    module_name, cls_name = entry.target.split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        simulator = _SIMULATOR_MODULES.get(name)
        if simulator and err.name and err.name.split(".")[0] == simulator:
            raise ImportError(
                f"backend {name!r} needs the {simulator} package: pip install 'footsim[{entry.extra}]'"
            ) from err
        if err.name == module_name:
            raise NotImplementedError(f"backend {name!r} is not available in this version of footsim") from err
        raise
    return getattr(module, cls_name)
