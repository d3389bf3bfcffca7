"""Finding and reading the Hydra config groups, and turning them into footsim objects.

``conf/`` sits at the repository top; a built wheel carries it as ``footsim/conf``.  The env
(``gymnasium.make``) reads single presets from it with OmegaConf — no Hydra global state — so
the same preset names work inside and outside a Hydra app.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

_PACKAGE_DIR = Path(__file__).resolve().parent

#: Preset used for each group when nothing is given (dict overrides merge on top of it).
GROUP_DEFAULTS = {
    "backend": "pymunk",
    "task": "nav",
    "noise": "none",
    "robot": "wolfgang",
    "walk": "default",
    "randomization": "none",
}


def conf_dir() -> Path:
    """The config directory: inside the installed package (wheel) or at the repository top."""
    for candidate in (_PACKAGE_DIR / "conf", _PACKAGE_DIR.parent / "conf"):
        if (candidate / "config.yaml").is_file():
            return candidate
    raise FileNotFoundError(
        "footsim's conf/ directory was not found "
        f"(looked in {_PACKAGE_DIR / 'conf'} and {_PACKAGE_DIR.parent / 'conf'})"
    )


def available(group: str) -> list[str]:
    return sorted(p.stem for p in (conf_dir() / group).glob("*.yaml"))


def load_preset(group: str, spec: str | Mapping | None) -> dict:
    """A group's config as a plain dict: a preset name, or a mapping merged over the default preset."""
    if spec is None:
        spec = GROUP_DEFAULTS[group]
    if isinstance(spec, str):
        path = conf_dir() / group / f"{spec}.yaml"
        if not path.is_file():
            raise ValueError(f"unknown {group} preset {spec!r}; available: {', '.join(available(group))}")
        data = OmegaConf.load(path)
        return OmegaConf.to_container(_merge_group_defaults(group, spec, data), resolve=True)
    if isinstance(spec, (Mapping, DictConfig)):
        data = OmegaConf.to_container(spec, resolve=True) if isinstance(spec, DictConfig) else dict(spec)
        base_name = data.get("name") if group in ("backend", "task", "robot") else None
        if base_name is not None and (conf_dir() / group / f"{base_name}.yaml").is_file():
            base = load_preset(group, base_name)
        elif group == "backend":  # never lend one backend's options to another
            base = {}
        else:
            base = load_preset(group, GROUP_DEFAULTS[group])
        return OmegaConf.to_container(OmegaConf.merge(base, data), resolve=True)
    raise TypeError(f"{group} must be a preset name or a mapping, got {type(spec).__name__}")


def _merge_group_defaults(group: str, name: str, data: DictConfig) -> DictConfig:
    """A preset that starts with Hydra's ``defaults: [OTHER, _self_]`` (OTHER a preset of the
    same group) is OTHER with this file's values merged over it, as Hydra composes it."""
    if "defaults" not in data:
        return data
    entries = list(data.pop("defaults"))
    if (
        not all(isinstance(e, str) for e in entries)
        or entries.count("_self_") > 1
        or ("_self_" in entries and entries[-1] != "_self_")
    ):
        raise ValueError(
            f"{group} preset {name!r}: defaults must be preset names of the same group, "
            f"optionally ending with _self_; got {entries}"
        )
    merged = OmegaConf.create({})
    for entry in entries:
        if entry != "_self_":
            merged = OmegaConf.merge(merged, load_preset(group, entry))
    return OmegaConf.merge(merged, data)


def walk_preset_for(backend: str) -> str:
    """The walk preset tuned for a backend (``conf/walk/<backend>.yaml``), else ``default``."""
    return backend if (conf_dir() / "walk" / f"{backend}.yaml").is_file() else GROUP_DEFAULTS["walk"]


def _number(cfg: Mapping, key: str, where: str) -> float:
    value = cfg[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}.{key} must be a finite number, got {value!r}")
    return float(value)


