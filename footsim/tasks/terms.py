"""Reward and termination terms as data: one small function plus one config entry each.

A **reward term** is a function ``f(step, **params) -> float`` over the :class:`StepContext` the
task fills once per step (pose, goal features, actions, the backend's ``StepResult``).  It enters
a task through one entry of the task config's ``reward`` table::

    reward:
      distance: {weight: 0.3}                                  # a registered term, by name
      stability: {weight: 0.1, params: {scale: 0.2}}           # params: the function's keywords
      clearance: {weight: 0.05, func: "mypkg.terms:clearance"} # a function in the user's module

A **termination term** is a function ``f(step, **params) -> bool``; the task config's
``terminations`` table lists them in priority order (the first that holds names the outcome).
Terms are found by name in :data:`REWARD_TERMS` / :data:`TERMINATION_TERMS` (the built-in ones
register with the decorators below) or by ``func: "module:function"``, so a user adds a term
in their own module and one config line, touching no footsim file.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from footsim.geometry import Pose2D
    from footsim.scene import Scene

#: What a term may need beyond the pose and actions: "tilt" is the backend's trunk tilt, which the
#: task asks for only when a weighted term or the observation uses it; "contact" is the backend's
#: report of an obstacle or ball contact during the step (``StepResult.collided``).
REQUIREMENTS = frozenset({"tilt", "contact"})


class StepContext:
    """The features of one env step that terms read (the task refills one instance every step).

    ``pose``: true navigation pose after the step; ``distance``, ``alpha``, ``beta``: the goal
    features from it (``nav.goal_features``); ``action`` / ``previous_action``: a(t), a(t-1) as 6
    floats in [-1, 1]; ``result``: the backend's ``StepResult``; ``max_tilt``: its largest trunk
    roll/pitch when the task uses the tilt, else None; ``steps``: double steps so far this episode;
    ``scene`` and ``arrays`` (``nav.scene_arrays(scene)``) of the episode; ``config``: the task config.
    """

    __slots__ = (
        "pose",
        "distance",
        "alpha",
        "beta",
        "action",
        "previous_action",
        "result",
        "max_tilt",
        "steps",
        "scene",
        "arrays",
        "config",
    )

    pose: Pose2D
    scene: Scene
    arrays: tuple[np.ndarray, np.ndarray]
    result: Any
    max_tilt: float | None
    action: Any
    previous_action: Any

    def __init__(self, config: Any = None):
        self.config = config
        # pose, scene and arrays stay unset until the task fills them, before any term runs
        self.result = self.max_tilt = None
        self.distance = self.alpha = self.beta = 0.0
        self.action = self.previous_action = None
        self.steps = 0


RewardFunction = Callable[..., float]
TerminationFunction = Callable[..., bool]


@dataclass(frozen=True)
class RewardTermSpec:
    func: RewardFunction
    needs: frozenset[str] = frozenset()


@dataclass(frozen=True)
class TerminationTermSpec:
    func: TerminationFunction
    #: ``settle(reward, step) -> reward``: how the step's reward changes when this term ends the
    #: episode (None: unchanged).
    settle: Callable[[float, StepContext], float] | None = None


REWARD_TERMS: dict[str, RewardTermSpec] = {}
TERMINATION_TERMS: dict[str, TerminationTermSpec] = {}


def reward_term(name: str | None = None, *, needs: tuple[str, ...] = ()) -> Callable[[RewardFunction], RewardFunction]:
    """Register ``f(step, **params) -> float`` as reward term ``name`` (default: the function's name)."""
    unknown = set(needs) - REQUIREMENTS
    if unknown:
        raise ValueError(f"reward term requirements {sorted(unknown)} unknown; valid: {sorted(REQUIREMENTS)}")

    def register(func: RewardFunction) -> RewardFunction:
        REWARD_TERMS[name or func.__name__] = RewardTermSpec(func, frozenset(needs))
        return func

    return register


def termination_term(
    name: str | None = None, *, settle: Callable[[float, StepContext], float] | None = None
) -> Callable[[TerminationFunction], TerminationFunction]:
    """Register ``f(step, **params) -> bool`` as termination term ``name`` (default: the function's name)."""

    def register(func: TerminationFunction) -> TerminationFunction:
        TERMINATION_TERMS[name or func.__name__] = TerminationTermSpec(func, settle)
        return func

    return register


def import_function(path: str, where: str) -> Callable:
    """The function named by ``"package.module:function"``, naming ``where`` if it cannot be found."""
    module_name, sep, attr = path.partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"{where}.func must look like 'package.module:function', got {path!r}")
    try:
        func = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{where}.func {path!r} cannot be imported: {exc}") from exc
    if not callable(func):
        raise ValueError(f"{where}.func {path!r} is not callable")
    return func


