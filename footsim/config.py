"""Composing the Hydra config groups of ``conf/``, and turning them into footsim objects.

``conf/`` sits at the repository top; a built wheel carries it as ``footsim/conf``.  There is one
composer, Hydra's: the command lines compose through ``hydra.main``, and ``gymnasium.make`` /
``footsim.make_env`` / :func:`load_preset` through Hydra's compose API over the same files and the
schemas of :mod:`footsim.schema`.  The defaults of the env's groups are the defaults list of
``conf/env.yaml`` (``footsim-train``'s ``conf/config.yaml`` includes it).  Composing works inside a
running Hydra app as well (its global state is set aside and restored) and leaves no global state
behind, so subprocess env workers compose on their own.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from footsim import schema
from footsim.backends.base import BACKENDS, backend_class
from footsim.randomization import Randomizer, parse_terms
from footsim.robots.registry import get_robot, robot_from_config
from footsim.tasks.nav import DEFAULT_REWARD, NavTaskConfig
from footsim.tasks.noise import NoiseModel
from footsim.tasks.scenes import SceneSampler
from footsim.walk.params import WalkParams

if TYPE_CHECKING:
    from footsim.backends.base import Backend

_PACKAGE_DIR = Path(__file__).resolve().parent
#: The env's config groups, in the order ``FootstepEnv`` takes them.
ENV_GROUPS = ("backend", "task", "noise", "robot", "walk", "randomization")
#: Groups whose mapping form picks its base preset by ``name`` (the others merge over their default).
_NAMED_BASE = ("backend", "task", "robot")


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
    """A group's presets: the YAML files in ``conf/<group>/`` and the nodes user code stored in
    Hydra's ConfigStore under that group (``ConfigStore.instance().store(group=..., name=...)``)."""
    from hydra.core.config_store import ConfigStore

    files = {p.stem for p in (conf_dir() / group).glob("*.yaml")}
    try:
        stored = {name.removesuffix(".yaml") for name in ConfigStore.instance().list(group)}
    except OSError:  # ConfigStore raises IOError for a group nobody stored into
        stored = set()
    return sorted(files | stored)


@contextmanager
def _hydra(controllers: bool = False) -> Iterator[None]:
    """Hydra initialised on ``conf/`` for the duration; a running app's global state is set aside
    and restored afterwards."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.utils import JobRuntime

    schema.register_schemas(controllers)
    global_hydra = GlobalHydra.instance()
    running = global_hydra.hydra if global_hydra.is_initialized() else None
    # initialize_config_dir renames the running app's job (JobRuntime "name"); a multirun that
    # composes its next job in this process would name it (and its log file) "footsim"
    job_name = JobRuntime.instance().conf.get("name")
    if running is not None:
        global_hydra.clear()
    try:
        with initialize_config_dir(config_dir=str(conf_dir()), version_base="1.3", job_name="footsim"):
            yield
    finally:
        if running is not None:
            global_hydra = GlobalHydra.instance()
            if global_hydra.is_initialized():
                global_hydra.clear()
            global_hydra.initialize(running)
        JobRuntime.instance().set("name", job_name)


@functools.lru_cache(maxsize=128)
def _composed(config_name: str | None, overrides: tuple[str, ...]) -> DictConfig:
    from hydra import compose as hydra_compose

    with _hydra(controllers=any(o.lstrip("+~").startswith("controller") for o in overrides)):
        return hydra_compose(config_name=config_name, overrides=list(overrides))


def compose(config_name: str | None = "env", overrides: Sequence[str] = ()) -> DictConfig:
    """Hydra's composition of ``conf/<config_name>.yaml`` with command-line style ``overrides``
    (a fresh copy: callers may modify it).  ``config_name=None`` composes only the overrides'
    groups (``+walk=mujoco``)."""
    return copy.deepcopy(_composed(config_name, tuple(overrides)))


def _check_preset(group: str, name: Any) -> str:
    if not isinstance(name, str) or name not in available(group):
        if group == "backend":
            raise ValueError(f"unknown backend {name!r}; valid backends: {', '.join(BACKENDS)}")
        raise ValueError(f"unknown {group} preset {name!r}; available: {', '.join(available(group))}")
    return name


def _preset_node(group: str, name: str | None, backend: str | None = None) -> DictConfig:
    """A group's preset as composed (schema-typed); ``name=None``: the env's default for the group
    (for ``walk``: the walk composed for ``backend``)."""
    if name is None:
        overrides = [f"backend={_check_preset('backend', backend)}"] if backend is not None else []
        env = compose("env", overrides)
        if group not in env:
            raise ValueError(f"{group} has no default preset; available: {', '.join(available(group))}")
        return env[group]
    return compose(None, [f"+{group}={_check_preset(group, name)}"])[group]


def _closed(node: Any) -> bool:
    """Whether a composed node is a schema's (fixed keys) rather than an open ``Dict[str, ...]``."""
    return isinstance(node, DictConfig) and OmegaConf.get_type(node) not in (dict, None)


