"""Domain randomization as composable distributions (Hydra group ``randomization``).

A preset has two sections, because a 2D geometric world and a 3D physics world vary in
different things::

    terms_3d:                      # applied by the MuJoCo, dm-control and PyBullet backends
      foot_friction: {dist: uniform, low: 0.7, high: 1.3}          # per episode (default)
      push_force:   {dist: uniform, low: 0, high: 15, when: step}  # resampled every double step
    terms_2d:                      # applied by the pymunk backend
      footstep_noise_x: {dist: normal, mean: 0, std: 0.01}

Each term names a distribution (``uniform`` low/high, ``normal`` mean/std, ``loguniform``
low/high, or ``constant`` value) and when it is drawn (``episode`` or ``step``).  A backend
publishes the terms it can apply in ``Backend.capabilities``; asking it for anything else fails
at start, naming the term and the backend.  The values drawn are reported in
``info["randomization"]`` so an episode can be reproduced.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

#: Every term footsim knows, with what it means (units) — the vocabulary of capabilities.
TERMS = {
    # 3D physics
    "floor_friction": "scale of the floor's sliding friction",
    "foot_friction": "scale of the feet's sliding friction",
    "rolling_friction_scale": "scale of the foot-floor contacts' rolling friction (a torque arm [m] · normal force)",
    "link_mass_scale": "scale of every link mass and inertia (one factor for all links)",
    "torso_com_offset_x": "torso centre-of-mass shift along x [m]",
    "torso_com_offset_y": "torso centre-of-mass shift along y [m]",
    "actuator_kp_scale": "scale of the position servos' gain",
    "torque_limit_scale": "scale of the servos' torque limits",
    "joint_damping_scale": "scale of the joint damping",
    "control_latency": "delay of the joint targets [control ticks] (rounded)",
    "push_force": "magnitude of a horizontal push on the torso [N] (random direction)",
    "push_duration": "duration of a push [s]",
    "push_interval": "time between pushes [s]",
    "terrain_slope": "tilt of the floor [rad] (random direction)",
    "walk_freq_scale": "scale of the walk frequency",
    "walk_trunk_height_scale": "scale of the walk's trunk height",
    # 2D geometry
    "footstep_noise_x": "σ of each footstep's landing error along the foot's x [m]",
    "footstep_noise_y": "σ of each footstep's landing error along the foot's y [m]",
    "footstep_noise_theta": "σ of each footstep's landing error in heading [rad]",
}


@dataclass(frozen=True)
class TermSpec:
    name: str
    dist: str
    params: tuple[float, ...]
    when: str = "episode"

    @classmethod
    def from_mapping(cls, name: str, cfg: Mapping, where: str) -> TermSpec:
        if name not in TERMS:
            raise ValueError(f"{where}.{name}: unknown randomization term; known terms: {', '.join(TERMS)}")
        cfg = dict(cfg)
        dist = cfg.pop("dist", "uniform")
        when = cfg.pop("when", "episode")
        if when not in ("episode", "step"):
            raise ValueError(f"{where}.{name}.when must be 'episode' or 'step', got {when!r}")
        keys = {
            "uniform": ("low", "high"),
            "loguniform": ("low", "high"),
            "normal": ("mean", "std"),
            "constant": ("value",),
        }
        if dist not in keys:
            raise ValueError(f"{where}.{name}.dist must be one of {sorted(keys)}, got {dist!r}")
        missing = [k for k in keys[dist] if k not in cfg]
        extra = sorted(set(cfg) - set(keys[dist]))
        if missing or extra:
            raise ValueError(
                f"{where}.{name}: a {dist} distribution takes {list(keys[dist])}"
                + (f"; missing {missing}" if missing else "")
                + (f"; unexpected {extra}" if extra else "")
            )
        params = []
        for k in keys[dist]:
            value = cfg[k]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{where}.{name}.{k} must be a finite number, got {value!r}")
            params.append(float(value))
        if dist in ("uniform", "loguniform") and params[0] > params[1]:
            raise ValueError(f"{where}.{name}: low ({params[0]}) must be <= high ({params[1]})")
        if dist == "loguniform" and params[0] <= 0:
            raise ValueError(f"{where}.{name}: loguniform needs low > 0, got {params[0]}")
        if dist == "normal" and params[1] < 0:
            raise ValueError(f"{where}.{name}.std must be >= 0, got {params[1]}")
        return cls(name, dist, tuple(params), when)

    def sample(self, rng: np.random.Generator) -> float:
        a = self.params
        if self.dist == "uniform":
            return float(rng.uniform(a[0], a[1]))
        if self.dist == "loguniform":
            return float(math.exp(rng.uniform(math.log(a[0]), math.log(a[1]))))
        if self.dist == "normal":
            return float(rng.normal(a[0], a[1]))
        return a[0]


class Randomizer:
    """Draws the configured terms for one backend; ``episode()`` at reset, ``step()`` per env step."""

    def __init__(self, terms: Mapping[str, TermSpec], backend_name: str, capabilities: frozenset[str]):
        unsupported = sorted(set(terms) - set(capabilities))
        if unsupported:
            raise ValueError(
                f"backend {backend_name!r} cannot apply randomization term(s) {unsupported}; "
                f"it supports: {', '.join(sorted(capabilities)) or 'none'}"
            )
        self.terms = dict(terms)  # fixed from here on
        self.values: dict[str, float] = {}
        #: whether there is anything to draw (a plain attribute: the env reads it twice per step)
        self.active = bool(self.terms)

    def episode(self, rng: np.random.Generator) -> dict[str, float]:
        """Draw every term (per-episode ones are then kept for the episode)."""
        self.values = {name: term.sample(rng) for name, term in self.terms.items()}
        return dict(self.values)

    def step(self, rng: np.random.Generator) -> dict[str, float]:
        """Redraw the per-step terms; returns only what changed."""
        changed = {name: term.sample(rng) for name, term in self.terms.items() if term.when == "step"}
        self.values.update(changed)
        return changed


def parse_terms(cfg: Mapping | None, section: str) -> dict[str, TermSpec]:
    """The ``terms_2d`` or ``terms_3d`` section of a randomization config as TermSpecs."""
    if not cfg:
        return {}
    unknown = sorted(set(cfg) - {"name", "terms_2d", "terms_3d"})
    if unknown:
        raise ValueError(f"randomization: unknown key(s) {unknown}; valid: name, terms_2d, terms_3d")
    terms = cfg.get(section) or {}
    return {name: TermSpec.from_mapping(name, spec or {}, f"randomization.{section}") for name, spec in terms.items()}