def build_task(task_cfg: Mapping):
    """``(SceneSampler, NavTaskConfig)`` from a task config, naming any bad key."""
    from footsim.tasks.nav import NavTaskConfig
    from footsim.tasks.scenes import SceneSampler

    cfg = dict(task_cfg)
    cfg.pop("name", None)
    scenes = dict(cfg.pop("scenes", {}) or {})
    obstacles = bool(cfg.pop("obstacles", False))
    if "success_angle_deg" in cfg:
        cfg["success_angle"] = math.radians(_number(cfg, "success_angle_deg", "task"))
        cfg.pop("success_angle_deg")
    known = {
        "max_steps",
        "success_distance",
        "success_angle",
        "distance_scale",
        "n_rays",
        "ray_range",
        "ray_scale",
        "reward",
        "terminations",
        "fall_threshold",
        "collision_ends_episode",
        "observe_imu",
        "imu_scale",
        "path_hint",
        "path_hint_lookahead",
        "path_hint_clearance",
        "success_bonus",
    }
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise ValueError(
            f"task: unknown key(s) {unknown}; "
            f"valid: {sorted(known | {'name', 'obstacles', 'scenes', 'success_angle_deg'})}"
        )
    for key in ("observe_imu", "path_hint"):
        if key in cfg and not isinstance(cfg[key], bool):
            raise ValueError(f"task.{key} must be true or false, got {cfg[key]!r}")
    for key in known - {
        "reward",
        "terminations",
        "collision_ends_episode",
        "max_steps",
        "n_rays",
        "observe_imu",
        "path_hint",
    }:
        if key in cfg:
            cfg[key] = _number(cfg, key, "task")
    for key in ("max_steps", "n_rays"):
        if key in cfg:
            cfg[key] = int(_number(cfg, key, "task"))
    if "terminations" in cfg and cfg["terminations"] is None:
        cfg["terminations"] = {}
    sampler_fields = set(SceneSampler.__dataclass_fields__) - {"obstacles"}
    unknown = sorted(set(scenes) - sampler_fields)
    if unknown:
        raise ValueError(f"task.scenes: unknown key(s) {unknown}; valid: {sorted(sampler_fields)}")
    for key in scenes:
        scenes[key] = _number(scenes, key, "task.scenes")
    for key in ("n_obstacles_robot", "n_obstacles_goal"):
        if key in scenes:
            scenes[key] = int(scenes[key])
    return SceneSampler(obstacles=obstacles, **scenes), NavTaskConfig(obstacles=obstacles, **cfg)


def build_noise(noise_cfg: Mapping):
    from footsim.tasks.noise import NoiseModel

    cfg = dict(noise_cfg)
    cfg.pop("name", None)
    known = {k for k in NoiseModel.__dataclass_fields__ if not k.startswith("_")}
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise ValueError(f"noise: unknown key(s) {unknown}; valid: {sorted(known)}")
    # delay_steps is a count: passed as given, NoiseModel rejects non-integers naming the key
    return NoiseModel(**{k: (cfg[k] if k == "delay_steps" else _number(cfg, k, "noise")) for k in cfg})


def build_walk(walk_cfg: Mapping):
    from footsim.walk.params import WalkParams

    cfg = dict(walk_cfg)
    cfg.pop("name", None)
    return WalkParams.from_mapping(cfg)


def build_robot(robot_cfg: Mapping | str):
    from footsim.robots.spec import get_robot, robot_from_config

    return get_robot(robot_cfg) if isinstance(robot_cfg, str) else robot_from_config(dict(robot_cfg))


def backend_kind(backend_cfg: Mapping) -> str:
    """ "2d" or "3d": the kind of the backend a config names (imports its module, not its simulator's state)."""
    from footsim.backends.base import backend_class

    if backend_cfg.get("name") is None:
        raise ValueError("backend: config has no 'name'")
    return backend_class(backend_cfg["name"]).kind


def build_backend(backend_cfg: Mapping, robot, walk, task=None):
    """The backend a config names; a 3D backend also gets the task's ``fall_threshold`` and
    ``collision_ends_episode`` (``task``: a resolved ``NavTaskConfig``; its driver stops simulating
    a double step early when the task will end the episode)."""
    from footsim.backends.base import backend_class

    cfg = dict(backend_cfg)
    name = cfg.pop("name", None)
    if name is None:
        raise ValueError("backend: config has no 'name'")
    cls = backend_class(name)
    for key in ("fall_threshold", "collision_ends_episode"):
        if key in cfg:
            raise ValueError(f"backend.{key} is a task rule: set task.{key} instead")
    if task is not None and cls.kind == "3d":
        cfg.update(fall_threshold=task.fall_threshold, collision_ends_episode=bool(task.collision_ends_episode))
    return cls(robot=robot, walk=walk, **cfg)


def build_randomizer(randomization_cfg: Mapping | None, backend):
    """A ``Randomizer`` for the backend's section of the preset; unsupported terms fail here."""
    from footsim.randomization import Randomizer, parse_terms

    section = "terms_2d" if backend.kind == "2d" else "terms_3d"
    return Randomizer(parse_terms(randomization_cfg, section), backend.name, backend.capabilities)


def to_plain(cfg: Any) -> Any:
    return OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else cfg