def _check_keys(node: Any, values: Mapping, where: str) -> None:
    for key, value in values.items():
        if _closed(node) and key not in node.keys():  # (`in` is false for a key left ???)
            raise ValueError(f"{where}: unknown key(s) {[key]}; valid: {sorted(node.keys())}")
        child = (
            node[key] if isinstance(node, DictConfig) and key in node and not OmegaConf.is_missing(node, key) else None
        )
        if isinstance(value, Mapping) and isinstance(child, DictConfig):
            _check_keys(child, value, f"{where}.{key}")


def merge_checked(base: DictConfig, values: Mapping, where: str) -> DictConfig:
    """``values`` merged over a composed (schema-typed) ``base``.  A key the schema lacks fails here,
    naming it and the valid keys; the values pass unconverted to the code that builds the objects,
    whose checks name the key, the bad value and what is allowed (stricter than OmegaConf's
    conversions, which would read ``"2"`` as an integer)."""
    _check_keys(base, values, where)
    try:
        return cast(DictConfig, OmegaConf.merge(OmegaConf.create(plain_config(base)), values))
    except OmegaConfBaseException as err:
        raise ValueError(f"{where}: {str(err).splitlines()[0]}") from None


def _base_preset(group: str, spec: str | Mapping | None) -> str | None:
    """The preset a group's spec starts from: a name is that preset; a mapping is merged over its
    ``name`` (backend, task, robot: when such a preset exists; a backend mapping must name one) or
    else over the group's default (None)."""
    if spec is None:
        return None
    if isinstance(spec, str):
        return _check_preset(group, spec)
    if not isinstance(spec, (Mapping, DictConfig)):
        raise TypeError(f"{group} must be a preset name or a mapping, got {type(spec).__name__}")
    name = spec.get("name") if group in _NAMED_BASE else None
    if group == "backend":
        _refuse_task_rules(spec)
        if name is None:
            raise ValueError("backend: config has no 'name'")
        return _check_preset(group, name)
    return name if name in available(group) else None


def _where(group: str, spec: Mapping) -> str:
    """How an error names a mapping's group: a backend by its name (``backend mujoco``)."""
    return f"backend {spec['name']}" if group == "backend" and "name" in spec else group


def preset_config(group: str, spec: str | Mapping | None = None, *, backend: str | None = None) -> DictConfig:
    """A group's config, composed: a preset name, or a mapping merged over its base preset
    (:func:`_base_preset`; the group's default, for ``walk`` the one of ``backend``)."""
    base = _preset_node(group, _base_preset(group, spec), backend)
    return base if spec is None or isinstance(spec, str) else merge_checked(base, to_plain(spec), _where(group, spec))


#: Episode rules that belong to the task config, never to a backend's.
TASK_RULES = ("fall_threshold", "collision_ends_episode")


def _refuse_task_rules(backend_cfg: Mapping) -> None:
    for key in TASK_RULES:
        if key in backend_cfg:
            raise ValueError(f"backend.{key} is a task rule: set task.{key} instead")


