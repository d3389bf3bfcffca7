"""The robot registry: robot names (the Hydra ``robot`` group's ``name``) to their spec builders."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping

from footsim.robots.spec import RobotSpec
from footsim.robots.wolfgang import wolfgang
from footsim.robots.wolfgang_simplified import wolfgang_simplified

ROBOTS = {"wolfgang": wolfgang, "wolfgang_simplified": wolfgang_simplified}


def get_robot(name: str, **options) -> RobotSpec:
    """The spec of robot ``name``; ``options`` are its builder's keyword arguments (e.g. Wolfgang's
    ``torso_extra_mass``), checked against the builder's signature."""
    try:
        build = ROBOTS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown robot {name!r}; valid robots: {sorted(ROBOTS)}") from None
    valid = robot_options(name)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ValueError(f"robot {name!r}: unknown option(s) {unknown}; valid: {valid}")
    return build(**options)


def robot_options(name: str) -> list[str]:
    """The keyword options robot ``name``'s builder takes."""
    return [p for p in inspect.signature(ROBOTS[name]).parameters if p != "self"]


def register_robot(name: str, build: Callable[[], RobotSpec]) -> None:
    """Make ``robot=name`` (or ``robot={"name": name}``) build its spec with ``build()``."""
    if not callable(build):
        raise TypeError(f"register_robot({name!r}): build must be a function returning a RobotSpec")
    ROBOTS[name] = build


CONFIG_KEYS = ("name",)  # plus the robot's own builder options (robot_options)


def robot_from_config(cfg: Mapping | str) -> RobotSpec:
    """The spec named by a Hydra ``robot`` group entry (``{name: wolfgang, torso_extra_mass: 1.0}``)
    or a bare name.

    Keys other than ``name`` are the builder's documented options; anything else is rejected: the
    robot's numbers live in code, in one place.
    """
    if isinstance(cfg, str):
        return get_robot(cfg)
    if not isinstance(cfg, Mapping):
        try:  # an omegaconf DictConfig
            cfg = dict(cfg)
        except (TypeError, ValueError):
            raise TypeError(f"robot config must be a mapping or a name, got {type(cfg).__name__}") from None
    if "name" not in cfg:
        raise ValueError(f"robot config needs a 'name' (valid robots: {sorted(ROBOTS)})")
    name = cfg["name"]
    if name not in ROBOTS:
        raise ValueError(f"unknown robot {name!r}; valid robots: {sorted(ROBOTS)}")
    # The schema lists every robot's options with null defaults: a null option is not given.
    options = {str(k): v for k, v in cfg.items() if k != "name" and v is not None}
    unknown = sorted(set(options) - set(robot_options(name)))
    if unknown:
        raise ValueError(
            f"unknown robot config key(s) {unknown}; valid keys: {list(CONFIG_KEYS) + robot_options(name)}"
        )
    return get_robot(name, **options)
