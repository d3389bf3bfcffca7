"""The backend interface: execute one double step, report the truth.

A backend knows physics (or planar geometry) and nothing about rewards or observations.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

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


class Backend(ABC):
    name: str = "base"
    #: "2d" or "3d": which section of a randomization preset applies (terms_2d / terms_3d).
    kind: str = "3d"
    #: Names of randomization terms this backend supports (see ``footsim.randomization.TERMS``).
    #: Asking for anything else is an error (never a silent no-op).
    capabilities: frozenset[str] = frozenset()

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