def upgrade_run_config(cfg: DictConfig) -> DictConfig:
    """A run's saved config in today's keys, so runs written before the task owned the episode
    evaluate unchanged: ``backend.fall_threshold`` / ``backend.collision_ends_episode`` move to the
    task (dropped where they equal today's defaults, so moving the run to another backend keeps
    that backend's collision rule), ``task.reward_weights`` and ``task.stability_scale`` become
    the ``task.reward`` table.  A config in today's keys is returned as it is."""
    backend, task = cfg.get("backend"), cfg.get("task")
    if not isinstance(backend, DictConfig) or not isinstance(task, DictConfig):
        return cfg
    old_rules = [k for k in TASK_RULES if k in backend]
    if not old_rules and "reward_weights" not in task and "stability_scale" not in task:
        return cfg

    cfg = copy.deepcopy(cfg)
    OmegaConf.set_struct(cfg, False)
    defaults = {
        "fall_threshold": NavTaskConfig.__dataclass_fields__["fall_threshold"].default,
        "collision_ends_episode": backend_kind(cfg.backend) == "2d",
    }
    for key in old_rules:
        value = cfg.backend.pop(key)
        if value != defaults[key]:
            cfg.task[key] = value
    if "reward_weights" in cfg.task or "stability_scale" in cfg.task:
        weights = cfg.task.pop("reward_weights", None) or {}
        scale = cfg.task.pop("stability_scale", DEFAULT_REWARD["stability"]["params"]["scale"])
        reward: dict[str, dict[str, Any]] = {name: {"weight": float(weights.get(name, 0.0))} for name in DEFAULT_REWARD}
        reward["stability"]["params"] = {"scale": scale}
        cfg.task.reward = reward
    return cfg


def load_preset(group: str, spec: str | Mapping | None = None, *, backend: str | None = None) -> dict:
    """:func:`preset_config` as a plain dict (keys the preset leaves unset are omitted)."""
    return plain_config(preset_config(group, spec, backend=backend))


def env_config(
    backend: str | Mapping = "pymunk",
    task: str | Mapping | None = None,
    noise: str | Mapping | None = None,
    robot: str | Mapping | None = None,
    walk: str | Mapping | None = None,
    randomization: str | Mapping | None = None,
) -> dict[str, dict]:
    """The env's groups as plain dicts, composed from ``conf/env.yaml`` in one go; ``None`` = the
    group's default there (``walk``: the chosen backend's); mappings merge over their base preset."""
    specs = {
        "backend": backend,  # a name is a preset (conf/backend/<name>.yaml, e.g. mujoco or mujoco_v0)
        "task": task,
        "noise": noise,
        "robot": robot,
        "walk": walk,
        "randomization": randomization,
    }
    overrides = []
    for group, spec in specs.items():
        name = _base_preset(group, spec)
        if name is not None:
            overrides.append(f"{group}={name}")
    composed = compose("env", overrides)
    out = {}
    for group in ENV_GROUPS:
        spec = specs[group]
        node = (
            composed[group]
            if spec is None or isinstance(spec, str)
            else merge_checked(composed[group], to_plain(spec), _where(group, spec))
        )
        out[group] = plain_config(node)
    return out


def plain_config(cfg: Any) -> Any:
    """A composed config as plain containers, resolved, without the keys left ``???``."""
    return _without_missing(OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else cfg)


def _without_missing(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _without_missing(v) for k, v in value.items() if v != "???"}
    if isinstance(value, list):
        return [_without_missing(v) for v in value]
    return value


def _number(cfg: Mapping, key: str, where: str) -> float:
    value = cfg[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}.{key} must be a finite number, got {value!r}")
    return float(value)


def _field_types(schema_class: type) -> dict[str, Any]:
    import typing

    return typing.get_type_hints(schema_class)


