"""The robot registry: robot names (the Hydra ``robot`` group's ``name``) to their spec builders."""

from __future__ import annotations

from collections.abc import Callable, Mapping

from footsim.robots.spec import RobotSpec
from footsim.robots.wolfgang import wolfgang
from footsim.robots.wolfgang_simplified import wolfgang_simplified

ROBOTS = {"wolfgang": wolfgang, "wolfgang_simplified": wolfgang_simplified}


def get_robot(name: str) -> RobotSpec:
    try:
        return ROBOTS[name]()
    except (KeyError, TypeError):
        raise ValueError(f"unknown robot {name!r}; valid robots: {sorted(ROBOTS)}") from None


def register_robot(name: str, build: Callable[[], RobotSpec]) -> None:
    """Make ``robot=name`` (or ``robot={"name": name}``) build its spec with ``build()``."""
    if not callable(build):
        raise TypeError(f"register_robot({name!r}): build must be a function returning a RobotSpec")
    ROBOTS[name] = build


CONFIG_KEYS = ("name",)


def robot_from_config(cfg: Mapping | str) -> RobotSpec:
    """The spec named by a Hydra ``robot`` group entry (``{name: wolfgang}``) or a bare name.

    Any key other than ``name`` is rejected: the robot's numbers live in code, in one place.
    """
    if isinstance(cfg, str):
        return get_robot(cfg)
    if not isinstance(cfg, Mapping):
        try:  # an omegaconf DictConfig
            cfg = dict(cfg)
        except (TypeError, ValueError):
            raise TypeError(f"robot config must be a mapping or a name, got {type(cfg).__name__}") from None
    unknown = sorted(set(map(str, cfg)) - set(CONFIG_KEYS))
    if unknown:
        raise ValueError(f"unknown robot config key(s) {unknown}; valid keys: {list(CONFIG_KEYS)}")
    if "name" not in cfg:
        raise ValueError(f"robot config needs a 'name' (valid robots: {sorted(ROBOTS)})")
    return get_robot(cfg["name"])