@dataclass(frozen=True)
class RewardTerm:
    """One resolved entry of a reward table: ``weight · func(step, **params)``."""

    name: str
    weight: float
    call: Callable[[StepContext], float]  # func with its params bound
    needs: frozenset[str] = field(default_factory=frozenset)


@dataclass(frozen=True)
class TerminationTerm:
    """One resolved entry of a termination table."""

    name: str
    call: Callable[[StepContext], bool]
    settle: Callable[[float, StepContext], float] | None = None


def _entry(entry: Any, where: str, keys: frozenset[str]) -> dict:
    if entry is None:
        return {"params": {}}
    if not isinstance(entry, Mapping):
        raise ValueError(f"{where} must be a mapping with keys {sorted(keys)}, got {entry!r}")
    unknown = sorted(set(entry) - keys)
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; valid: {sorted(keys)}")
    params = entry.get("params") or {}
    if not isinstance(params, Mapping):
        raise ValueError(f"{where}.params must be a mapping of keyword arguments, got {params!r}")
    func = entry.get("func")
    if func is not None and not isinstance(func, str):
        raise ValueError(f"{where}.func must be a string 'package.module:function', got {func!r}")
    return {**entry, "params": dict(params)}


def _bind(func: Callable, params: dict) -> Callable:
    return partial(func, **params) if params else func


def _spec(name: str, entry: dict, registry: Mapping[str, Any], bare: Callable[[Callable], Any], where: str) -> Any:
    """A table entry's term spec: the registered one of that name, or the function named by
    ``func`` with what its module registered it with (``needs``, ``settle``); ``bare(func)`` for
    a function nobody registered."""
    if entry.get("func") is not None:
        func = import_function(entry["func"], f"{where}.{name}")
        return next((spec for spec in registry.values() if spec.func is func), None) or bare(func)
    if name in registry:
        return registry[name]
    raise ValueError(
        f"{where}: unknown term {name!r}; registered: {sorted(registry)} (or give func: 'package.module:function')"
    )


def reward_table(table: Mapping[str, Any], where: str = "task.reward") -> tuple[RewardTerm, ...]:
    """Resolve a ``reward`` config table (term name → ``{weight, params, func}``), in its order."""
    if not isinstance(table, Mapping):
        raise ValueError(f"{where} must be a mapping of term name to {{weight, params, func}}, got {table!r}")
    terms = []
    for name, raw in table.items():
        entry = _entry(raw, f"{where}.{name}", frozenset({"weight", "params", "func"}))
        weight = entry.get("weight", 0.0)
        if (
            isinstance(weight, bool)
            or not isinstance(weight, (int, float))
            or not (math.isfinite(weight) and weight >= 0)
        ):
            raise ValueError(f"{where}.{name}.weight must be a number >= 0, got {weight!r}")
        spec = _spec(name, entry, REWARD_TERMS, RewardTermSpec, where)
        terms.append(RewardTerm(str(name), float(weight), _bind(spec.func, entry["params"]), spec.needs))
    return tuple(terms)


def termination_table(table: Mapping[str, Any], where: str = "task.terminations") -> tuple[TerminationTerm, ...]:
    """Resolve a ``terminations`` config table (outcome name → ``{params, func}`` or null), in priority order."""
    if not isinstance(table, Mapping):
        raise ValueError(f"{where} must be a mapping of outcome name to {{params, func}}, got {table!r}")
    terms = []
    for name, raw in table.items():
        entry = _entry(raw, f"{where}.{name}", frozenset({"params", "func"}))
        spec = _spec(name, entry, TERMINATION_TERMS, TerminationTermSpec, where)
        terms.append(TerminationTerm(str(name), _bind(spec.func, entry["params"]), spec.settle))
    return tuple(terms)