def build_task(task_cfg: Mapping):
    """``(SceneSampler, NavTaskConfig)`` from a task config, naming any bad key (the keys and the
    numeric ones come from :class:`footsim.schema.TaskConfig`)."""

    types = _field_types(schema.TaskConfig)
    cfg = dict(task_cfg)
    unknown = sorted(set(cfg) - set(types))
    if unknown:
        raise ValueError(f"task: unknown key(s) {unknown}; valid: {sorted(types)}")
    cfg.pop("name", None)
    scenes = dict(cfg.pop("scenes", {}) or {})
    obstacles = bool(cfg.pop("obstacles", False))
    for key in ("observe_imu", "path_hint"):
        if key in cfg and not isinstance(cfg[key], bool):
            raise ValueError(f"task.{key} must be true or false, got {cfg[key]!r}")
    for key in list(cfg):
        if types[key] in (float, int):
            value = _number(cfg, key, "task")
            cfg[key] = int(value) if types[key] is int else value
    if "success_angle_deg" in cfg:
        cfg["success_angle"] = math.radians(cfg.pop("success_angle_deg"))
    if "terminations" in cfg and cfg["terminations"] is None:
        cfg["terminations"] = {}
    scene_types = _field_types(schema.ScenesConfig)
    unknown = sorted(set(scenes) - set(scene_types))
    if unknown:
        raise ValueError(f"task.scenes: unknown key(s) {unknown}; valid: {sorted(scene_types)}")
    for key in scenes:
        value = _number(scenes, key, "task.scenes")
        scenes[key] = int(value) if scene_types[key] is int else value
    return SceneSampler(obstacles=obstacles, **scenes), NavTaskConfig(obstacles=obstacles, **cfg)


def build_noise(noise_cfg: Mapping):

    cfg = dict(noise_cfg)
    cfg.pop("name", None)
    known = {k for k in NoiseModel.__dataclass_fields__ if not k.startswith("_")}
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise ValueError(f"noise: unknown key(s) {unknown}; valid: {sorted(known)}")
    # delay_steps is a count: passed as given, NoiseModel rejects non-integers naming the key
    values: dict[str, Any] = {k: (cfg[k] if k == "delay_steps" else _number(cfg, k, "noise")) for k in cfg}
    return NoiseModel(**values)


def build_walk(walk_cfg: Mapping):

    cfg = dict(walk_cfg)
    cfg.pop("name", None)
    return WalkParams.from_mapping(cfg)


def build_robot(robot_cfg: Mapping | str):

    return get_robot(robot_cfg) if isinstance(robot_cfg, str) else robot_from_config(dict(robot_cfg))


def backend_kind(backend_cfg: Mapping) -> str:
    """ "2d" or "3d": the kind of the backend a config names (imports its module, not its simulator's state)."""

    if backend_cfg.get("name") is None:
        raise ValueError("backend: config has no 'name'")
    return backend_class(backend_cfg["name"]).kind


def build_backend(backend_cfg: Mapping, robot, walk, task=None):
    """The backend a config names; a 3D backend also gets the task's ``fall_threshold`` and
    ``collision_ends_episode`` (``task``: a resolved ``NavTaskConfig``; its driver stops simulating
    a double step early when the task will end the episode)."""

    cfg = dict(backend_cfg)
    name = cfg.pop("name", None)
    if name is None:
        raise ValueError("backend: config has no 'name'")
    cls = backend_class(name)
    _refuse_task_rules(cfg)
    if task is not None and cls.kind == "3d":
        cfg.update(fall_threshold=task.fall_threshold, collision_ends_episode=bool(task.collision_ends_episode))
    construct: Callable[..., Backend] = cls  # every backend class takes the robot, the walk and its options
    return construct(robot=robot, walk=walk, **cfg)


def build_randomizer(randomization_cfg: Mapping | None, backend):
    """A ``Randomizer`` for the backend's section of the preset; unsupported terms fail here."""

    section = "terms_2d" if backend.kind == "2d" else "terms_3d"
    return Randomizer(parse_terms(randomization_cfg, section), backend.name, backend.capabilities)


def to_plain(cfg: Any) -> Any:
    return plain_config(cfg) if isinstance(cfg, DictConfig) else cfg


# The command lines (footsim-train, footsim-walktune) import conf_dir from here before hydra.main
# composes: registering now puts the schemas in its ConfigStore (footsim-eval adds the controllers').
schema.register_schemas()
