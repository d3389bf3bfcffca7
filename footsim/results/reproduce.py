"""``footsim-reproduce``: evaluate every zoo policy of the study plan and the baselines on the plan's
scene sets, write the data files, regenerate the results page and its plots, and report every cell
that differs from the data files already there; with ``train=true``, run the plan's trainings.

The study plan (``conf/study/v1.yaml``) names the conditions (backend, task, noise, training seeds
and the ``footsim-train`` overrides of one seed), the scene sets, the baselines, the page's tables and
the thesis side by side.  A condition's policies are the zoo entries ``zoo_name`` gives for its seeds
(``2d_nav_s0`` ...); a seed without an entry is listed as missing, not evaluated.  Its transfer
matrices (``matrices:``) name rows (trained conditions), backends and randomization presets; each
cell is a condition too (an existing one that evaluates the same thing, or one derived for the
cell), so the matrices are evaluated, stored and compared like every other row, and the page shows
them as tables and heatmaps (``matrix_<title>.png``) with what each 3D-trained row keeps of its
success on the other 3D backends.

Data files (``out=``, default ``docs/results/``): ``runs.csv``, one row per evaluation (condition,
scene set, policy seed or baseline) with its outcome shares and success time and steps;
``conditions.csv``, per condition, scene set, policy or baseline, and metric: the mean over seeds,
its 95 % bootstrap interval and the interquartile mean (:mod:`footsim.results.stats`).  Rows of
conditions left out by ``only=`` are kept as they were.  Plots: ``success_by_seed.png`` and
``learning_curves.png``.  The page (``page=``) is generated from the data files alone.

Each evaluation is cut into scene shards (``shard_size`` scenes; episode ``i`` keeps scene ``i`` and
seed ``i``, as in ``footsim-eval shard=K/N``), run by ``jobs`` worker processes, and merged in scene order.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from footsim import zoo
from footsim.results.stats import bootstrap_interval, seed_stats
from footsim.utils import atomic_save, atomic_write_text, atomic_write_texts

DEFAULT_PLAN = "study/v1.yaml"  # under conf/
#: Per evaluation: the identity of a row of runs.csv.
KEY = ("condition", "scene_set", "kind", "name")
INFO = ("seed", "backend", "task", "noise", "randomization", "scenes_seed", "first_scene", "n_scenes")
METRICS = (
    "success",
    "timeout",
    "fall",
    "collision",
    "sim_error",
    "contact",
    "unsafe",  # share of episodes that fell, collided or touched an obstacle
    "success_time_mean",
    "success_steps_mean",
)
#: A policy trained with randomization on one 3D backend keeps at least this share of its success
#: on the other 3D backends (the study's transfer target).
RETENTION_TARGET = 0.90
RUNS_FILE = "runs.csv"
CONDITIONS_FILE = "conditions.csv"
STAT_COLUMNS = ("n", "mean", "ci_low", "ci_high", "iqm", "n_undefined")


class PlanError(ValueError):
    """A study plan that cannot be used; the message names the key."""


# -- the plan -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Condition:
    name: str
    title: str
    backend: str
    task: str
    noise: str
    seeds: tuple[int, ...] = ()
    train: tuple[str, ...] = ()
    parent: str | None = None
    policies: str | None = None  # evaluate this condition's zoo entries (no training of its own)
    n_scenes: int | None = None  # at most this many scenes of each set (3D evaluation is slow)
    randomization: str = "none"  # the domain randomization (conf/randomization) it is evaluated under
    sets: tuple[str, ...] | None = None  # the scene sets it is evaluated on (None: every set of the plan)
    #: n_scenes is the condition's total, split over its seeds in consecutive blocks (seed k of the
    #: plan's list takes the k-th block), so that a row of five seeds costs what a row of one does
    #: and together they still cover n_scenes different scenes.
    split_scenes: bool = False
    #: False: a training stage only, run by ``train=true`` as another condition's parent; its policies
    #: are not in the zoo and no table, figure or evaluation uses it (the zoo's 30 MB keep the
    #: conditions a table shows).
    shipped: bool = True
    #: a Beta policy's deterministic action in this condition's evaluations ("mode" or "mean"); None:
    #: the one each policy was trained with (``agent.beta_action``)
    beta_action: str | None = None
    #: backend settings over the plan's (``backends:``) and the command line's for this condition's
    #: evaluations, e.g. pymunk's ``collision_model``: the same policies judged by another rule
    backend_settings: tuple[tuple[str, Any], ...] = ()

    @property
    def source(self) -> str:
        """The condition whose zoo entries are evaluated here."""
        return self.policies or self.name


@dataclass(frozen=True)
class Matrix:
    """A transfer matrix: each row's policies (a trained condition) evaluated on each backend under
    each randomization.  ``cells[(row, backend, randomization)]`` is the condition that evaluates it:
    a condition of the plan with the same policies, backend, task, noise and randomization, or one
    derived for the cell (``<row condition>_on_<backend>[_dr_<randomization>]``)."""

    title: str
    task: str
    rows: dict[str, str]  # row label -> the trained condition whose policies the row evaluates
    backends: tuple[str, ...]
    randomizations: tuple[str, ...]
    cells: dict[tuple[str, str, str], str]
    scene_set: str  # the set its tables and heatmaps show
    note: str = ""  # shown under its title

    @property
    def slug(self) -> str:
        return re.sub(r"[^a-z0-9]+", "_", self.title.lower()).strip("_")


@dataclass(frozen=True)
class Plan:
    path: Path
    name: str
    zoo_name: str
    runs_dir: str
    scene_sets: dict[str, tuple[int, int]]  # name -> (seed, n_scenes)
    conditions: dict[str, Condition]
    baselines: dict[str, tuple[str, ...]]
    tables: tuple[dict, ...]
    thesis: tuple[dict, ...]
    paths: tuple[dict, ...] = ()  # per-scene path plots: {condition, set, scenes}
    matrices: tuple[Matrix, ...] = ()  # transfer matrices; their cells are conditions too
    media: tuple[dict, ...] = ()  # pictures and clips made by other commands: {file, caption, command}
    #: the backend settings the study trains and evaluates at, over each backend's preset (the
    #: plan's ``backends: {B: {KEY: V}}``): added to the training commands of the conditions on B and
    #: to every evaluation on B
    backends: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: what footsim-reproduce re-evaluates when given neither only= nor sets= (the plan's
    #: ``reproduce: {only, sets}``); None: every condition, every set
    default_only: str | None = None
    default_sets: tuple[str, ...] | None = None
    raw: dict = field(repr=False, default_factory=dict)

    def entry(self, condition: Condition, seed: int) -> str:
        return self.zoo_name.format(condition=condition.source, seed=seed)

    def seeds(self, condition: Condition) -> tuple[int, ...]:
        return self.conditions[condition.source].seeds

    def train_overrides(self, condition: Condition) -> list[str]:
        """A trained condition's footsim-train overrides: its ``train`` line, then the plan's backend
        settings for its backend that the line does not set itself."""
        own = {o.split("=", 1)[0] for o in condition.train}
        pinned = self.backends.get(condition.backend, {})
        return [*condition.train, *(f"backend.{k}={v}" for k, v in pinned.items() if f"backend.{k}" not in own)]


def plan_path(spec: str | os.PathLike | None) -> Path:
    from footsim.config import conf_dir

    if spec is None:
        return conf_dir() / DEFAULT_PLAN
    path = Path(spec).expanduser()
    return path if path.is_file() or path.is_absolute() else (conf_dir() / "study" / spec)


def load_plan(spec: str | os.PathLike | None = None) -> Plan:
    """Read and check a study plan; a missing or bad key fails naming it."""
    from omegaconf import OmegaConf

    path = plan_path(spec)
    if not path.is_file():
        raise PlanError(f"study plan {path} not found")
    try:
        raw = OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    except Exception as err:  # a YAML syntax error
        raise PlanError(f"{path}: not readable as YAML: {err}") from None
    if not isinstance(raw, dict):
        raise PlanError(f"{path}: expected a mapping")

    def need(mapping: dict, key: str, kind: type | tuple[type, ...], where: str) -> Any:
        if key not in mapping:
            raise PlanError(f"{path}: {where}{key} is missing")
        value = mapping[key]
        if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
            raise PlanError(f"{path}: {where}{key} must be {getattr(kind, '__name__', kind)}, got {value!r}")
        return value

    sets = {}
    for name, spec_ in need(raw, "scene_sets", dict, "").items():
        where = f"scene_sets.{name}."
        if not isinstance(spec_, dict):
            raise PlanError(f"{path}: scene_sets.{name} must be a mapping with seed and n_scenes")
        seed, n = need(spec_, "seed", int, where), need(spec_, "n_scenes", int, where)
        if n <= 0:
            raise PlanError(f"{path}: {where}n_scenes must be > 0, got {n}")
        sets[name] = (seed, n)
    known = {
        "title",
        "backend",
        "task",
        "noise",
        "seeds",
        "train",
        "parent",
        "policies",
        "n_scenes",
        "randomization",
        "sets",
        "split_scenes",
        "shipped",
        "beta_action",
        "backend_settings",
    }
    conditions = {}
    for name, spec_ in need(raw, "conditions", dict, "").items():
        where = f"conditions.{name}."
        if not isinstance(spec_, dict):
            raise PlanError(f"{path}: conditions.{name} must be a mapping")
        _known_keys(spec_, known, f"{path}: {where[:-1]}")
        seeds = tuple(spec_.get("seeds") or ())
        if any(not isinstance(s, int) or isinstance(s, bool) for s in seeds):
            raise PlanError(f"{path}: {where}seeds must be a list of integers, got {spec_.get('seeds')!r}")
        cap = _scene_cap(spec_.get("n_scenes"), f"{path}: {where}n_scenes")
        cond_sets = _set_names(spec_.get("sets"), sets, f"{path}: {where}sets")
        split = spec_.get("split_scenes", False)
        if not isinstance(split, bool) or (split and cap is None):
            raise PlanError(
                f"{path}: {where}split_scenes must be true or false, and true needs n_scenes, got {split!r}"
            )
        shipped = spec_.get("shipped", True)
        if not isinstance(shipped, bool):
            raise PlanError(f"{path}: {where}shipped must be true or false, got {shipped!r}")
        beta_action = spec_.get("beta_action")
        if beta_action not in (None, "mode", "mean"):
            raise PlanError(f"{path}: {where}beta_action must be mode or mean, got {beta_action!r}")
        settings = spec_.get("backend_settings") or {}
        if not isinstance(settings, dict):
            raise PlanError(f"{path}: {where}backend_settings must be a mapping of backend keys, got {settings!r}")
        if settings and not spec_.get("policies"):
            raise PlanError(
                f"{path}: {where}backend_settings needs policies: (a trained condition's settings go in its "
                "train line, so that its training command shows them)"
            )
        backend = need(spec_, "backend", str, where)
        try:
            check_backend_settings({backend: settings})
        except PlanError as err:
            raise PlanError(f"{path}: {where}backend_settings: {err}") from None
        conditions[name] = Condition(
            name=name,
            title=str(spec_.get("title", name)),
            backend=backend,
            task=need(spec_, "task", str, where),
            noise=str(spec_.get("noise", "none")),
            seeds=seeds,
            train=tuple(str(o) for o in spec_.get("train") or ()),
            parent=spec_.get("parent"),
            policies=spec_.get("policies"),
            n_scenes=cap,
            randomization=str(spec_.get("randomization", "none")),
            sets=cond_sets,
            split_scenes=split,
            shipped=shipped,
            beta_action=beta_action,
            backend_settings=tuple(sorted(settings.items())),
        )

    def shown(name: str, where: str) -> None:
        """``where`` evaluates or shows condition ``name``: it must exist and ship its policies."""
        if name not in conditions:
            raise PlanError(f"{path}: {where}: no condition {name!r}")
        if not conditions[name].shipped:
            raise PlanError(f"{path}: {where}: {name!r} is a training stage only (shipped: false), not in the zoo")

    for cond in conditions.values():
        for key in ("parent", "policies"):
            ref = getattr(cond, key)
            if ref is not None and ref not in conditions:
                raise PlanError(f"{path}: conditions.{cond.name}.{key}: no condition {ref!r}")
        if cond.policies is not None:
            shown(cond.policies, f"conditions.{cond.name}.policies")
        if not cond.shipped and cond.policies is not None:
            raise PlanError(f"{path}: conditions.{cond.name}: shipped: false is for trained conditions, not policies")
        n_seeds = len(conditions[cond.source].seeds)
        if cond.split_scenes and cond.n_scenes is not None and cond.n_scenes < n_seeds:
            raise PlanError(
                f"{path}: conditions.{cond.name}.n_scenes: {cond.n_scenes} scenes cannot be split over {n_seeds} seeds"
            )
        if cond.policies is None and not cond.seeds:
            raise PlanError(f"{path}: conditions.{cond.name}: give seeds (and train) or policies")
    baselines = {}
    for controller, conds in (raw.get("baselines") or {}).items():
        for c in conds:
            shown(c, f"baselines.{controller}")
        baselines[controller] = tuple(conds)
    tables = tuple(raw.get("tables") or ())
    for i, table in enumerate(tables):
        for c in need(table, "conditions", list, f"tables[{i}]."):
            shown(c, f"tables[{i}].conditions")
    thesis = tuple(raw.get("thesis") or ())
    for i, row in enumerate(thesis):
        tried = row.get("tried")
        if tried is not None and not (
            isinstance(tried, str) or (isinstance(tried, list) and all(isinstance(t, str) for t in tried))
        ):
            raise PlanError(f"{path}: thesis[{i}].tried: expected a text or a list of texts, got {tried!r}")
        for j, fig in enumerate(need(row, "figures", list, f"thesis[{i}].")):
            where = f"thesis[{i}].figures[{j}]."
            for key in ("condition", "minus", "reaches"):
                if fig.get(key) is not None:
                    shown(fig[key], f"{where}{key}")
            if fig.get("reaches") is not None:
                for key in ("condition", "reaches"):
                    if conditions[fig[key]].policies:
                        raise PlanError(
                            f"{path}: {where}{key}: {fig[key]!r} is not a trained condition (no learning curve)"
                        )
            if fig.get("reaches") is None and need(fig, "metric", str, where) not in METRICS:
                raise PlanError(f"{path}: {where}metric: {fig['metric']!r} is not one of {list(METRICS)}")
            if fig.get("target") is not None:
                parse_target(fig["target"], f"{path}: {where}target")
    paths = tuple(raw.get("paths") or ())
    for i, spec_ in enumerate(paths):
        where = f"paths[{i}]."
        shown(need(spec_, "condition", str, where), f"{where}condition")
        if need(spec_, "set", str, where) not in sets:
            raise PlanError(f"{path}: {where}set: no scene set {spec_['set']!r} ({', '.join(sets)})")
        scenes = need(spec_, "scenes", list, where)
        n_set = sets[spec_["set"]][1]
        if not scenes or not all(isinstance(k, int) and 0 <= k < n_set for k in scenes):
            raise PlanError(
                f"{path}: {where}scenes: scene indices 0..{n_set - 1} of set {spec_['set']!r}, got {scenes!r}"
            )
    matrices = tuple(_matrix(path, i, spec_, conditions, sets) for i, spec_ in enumerate(raw.get("matrices") or ()))
    for i, matrix in enumerate(matrices):
        for name in (*matrix.rows.values(), *matrix.cells.values()):
            shown(name, f"matrices[{i}]")
    media = tuple(raw.get("media") or ())
    for i, spec_ in enumerate(media):
        for key in ("file", "caption", "command"):
            need(spec_, key, str, f"media[{i}].")
    backends = raw.get("backends") or {}
    if not isinstance(backends, dict) or not all(isinstance(v, dict) for v in backends.values()):
        raise PlanError(f"{path}: backends must map a backend to its settings, e.g. {{mujoco: {{physics_dt: 0.002}}}}")
    try:
        check_backend_settings(backends)
    except PlanError as err:
        raise PlanError(f"{path}: {err}") from None
    scope = raw.get("reproduce") or {}
    if not isinstance(scope, dict):
        raise PlanError(f"{path}: reproduce must be a mapping with only and sets, got {scope!r}")
    _known_keys(scope, {"only", "sets"}, f"{path}: reproduce")
    default_only = scope.get("only")
    if default_only is not None and not isinstance(default_only, str):
        raise PlanError(f"{path}: reproduce.only must be a text like only=, got {default_only!r}")
    default_sets = _set_names(scope.get("sets"), sets, f"{path}: reproduce.sets")
    zoo_name = str(raw.get("zoo_name", "{condition}_s{seed}"))
    plan = Plan(
        path=path,
        name=str(raw.get("name", path.stem)),
        zoo_name=zoo_name,
        runs_dir=str(raw.get("runs_dir", "runs/study")),
        scene_sets=sets,
        conditions=conditions,
        baselines=baselines,
        tables=tables,
        thesis=thesis,
        paths=paths,
        matrices=matrices,
        media=media,
        backends={b: dict(v) for b, v in backends.items()},
        default_only=default_only,
        default_sets=default_sets,
        raw=raw,
    )
    if default_only is not None:
        try:
            select(plan, default_only)
        except PlanError as err:
            raise PlanError(f"{path}: reproduce.only: {err}") from None
    return plan


def _known_keys(spec: dict, known: set[str], where: str) -> None:
    unknown = sorted(set(spec) - known)
    if unknown:
        raise PlanError(f"{where}: unknown key(s) {unknown}; valid: {sorted(known)}")


def _scene_cap(value: Any, where: str) -> int | None:
    if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value <= 0):
        raise PlanError(f"{where} must be a positive integer, got {value!r}")
    return value


def _set_names(value: Any, sets: dict, where: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    if not isinstance(value, list) or not value or any(v not in sets for v in value):
        raise PlanError(f"{where}: a list of the plan's scene sets ({', '.join(sets)}), got {value!r}")
    return tuple(value)


def _matrix(path: Path, i: int, spec: Any, conditions: dict[str, Condition], sets: dict) -> Matrix:
    """Read ``matrices[i]`` and add the conditions its cells need to ``conditions``."""
    where = f"{path}: matrices[{i}]."
    if not isinstance(spec, dict):
        raise PlanError(f"{where[:-1]} must be a mapping")
    _known_keys(spec, {"title", "task", "rows", "backends", "randomization", "n_scenes", "sets", "note"}, where[:-1])
    for key in ("task", "rows", "backends"):
        if key not in spec:
            raise PlanError(f"{where}{key} is missing")
    rows = spec["rows"]
    if not isinstance(rows, dict) or not rows:
        raise PlanError(f"{where}rows must map a row label to a trained condition, got {rows!r}")
    for label, name in rows.items():
        if name not in conditions or conditions[name].policies:
            raise PlanError(f"{where}rows.{label}: {name!r} is not a trained condition of the plan")
    backends = spec["backends"]
    if not isinstance(backends, list) or not backends or not all(isinstance(b, str) for b in backends):
        raise PlanError(f"{where}backends must be a list of backend names, got {backends!r}")
    randomizations = spec.get("randomization", ["none"])
    if not isinstance(randomizations, list) or not randomizations:
        raise PlanError(f"{where}randomization must be a list of conf/randomization presets, got {randomizations!r}")
    # n_scenes: one cap for every 3D backend, or a cap per backend (a PyBullet episode costs several
    # MuJoCo ones at its converged timestep); 2D evaluation is cheap and never capped
    capped = [b for b in backends if b != "pymunk"]
    caps_spec = spec.get("n_scenes")
    if isinstance(caps_spec, dict):
        unknown = sorted(set(caps_spec) - set(capped))
        if unknown:
            raise PlanError(f"{where}n_scenes: {unknown} are not among the matrix's 3D backends {capped}")
        caps = {str(b): _scene_cap(v, f"{where}n_scenes.{b}") for b, v in caps_spec.items()}
    else:
        cap = _scene_cap(caps_spec, f"{where}n_scenes")
        caps = {b: cap for b in capped}
    cell_sets = _set_names(spec.get("sets"), sets, f"{where}sets")
    task = str(spec["task"])
    cells = {}
    for label, source in rows.items():
        row = conditions[source]
        for backend, cap in caps.items():
            if cap is not None and cap < len(row.seeds):
                raise PlanError(
                    f"{where}n_scenes: {cap} scenes cannot be split over the {len(row.seeds)} seeds of row {label} "
                    f"({backend})"
                )
        for backend in backends:
            cap = caps.get(backend)
            for rand in map(str, randomizations):
                same = [
                    c.name
                    for c in conditions.values()
                    if c.source == source
                    and (c.backend, c.task, c.noise, c.randomization) == (backend, task, row.noise, rand)
                    and c.beta_action is None  # a cell acts and is judged as the row was trained
                    and not c.backend_settings
                ]
                if same:
                    cells[(label, backend, rand)] = same[0]
                    continue
                name = f"{source}_on_{backend}" + ("" if rand == "none" else f"_dr_{rand}")
                shown = "" if rand == "none" else f", randomization {rand}"
                conditions[name] = Condition(
                    name=name,
                    title=f"{row.title} policy on {backend}{shown}",
                    backend=backend,
                    task=task,
                    noise=row.noise,
                    policies=source,
                    n_scenes=cap,
                    randomization=rand,
                    sets=cell_sets,
                    split_scenes=cap is not None,
                )
                cells[(label, backend, rand)] = name
    return Matrix(
        title=str(spec.get("title", f"matrix {i}")),
        task=task,
        rows={str(k): str(v) for k, v in rows.items()},
        backends=tuple(backends),
        randomizations=tuple(map(str, randomizations)),
        cells=cells,
        scene_set=(cell_sets or tuple(sets))[0],
        note=str(spec.get("note", "")),
    )


def parse_target(text: str, where: str = "target") -> tuple[str, float]:
    match = re.fullmatch(r"\s*(>=|<=)\s*(-?[0-9.]+)\s*", str(text))
    if not match:
        raise PlanError(f'{where}: expected "<op> <number>" with op >= or <=, got {text!r}')
    return match.group(1), float(match.group(2))


def select(plan: Plan, only: str | None) -> list[Condition]:
    """The conditions ``only`` picks: ``2d`` (pymunk), ``3d`` (the 3D backends), ``matrix`` (every
    cell of the transfer matrices), ``zoo`` (the conditions that train policies, each evaluating its
    own zoo entries), or condition names."""
    conds = list(plan.conditions.values())
    if not only:
        return conds
    picked: list[Condition] = []
    for item in (s.strip() for s in only.split(",") if s.strip()):
        if item == "2d":
            picked += [c for c in conds if c.backend == "pymunk"]
        elif item == "3d":
            picked += [c for c in conds if c.backend != "pymunk"]
        elif item == "matrix":
            picked += [plan.conditions[name] for m in plan.matrices for name in m.cells.values()]
        elif item == "zoo":
            picked += [c for c in conds if c.policies is None and c.shipped]
        elif item in plan.conditions:
            picked.append(plan.conditions[item])
        else:
            raise PlanError(
                f"only={only}: {item!r} is neither 2d, 3d, matrix, zoo nor a condition ({', '.join(plan.conditions)})"
            )
    return list(dict.fromkeys(picked))


def scope(
    plan: Plan, only: str | None, sets: Sequence[str] | None, everything: bool
) -> tuple[str | None, list[str] | None]:
    """What footsim-reproduce re-evaluates (``only``, ``sets``; None: all): ``only=`` and ``sets=`` as
    given; with neither, the plan's ``reproduce:`` scope; ``everything`` (``all=true``): every
    condition on every set."""
    if everything:
        if only or sets:
            raise PlanError("all=true re-evaluates every condition on every scene set: drop only= and sets=")
        return None, None
    if only is None and sets is None:
        return plan.default_only, list(plan.default_sets) if plan.default_sets is not None else None
    return only, list(sets) if sets is not None else None


# -- evaluation jobs ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Job:
    """One evaluation: a policy (zoo entry) or a baseline under a condition on a scene set."""

    condition: str
    scene_set: str
    kind: str  # "policy" | "baseline"
    name: str  # zoo entry | controller preset
    seed: int | None
    backend: str
    task: str
    noise: str
    scenes_seed: int
    n_scenes: int
    randomization: str = "none"
    first_scene: int = 0  # the job evaluates scenes first_scene .. first_scene + n_scenes - 1 of its set
    beta_action: str | None = None  # a Beta policy's deterministic action, None: its own
    #: backend settings over the backend's preset, for the policy's recorded ones and the baselines'
    #: defaults (``footsim-reproduce backends.B.KEY=V``: the study at other physics); () = as recorded
    backend_settings: tuple[tuple[str, Any], ...] = ()

    @property
    def key(self) -> tuple[str, str, str, str]:
        return (self.condition, self.scene_set, self.kind, self.name)

    @property
    def episode_cost(self) -> float:
        """Rough worker seconds of one episode (what order the shards are handed out in: the
        longest first, so that no worker is left with a long one at the end)."""
        per_backend = {"pybullet": 0.5, "mujoco": 0.15, "dm_control": 0.15}.get(self.backend, 0.005)
        return per_backend * (1.5 if self.task == "nav_obstacles" else 1.0)


def scene_blocks(n_scenes: int, n_seeds: int) -> list[tuple[int, int]]:
    """``n_scenes`` consecutive scenes split into ``n_seeds`` blocks as even as can be: each block's
    (first scene, number of scenes); the first ``n_scenes % n_seeds`` blocks take one scene more."""
    if n_seeds > n_scenes:
        raise PlanError(f"{n_scenes} scenes cannot be split over {n_seeds} seeds (at least one scene each)")
    size, extra = divmod(n_scenes, n_seeds)
    sizes = [size + (k < extra) for k in range(n_seeds)]
    return [(sum(sizes[:k]), sizes[k]) for k in range(n_seeds)]


def _job_settings(
    cond: Condition, backend_settings: Mapping[str, Mapping[str, Any]] | None
) -> tuple[tuple[str, Any], ...]:
    """A job's backend settings: ``backend_settings`` for the condition's backend, its own over them."""
    settings = {**(backend_settings or {}).get(cond.backend, {}), **dict(cond.backend_settings)}
    return tuple(sorted(settings.items()))


def _evaluated_as(cond: Condition, scenes_seed: int, n_scenes: int) -> dict[str, Any]:
    """The fields a :class:`Job` of ``cond`` takes from it: what it is evaluated under, on which scenes."""
    return dict(
        backend=cond.backend,
        task=cond.task,
        noise=cond.noise,
        randomization=cond.randomization,
        scenes_seed=scenes_seed,
        n_scenes=n_scenes,
    )


def lineage_problems(plan: Plan, conditions: Sequence[Condition], root: Path) -> list[str]:
    """Zoo entries of ``conditions`` whose recorded parent weights are not those of the zoo entry the
    plan names as their parent (the parent condition's entry of the same seed): the page would say a
    policy descends from one it was not trained from."""
    available = set(zoo.names(root))
    problems = []
    for cond in conditions:
        if cond.parent is None or cond.policies:
            continue
        for s in cond.seeds:
            child, parent = plan.entry(cond, s), plan.entry(plan.conditions[cond.parent], s)
            if child not in available or parent not in available:
                continue
            recorded = (zoo.provenance(child, root).get("parent") or {}).get("weights_sha256")
            if recorded is None:
                problems.append(f"{child}: its provenance records no parent weights, so zoo:{parent} cannot be checked")
            elif recorded != zoo.entry_weights_digest(parent, root):
                problems.append(
                    f"{child} was trained from other weights than zoo:{parent} (condition {cond.name}'s parent "
                    f"{cond.parent}, seed {s}); retrain it (footsim-reproduce train=true only={cond.name})"
                )
    return problems


def check_backend_settings(settings: Mapping[str, Mapping[str, Any]]) -> None:
    """``backends.B.KEY=V`` (plan or command line): checked as the env's config checks a backend
    mapping, so B must be a backend and KEY one of its settings."""
    from footsim import config as fconf

    for backend, values in settings.items():
        if "name" in values:
            raise PlanError(f"backends.{backend}.name: the backend is named by the key ({backend})")
        try:
            fconf.env_config(backend={"name": backend, **values})
        except ValueError as err:
            raise PlanError(f"backends.{backend}: {err}") from None


def plan_jobs(
    plan: Plan,
    conditions: Sequence[Condition],
    root: Path,
    n_scenes: int | None,
    sets: Sequence[str],
    baselines: bool,
    backend_settings: Mapping[str, Mapping[str, Any]] | None = None,
) -> tuple[list[Job], list[str]]:
    """The evaluations of ``conditions`` on ``sets``, and the zoo entries the plan names but the zoo
    lacks; ``backend_settings`` (backend -> {key: value}) evaluates every job on that backend with
    those settings over the backend's preset, and a condition's own ``backend_settings`` over them."""
    available = set(zoo.names(root))
    conditions = [c for c in conditions if c.shipped]  # a training stage has no zoo entries
    for cond in conditions:  # a stale entry fails here, naming what changed, before any evaluation
        for s in plan.seeds(cond):
            if plan.entry(cond, s) in available:
                zoo.check_config(plan.entry(cond, s), root)
    problems = lineage_problems(plan, conditions, root)
    if problems:
        raise zoo.ZooError("zoo entries not trained from the plan's parents:\n  " + "\n  ".join(problems))
    jobs, missing = [], []
    for cond in conditions:
        for set_name in sets:
            if cond.sets is not None and set_name not in cond.sets:
                continue
            seed, n = plan.scene_sets[set_name]
            common = _evaluated_as(cond, seed, min([n, *(cap for cap in (cond.n_scenes, n_scenes) if cap is not None)]))
            common["backend_settings"] = _job_settings(cond, backend_settings)
            seeds = plan.seeds(cond)
            n_cond = common["n_scenes"]
            blocks = scene_blocks(n_cond, len(seeds)) if cond.split_scenes else [(0, n_cond)] * len(seeds)
            for s, (first, count) in zip(seeds, blocks):
                entry = plan.entry(cond, s)
                if entry not in available:
                    missing.append(entry)
                    continue
                block = {**common, "n_scenes": count, "first_scene": first, "beta_action": cond.beta_action}
                jobs.append(Job(cond.name, set_name, "policy", entry, s, **block))
            if baselines:
                for controller, conds in plan.baselines.items():
                    if cond.name in conds:
                        jobs.append(Job(cond.name, set_name, "baseline", controller, None, **common))
    return jobs, sorted(set(missing))


def _quiet():
    """Swallow the notes an evaluation prints (e.g. the walk preset on another backend) in a worker."""
    return contextlib.redirect_stdout(io.StringIO())


def job_env_and_controller(job: Job, root: str | Path) -> tuple[Any, Any]:
    """The env and controller that evaluate ``job``: a zoo policy in its own resolved config with
    the job's backend, task and noise, or a baseline preset on the job's env."""
    from omegaconf import OmegaConf

    from footsim import config as fconf
    from footsim.env import FootstepEnv, make_env
    from footsim.planners.controllers import make_controller
    from footsim.rl.common import LoadedPolicy, load_run_config
    from footsim.rl.evaluate import PolicyController, eval_run_config

    if job.kind == "policy":
        run_dir = zoo.entry_dir(job.name, Path(root))
        saved = load_run_config(run_dir)
        asked: dict[str, Any] = {}
        if saved.backend.name != job.backend:  # the backend's preset, with the job's settings over it
            asked["backend"] = {"name": job.backend, **dict(job.backend_settings)}
        if saved.task.name != job.task:
            asked["task"] = job.task
        if saved.noise.get("name", "none") != job.noise:
            asked["noise"] = job.noise
        if (saved.get("randomization") or {}).get("name", "none") != job.randomization:
            asked["randomization"] = job.randomization
        run_cfg = eval_run_config(run_dir, OmegaConf.create(asked))
        if saved.backend.name == job.backend:  # the policy's own recorded backend, the job's settings over it
            for key, value in job.backend_settings:
                run_cfg.backend[key] = value
        # The scene sets are the task preset's (the thesis sampler), whatever a policy trained on.
        run_cfg.task.scenes = fconf.load_preset("task", job.task)["scenes"]
        return make_env(run_cfg), PolicyController(LoadedPolicy(run_dir, beta_action=job.beta_action))
    backend = {"name": job.backend, **dict(job.backend_settings)} if job.backend_settings else job.backend
    env = FootstepEnv(backend=backend, task=job.task, noise=job.noise, randomization=job.randomization)
    controller_cfg = fconf.to_plain(fconf.compose("eval", [f"controller={job.name}"]).controller)
    return env, make_controller(env, controller_cfg)


#: This process's last job with its env, controller and scenes: the next shard of the same job (the
#: shards of a job are handed out one after another) reuses them instead of building them again.
_BUILT: list[tuple[Job, str, Any, Any, list]] = []


def _built(job: Job, root: str) -> tuple[Any, Any, list]:
    from footsim.tasks.scenes import sample_scenes

    if _BUILT and _BUILT[0][:2] == (job, root):
        return _BUILT[0][2:]
    release_built()
    env, controller = job_env_and_controller(job, root)
    try:
        scenes = sample_scenes(env.sampler, job.first_scene + job.n_scenes, job.scenes_seed)
    except BaseException:
        env.close()
        raise
    _BUILT.append((job, root, env, controller, scenes))
    return env, controller, scenes


def release_built() -> None:
    """Close the env :func:`evaluate_shard` keeps for the next shard of its job."""
    while _BUILT:
        _BUILT.pop()[2].close()


def evaluate_shard(job: Job, start: int, stop: int, root: str) -> list[dict]:
    """Episodes ``start..stop-1`` of ``job`` (counted from its first scene; module level: runs in a
    worker process).  Episode ``i`` of the set runs scene ``i`` with seed ``i`` whatever the shard,
    and whatever the env ran before (every episode resets it with its own scene and seed), so a
    worker keeps the env for the job's next shard."""
    from footsim.rl.evaluate import evaluate

    first = job.first_scene
    with _quiet():
        env, controller, scenes = _built(job, root)
        try:
            return evaluate(env, controller, scenes, seed=0, progress=False, indices=range(first + start, first + stop))
        except BaseException:
            release_built()  # an env an episode failed in is not reused
            raise


def timed_shard(job: Job, start: int, stop: int, root: str) -> tuple[list[dict], float]:
    """:func:`evaluate_shard` and its wall time (s)."""
    started = time.perf_counter()
    records = evaluate_shard(job, start, stop, root)
    return records, time.perf_counter() - started


def _worker_init() -> None:
    import torch

    torch.set_num_threads(1)


def run_jobs(
    jobs: Sequence[Job], root: Path, workers: int = 1, shard_size: int = 50, progress: bool = True
) -> tuple[dict[tuple, list[dict]], dict[tuple, float]]:
    """Every job's episode records (scene order) and worker seconds, shard by shard, with a progress
    bar over episodes.  A 3D shard has ``shard_size`` scenes, a 2D one five times as many (its
    episodes take milliseconds, so building the env and policy would dominate a small shard); the
    shards are handed out longest first."""
    from tqdm import tqdm

    def size(job: Job) -> int:
        return shard_size * (5 if job.backend == "pymunk" else 1)

    tasks = [
        (job, start, min(start + size(job), job.n_scenes))
        for job in jobs
        for start in range(0, job.n_scenes, size(job))
    ]
    tasks.sort(key=lambda t: -(t[2] - t[1]) * t[0].episode_cost)  # stable: plan order among equals
    parts: dict[tuple, dict[int, list[dict]]] = {job.key: {} for job in jobs}
    seconds: dict[tuple, float] = {job.key: 0.0 for job in jobs}
    bar = tqdm(total=sum(j.n_scenes for j in jobs), unit="episode", desc="footsim-reproduce", disable=not progress)
    try:
        if workers <= 1:
            _worker_init()
            for job, start, stop in tasks:
                parts[job.key][start], wall = timed_shard(job, start, stop, str(root))
                seconds[job.key] += wall
                bar.update(stop - start)
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            context = multiprocessing.get_context("forkserver")
            with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_init) as pool:
                futures = {
                    pool.submit(timed_shard, job, start, stop, str(root)): (job, start, stop)
                    for job, start, stop in tasks
                }
                for future in as_completed(futures):
                    job, start, stop = futures[future]
                    parts[job.key][start], wall = future.result()
                    seconds[job.key] += wall
                    bar.update(stop - start)
    finally:
        release_built()
        bar.close()
    return {key: [r for start in sorted(p) for r in p[start]] for key, p in parts.items()}, seconds


def run_row(job: Job, records: list[dict]) -> dict:
    """A row of runs.csv from an evaluation's episodes."""
    from footsim.rl.evaluate import summarize

    summary = summarize(records)
    unsafe = sum(r["outcome"] in ("fall", "collision") or r.get("contact_steps", 0) > 0 for r in records)
    row: dict[str, Any] = {k: getattr(job, k) for k in (*KEY, *INFO)}
    row.update({m: summary[m] for m in METRICS if m != "unsafe"})
    row["unsafe"] = unsafe / len(records)
    row["n_scenes"] = len(records)
    return row


# -- data files ---------------------------------------------------------------------------------
def _text(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def _number(text: str) -> float:
    return math.nan if text in ("", None) else float(text)


def read_csv(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def csv_text(columns: Sequence[str], rows: Iterable[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({c: _text(row.get(c)) for c in columns})
    return buffer.getvalue()


def merge_rows(old: list[dict], new: list[dict], key: Sequence[str]) -> list[dict]:
    """``new`` over ``old`` by ``key``; old rows ``new`` does not regenerate are kept, all in key order."""
    merged = {tuple(r[k] for k in key): r for r in old}
    merged.update({tuple(str(r[k]) for k in key): {c: _text(v) for c, v in r.items()} for r in new})
    return [merged[k] for k in sorted(merged)]


def planned_rows(plan: Plan, runs: list[dict]) -> tuple[list[dict], list[str]]:
    """The rows of ``runs`` the plan still has (its conditions on their scene sets, with their seeds'
    zoo entries and their baselines), and the keys of the others."""
    kept, dropped = [], []
    for row in runs:
        cond = plan.conditions.get(row["condition"])
        if cond is None or not cond.shipped or row["scene_set"] not in (cond.sets or plan.scene_sets):
            planned = False
        elif row["kind"] == "policy":
            planned = row["name"] in {plan.entry(cond, s) for s in plan.seeds(cond)}
        else:
            planned = cond.name in plan.baselines.get(row["name"], ())
        if planned:
            kept.append(row)
        else:
            dropped.append("/".join(str(row[k]) for k in KEY))
    return kept, dropped


def differences(old: list[dict], new: list[dict], key: Sequence[str], values: Sequence[str]) -> list[str]:
    """Every cell of ``new`` that differs from ``old`` (rows matched by ``key``), in words."""
    before = {tuple(r[k] for k in key): r for r in old}
    out = []
    for row in new:
        k = tuple(str(row[c]) for c in key)
        if k not in before:
            if old:
                out.append(f"{'/'.join(k)}: new row")
            continue
        for column in values:
            a, b = _number(before[k].get(column, "")), _number(_text(row.get(column)))
            if not (a == b or (math.isnan(a) and math.isnan(b))):
                out.append(f"{'/'.join(k)} {column}: {_fmt(a)} -> {_fmt(b)}")
    return out


def _fmt(value: float) -> str:
    return "—" if math.isnan(value) else f"{value:.6g}"


def condition_rows(runs: list[dict]) -> list[dict]:
    """conditions.csv: per condition, scene set, and policy (over seeds) or baseline, every metric's statistics."""
    groups: dict[tuple, list[dict]] = {}
    for row in runs:
        name = "policy" if row["kind"] == "policy" else row["name"]
        groups.setdefault((row["condition"], row["scene_set"], row["kind"], name), []).append(row)
    out = []
    for (condition, scene_set, kind, name), rows in sorted(groups.items()):
        for metric in METRICS:
            stats = seed_stats(_number(_text(r[metric])) for r in rows)
            out.append(
                {"condition": condition, "scene_set": scene_set, "kind": kind, "name": name, "metric": metric}
                | stats.as_dict()
            )
    return out


# -- the page -----------------------------------------------------------------------------------
def index_stats(cond_rows: list[dict]) -> dict[tuple, dict]:
    """conditions.csv's rows by (condition, scene set, kind, name, metric)."""
    return {(r["condition"], r["scene_set"], r["kind"], r["name"], r["metric"]): r for r in cond_rows}


def _stat(cstats: dict, key: tuple, metric: str, digits: int = 3, interval: bool = True) -> str:
    row = cstats.get((*key, metric))
    if row is None or math.isnan(_number(row["mean"])):
        return "—"
    mean, low, high = (_number(row[c]) for c in ("mean", "ci_low", "ci_high"))
    text = f"{mean:.{digits}f}"
    if interval and not math.isnan(low):
        text += f" [{low:.{digits}f}, {high:.{digits}f}]"
    return text


def _table_command(conditions: Sequence[str]) -> str:
    return f"footsim-reproduce only={','.join(conditions)}"


def _train_line(plan: Plan, cond: Condition) -> str:
    if cond.policies:
        settings = "".join(f", backend.{k}={v}" for k, v in cond.backend_settings)
        return f"{cond.name}: the policies of {cond.policies}, evaluated on {cond.backend}{settings}"
    parent = f" init_from={plan.runs_dir}/{cond.parent}/seed<S>" if cond.parent else ""
    seeds = ",".join(str(s) for s in cond.seeds)
    stage = "" if cond.shipped else " (a training stage: its policies are not in the zoo)"
    command = " ".join(["footsim-train", *plan.train_overrides(cond)])
    return f"{cond.name}: `{command} seed=<S>{parent}` (S = {seeds}){stage}"


def _with_stages(plan: Plan, conds: Sequence[Condition]) -> list[Condition]:
    """``conds`` with the training stages (``shipped: false``) their parents go through, each stage
    before the first condition that descends from it: the commands a reader runs, in order."""
    out: list[Condition] = []
    for cond in conds:
        stages = []
        parent = plan.conditions[cond.parent] if cond.parent else None
        while parent is not None and not parent.shipped:
            stages.append(parent)
            parent = plan.conditions[parent.parent] if parent.parent else None
        out += [c for c in reversed(stages) if c not in out] + [cond]
    return out


def _zoo_line(plan: Plan, cond: Condition, runs: list[dict], root: Path) -> str:
    names = sorted({r["name"] for r in runs if r["condition"] == cond.name and r["kind"] == "policy"})
    if not names:
        return f"{cond.name}: no zoo entry yet"
    commits = set()
    for name in names:
        try:
            commits.add(((zoo.provenance(name, root).get("commit") or {}).get("sha") or "unknown")[:10])
        except (zoo.ZooError, OSError, ValueError):
            commits.add("not in this zoo")
    return f"{cond.name}: {', '.join(names)} (trained at commit {', '.join(sorted(commits))})"


def _physics_lines(plan: Plan) -> list[str]:
    """The backend settings the study runs at where the plan sets them."""
    if not plan.backends:
        return []
    shown = "; ".join(
        f"{b}: " + ", ".join(f"`{k}` {v}" for k, v in values.items()) for b, values in plan.backends.items()
    )
    return [
        f"The study trains and evaluates at these backend settings over the presets (the plan's `backends:`): {shown}.",
        "",
    ]


def _scope_lines(plan: Plan) -> list[str]:
    """What ``footsim-reproduce`` alone re-evaluates, when the plan narrows it."""
    if plan.default_only is None and plan.default_sets is None:
        return []
    given = " ".join(
        part
        for part in (
            f"only={plan.default_only}" if plan.default_only else "",
            f"sets={','.join(plan.default_sets)}" if plan.default_sets else "",
        )
        if part
    )
    return [
        f"`footsim-reproduce` alone re-evaluates `{given}` (the plan's `reproduce:` scope"
        + (": each zoo policy under its own condition, and the baselines" if plan.default_only == "zoo" else "")
        + ") and keeps the data files' other evaluations; `footsim-reproduce all=true` re-evaluates every "
        "cell of this page.",
        "",
    ]


def render_page(plan: Plan, runs: list[dict], cond_rows: list[dict], root: Path, data_dir: str) -> str:
    cstats = index_stats(cond_rows)
    seeds_of = {}
    for r in cond_rows:
        if r["metric"] == "success":
            seeds_of[(r["condition"], r["scene_set"], r["kind"], r["name"])] = r["n"]
    lines = [
        "# Results",
        "",
        f"Generated by `footsim-reproduce` from the data files in `{data_dir}/` (`{RUNS_FILE}`: each policy seed and",
        f"baseline on each scene set; `{CONDITIONS_FILE}`: per condition the mean over seeds, its 95 % bootstrap",
        "interval and the interquartile mean). Study plan: "
        f"`conf/study/{plan.path.name}`. Do not edit this page: run `footsim-reproduce`.",
        "",
        *_scope_lines(plan),
        *_physics_lines(plan),
        "Cells: mean over training seeds [95 % percentile bootstrap interval over the seeds]; a baseline is "
        "one evaluation. With 3-5 seeds that interval is narrow (it covers the true mean less often than its "
        "95 % says), and [v, v] means every seed scored v. The IQM cuts whole seeds: with 3 it is the mean, "
        "with 5 the mean of the middle 3. Success time and double steps: the mean over seeds of each seed's "
        "mean over its successful episodes.",
        "",
        "The plan's scene sets: "
        + "; ".join(f"{name}: seed {seed}, {n} scenes" for name, (seed, n) in plan.scene_sets.items())
        + " (each table says which it shows).",
        "",
    ]
    header = (
        "| Condition | Scenes | Policy | Seeds | Success | Success IQM | Fall | Collision | Falls + collisions "
        "| Timeout | Success time (s) | Double steps |"
    )
    for table in plan.tables:
        conds = [plan.conditions[c] for c in table["conditions"]]
        lines += [f"## {table['title']}", "", f"Command: `{_table_command(table['conditions'])}`", ""]
        totals: dict[tuple[str, str, str], int] = {}  # a split condition's scenes in all, per set
        for r in runs:
            if r["condition"] in table["conditions"] and plan.conditions[r["condition"]].split_scenes:
                k = (r["condition"], r["scene_set"], r["scenes_seed"])
                totals[k] = totals.get(k, 0) + int(r["n_scenes"])
        used = {
            (r["scene_set"], r["scenes_seed"], int(r["n_scenes"]), "")
            for r in runs
            if r["condition"] in table["conditions"] and not plan.conditions[r["condition"]].split_scenes
        }
        split_by: dict[tuple[str, str, int], list[str]] = {}
        for (cond_name, name, seed), n in totals.items():
            split_by.setdefault((name, seed, n), []).append(cond_name)
        used |= {
            (name, seed, n, f" in all, split over the seeds ({', '.join(sorted(names))})")
            for (name, seed, n), names in split_by.items()
        }
        if used:
            lines += [
                "Scenes: "
                + "; ".join(f"{name}: seed {seed}, {n} scenes{split}" for name, seed, n, split in sorted(used))
                + ".",
                "",
            ]
        lines += ["Training:", ""] + [f"* {_train_line(plan, c)}" for c in _with_stages(plan, conds)] + [""]
        lines += ["Zoo entries:", ""] + [f"* {_zoo_line(plan, c, runs, root)}" for c in conds] + [""]
        lines += [header, "|" + "---|" * 12]
        for cond in conds:
            for set_name in plan.scene_sets:
                keys = [(cond.name, set_name, "policy", "policy")] + [
                    (cond.name, set_name, "baseline", b) for b, cs in plan.baselines.items() if cond.name in cs
                ]
                for key in keys:
                    if key not in seeds_of:
                        continue
                    label = "PPO" if key[2] == "policy" else f"{key[3]} baseline"
                    interval = key[2] == "policy"
                    cells = [
                        cond.title,
                        set_name,
                        label,
                        seeds_of[key] if key[2] == "policy" else "—",
                        _stat(cstats, key, "success", interval=interval),
                        _stat(cstats, key, "success", interval=False)
                        if key[2] == "baseline"
                        else _iqm(cstats, key, "success"),
                        _stat(cstats, key, "fall", interval=interval),
                        _stat(cstats, key, "collision", interval=interval),
                        _stat(cstats, key, "unsafe", interval=interval),
                        _stat(cstats, key, "timeout", interval=interval),
                        _stat(cstats, key, "success_time_mean", 2, interval),
                        _stat(cstats, key, "success_steps_mean", 2, interval),
                    ]
                    lines.append("| " + " | ".join(str(c) for c in cells) + " |")
        lines.append("")
    for matrix in plan.matrices:
        lines += matrix_lines(plan, matrix, cstats, data_dir, runs)
    lines += thesis_table(plan, cstats, root, runs)
    lines += [
        "## Plots",
        "",
        f"* `{data_dir}/success_by_seed.png`: each seed's success on the standard scenes, the mean and its interval.",
        f"* `{data_dir}/learning_curves.png`: training success rate over steps, mean over seeds and the interval"
        " band, one panel per training backend.",
    ]
    for spec in plan.paths:
        cond = plan.conditions[spec["condition"]]
        shown = ", ".join(("policy " + j.name) if j.kind == "policy" else j.name for j in path_jobs(plan, spec, root))
        if not shown:
            continue
        files = ", ".join(f"`{data_dir}/{path_plot_name(spec, k)}`" for k in spec["scenes"])
        lines.append(
            f"* {files}: the footsteps on scene(s) {', '.join(map(str, spec['scenes']))} of the {spec['set']} set, "
            f"{cond.title} ({shown}; each the episode the tables count)."
        )
    lines += [f"* `{m['file']}`: {m['caption']} Command: `{m['command']}`." for m in plan.media]
    lines.append("")
    return "\n".join(lines)


def matrix_plot_name(matrix: Matrix) -> str:
    return f"matrix_{matrix.slug}.png"


def _cell(
    cstats: dict, matrix: Matrix, row: str, backend: str, rand: str, digits: int = 3, sep: str = " "
) -> tuple[float, str]:
    """A matrix cell's success: its mean over seeds and its text (the mean, then after ``sep`` its
    interval, or "1 seed" for a one-seed cell)."""
    stat = cstats.get((matrix.cells[(row, backend, rand)], matrix.scene_set, "policy", "policy", "success"))
    if stat is None or math.isnan(_number(stat["mean"])):
        return math.nan, "—"
    mean = _number(stat["mean"])
    if int(stat["n"]) == 1:
        return mean, f"{mean:.{digits}f}{sep}(1 seed)"
    low, high = _number(stat["ci_low"]), _number(stat["ci_high"])
    return mean, f"{mean:.{digits}f}{sep}[{low:.{digits}f}, {high:.{digits}f}]"


def policy_rows(runs: list[dict], condition: str, scene_set: str = "standard") -> list[dict]:
    """runs.csv's rows of ``condition``'s policy seeds on ``scene_set``."""
    return [r for r in runs if r["condition"] == condition and r["scene_set"] == scene_set and r["kind"] == "policy"]


def pooled_successes(runs: list[dict], condition: str, scene_set: str = "standard") -> tuple[int, int] | None:
    """``(successes, episodes)`` of ``condition``'s policy episodes on ``scene_set`` over all its seeds
    (runs.csv keeps each seed's success rate and scene count); None without rows."""
    rows = policy_rows(runs, condition, scene_set)
    if not rows:
        return None
    episodes = sum(int(r["n_scenes"]) for r in rows)
    return round(sum(_number(r["success"]) * int(r["n_scenes"]) for r in rows)), episodes


def wilson_interval(successes: int, episodes: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (``scipy.stats.binomtest``)."""
    from scipy.stats import binomtest

    ci = binomtest(successes, episodes).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def _kept_range(own: tuple[int, int] | None, other: tuple[int, int] | None) -> str:
    """The kept ratio's range from the two cells' Wilson intervals over their episodes: the other
    backend's low over the own backend's high to its high over the own low (wide: both vary)."""
    if own is None or other is None or own[0] == 0:
        return "—"
    own_low, own_high = wilson_interval(*own)
    other_low, other_high = wilson_interval(*other)
    return f"[{other_low / own_high:.2f}, {other_high / own_low:.2f}]"


def matrix_lines(plan: Plan, matrix: Matrix, cstats: dict, data_dir: str, runs: list[dict] | None = None) -> list[str]:
    """A transfer matrix on the page: one success table per randomization and what each 3D-trained row
    keeps of its own backend's success on the other 3D backends (with ``runs``: each cell's episodes
    and the ratio's range from their Wilson intervals)."""
    seed, n = plan.scene_sets[matrix.scene_set]
    cells = [plan.conditions[c] for c in matrix.cells.values()]
    split = sorted({c.n_scenes or n for c in cells if c.split_scenes})
    per_seed = sorted({c.n_scenes or n for c in cells if not c.split_scenes})
    scenes = []
    if split:
        scenes.append(
            f"{' or '.join(map(str, split))} scenes in all in a split cell (the row's seeds take consecutive blocks "
            "of them; split: the cells derived for the matrix on a 3D backend and the plan's split_scenes conditions)"
        )
    if per_seed:
        scenes.append(f"{' or '.join(map(str, per_seed))} scenes per seed in the other cells")
    names = sorted(set(matrix.cells.values()))
    lines = [
        f"## Transfer matrix: {matrix.title}",
        "",
        f"Command: `footsim-reproduce only=matrix` (this matrix's cells: `{','.join(names)}`).",
        "",
        f"Success on the {matrix.scene_set} scenes (seed {seed}; {'; '.join(scenes)}): mean over the row's "
        "training seeds [95 % bootstrap interval]; a cell of one seed says so. "
        f"Rows: the policies of a trained condition (its training command is in the tables above); columns: the "
        f"backend they are evaluated on. Heatmap: `{data_dir}/{matrix_plot_name(matrix)}`.",
        "",
    ]
    if matrix.note:
        lines += [matrix.note, ""]
    for rand in matrix.randomizations:
        lines += [f"Evaluated with randomization={rand}:", ""]
        lines += ["| Trained (condition, seeds) | " + " | ".join(matrix.backends) + " |"]
        lines += ["|---|" + "---|" * len(matrix.backends)]
        for label, source in matrix.rows.items():
            texts = [_cell(cstats, matrix, label, b, rand)[1] for b in matrix.backends]
            seeds = len(plan.conditions[source].seeds)
            lines.append(f"| {label} ({source}, {seeds} seed{'s' if seeds > 1 else ''}) | " + " | ".join(texts) + " |")
        lines.append("")
    retained = []
    for label, source in matrix.rows.items():
        row = plan.conditions[source]
        if row.backend == "pymunk" or row.backend not in matrix.backends:
            continue
        for rand in matrix.randomizations:
            own, own_text = _cell(cstats, matrix, label, row.backend, rand)
            own_count = pooled_successes(runs or [], matrix.cells[(label, row.backend, rand)], matrix.scene_set)
            for other in matrix.backends:
                if other in ("pymunk", row.backend):
                    continue
                value = _cell(cstats, matrix, label, other, rand)[0]
                other_count = pooled_successes(runs or [], matrix.cells[(label, other, rand)], matrix.scene_set)
                episodes = " / ".join("—" if c is None else str(c[1]) for c in (own_count, other_count))
                ratio = value / own if own > 0 and not math.isnan(value) else math.nan
                if row.randomization == "none":
                    verdict = "—"
                elif math.isnan(ratio):
                    verdict = "no data yet"
                else:
                    verdict = "met" if ratio >= RETENTION_TARGET else "not met"
                ratio_text = "—" if math.isnan(ratio) else f"{ratio:.2f}"
                retained.append(
                    f"| {label} | {rand} | {own_text} | {other} | {episodes} | {ratio_text} "
                    f"| {_kept_range(own_count, other_count)} | {verdict} |"
                )
    if retained:
        lines += [
            f"What a 3D-trained row keeps on the other 3D backends (success there ÷ success on its own backend, "
            f"under the same randomization; target for a row trained with randomization: ≥ {RETENTION_TARGET:g}, "
            "judged at the means). The two cells may hold different scenes and numbers of episodes (all seeds "
            "together: own / on); the range divides the ends of their 95 % Wilson intervals over those "
            "episodes, so it is wide where a cell has few:",
            "",
            "| Trained | Randomization | Success on its own backend | On | Episodes (own / on) | Kept | Kept, range "
            "| Target |",
            "|---|---|---|---|---|---|---|---|",
            *retained,
            "",
        ]
    return lines


def plot_matrix(path: Path, matrix: Matrix, cstats: dict) -> None:
    """A matrix's heatmaps (one per randomization): success mean, with its interval or "1 seed" in each cell."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(matrix.rows)
    fig, axes = plt.subplots(
        1,
        len(matrix.randomizations),
        figsize=(1.9 * len(matrix.backends) * len(matrix.randomizations) + 2.5, 0.75 * len(rows) + 1.6),
        squeeze=False,
    )
    for ax, rand in zip(axes[0], matrix.randomizations):
        values = np.full((len(rows), len(matrix.backends)), np.nan)
        for i, label in enumerate(rows):
            for j, backend in enumerate(matrix.backends):
                mean, text = _cell(cstats, matrix, label, backend, rand, digits=2, sep="\n")
                values[i, j] = mean
                dark = not math.isnan(mean) and mean < 0.6
                ax.text(j, i, text, ha="center", va="center", fontsize=7, color="white" if dark else "black")
        image = ax.imshow(values, vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(matrix.backends)), matrix.backends, fontsize=8)
        ax.set_yticks(range(len(rows)), rows if ax is axes[0][0] else [], fontsize=8)
        ax.set_xlabel("evaluated on")
        ax.set_title(f"randomization={rand}", fontsize=9)
    axes[0][0].set_ylabel("trained")
    fig.colorbar(image, ax=list(axes[0]), label=f"success ({matrix.scene_set} scenes)", shrink=0.8)
    fig.suptitle(f"Transfer matrix: {matrix.title}", fontsize=10)
    atomic_save(lambda tmp: fig.savefig(tmp, dpi=110, format="png", bbox_inches="tight"), path, ".png")
    plt.close(fig)


def _iqm(cstats: dict, key: tuple, metric: str) -> str:
    row = cstats.get((*key, metric))
    return "—" if row is None or row["iqm"] in ("", None) else f"{_number(row['iqm']):.3f}"


def _mean(cstats: dict, condition: str, metric: str, kind: str = "policy", name: str = "policy") -> float:
    row = cstats.get((condition, "standard", kind, name, metric))
    return math.nan if row is None else _number(row["mean"])


def steps_to_reach(plan: Plan, condition: str, reference: str, root: Path) -> tuple[float, str]:
    """The training steps after which ``condition``'s mean training success rate (over its seeds' zoo
    learning curves) first reaches ``reference``'s final one, and its text; NaN when either has no
    curve or it is never reached."""
    ours, theirs = (
        mean_curve(plan, plan.conditions[condition], root),
        mean_curve(plan, plan.conditions[reference], root),
    )
    if ours is None or theirs is None:
        return math.nan, "no learning curve yet"
    final = float(theirs[1][:, -1].mean())
    about = f"{reference}'s final training success ({final:.2f} at {theirs[0][-1]:.0f} steps)"
    mean = ours[1].mean(axis=0)
    reached = np.flatnonzero(mean >= final)
    if not len(reached):
        return math.nan, f"{condition} does not reach {about} in {ours[0][-1]:.0f} steps"
    step = float(ours[0][reached[0]])
    return step, f"{condition} reaches {about} after {step:.0f} steps"


def seed_values(runs: list[dict], condition: str, metric: str) -> dict[int, float]:
    """Each training seed's ``metric`` for ``condition``'s policy on the standard set (runs.csv)."""
    return {int(r["seed"]): _number(r[metric]) for r in policy_rows(runs, condition)}


def paired_difference(runs: list[dict], condition: str, minus: str, metric: str) -> tuple[list[float], float, float]:
    """The per-seed differences ``condition − minus`` (a noise fine-tune and its parent share each
    seed) and the 95 % bootstrap interval of their mean; no differences and a NaN interval unless both
    have the same seeds (the mean of the differences is then the difference of the means), NaN under two."""
    ours, theirs = seed_values(runs, condition, metric), seed_values(runs, minus, metric)
    if ours.keys() != theirs.keys():
        return [], math.nan, math.nan
    diffs = [ours[k] - theirs[k] for k in sorted(ours)]
    low, high = bootstrap_interval(diffs)
    return diffs, low, high


def figure_value(
    cstats: dict, fig: dict, plan: Plan | None = None, root: Path | None = None, runs: list[dict] | None = None
) -> tuple[float, str]:
    """A thesis-table figure's value (mean over seeds on the standard set, or with ``reaches: C`` the
    training steps after which the condition's training success first reaches C's final one) and its
    text; a ``minus:`` figure given ``runs`` adds the interval of the per-seed differences."""
    if fig.get("reaches"):
        if plan is None or root is None:
            raise ValueError("a reaches: figure needs the plan and the zoo")
        return steps_to_reach(plan, fig["condition"], fig["reaches"], root)
    value = _mean(cstats, fig["condition"], fig["metric"])
    text = _stat(cstats, (fig["condition"], "standard", "policy", "policy"), fig["metric"])
    if fig.get("ratio_to"):
        base = _mean(cstats, fig["condition"], fig["metric"], "baseline", fig["ratio_to"])
        value = value / base if base and not math.isnan(base) else math.nan
        text = "—" if math.isnan(value) else f"{value:.2f} (÷ {fig['ratio_to']} baseline {base:.2f})"
    if fig.get("minus"):
        other = _mean(cstats, fig["minus"], fig["metric"])
        value = value - other
        text = "—" if math.isnan(value) else f"{value:+.3f} ({fig['condition']} − {fig['minus']})"
        if runs is not None and not math.isnan(value):
            diffs, low, high = paired_difference(runs, fig["condition"], fig["minus"], fig["metric"])
            if not math.isnan(low):
                text = (
                    f"{value:+.3f} [{low:+.3f}, {high:+.3f}] over {len(diffs)} paired seeds "
                    f"({fig['condition']} − {fig['minus']})"
                )
    return value, text


#: How a thesis-table target names its metric.
TARGET_WORDS = {
    "success": "success",
    "fall": "fall",
    "collision": "collision",
    "unsafe": "falls + collisions",
    "timeout": "timeout",
    "success_time_mean": "success time",
    "success_steps_mean": "double steps",
}


def target_verdict(fig: dict, value: float) -> str:
    """``"<condition> <metric> <op> <limit>: met|not met (<value>)"`` for a figure with a target."""
    op, limit = parse_target(fig["target"])
    subject = TARGET_WORDS.get(fig["metric"], fig["metric"])
    if fig.get("ratio_to"):
        subject = f"{subject} / {fig['ratio_to']}'s"
    if fig.get("minus"):
        subject = f"{subject} change from {fig['minus']}"
    if math.isnan(value):
        verdict = "no data yet"
    else:
        met = value >= limit if op == ">=" else value <= limit
        digits = 2 if fig.get("ratio_to") or fig["metric"] in ("success_time_mean", "success_steps_mean") else 3
        verdict = f"{'met' if met else 'not met'} ({value:{'+' if fig.get('minus') else ''}.{digits}f})"
    return f"{fig['condition']} {subject} {op.replace('>=', '≥').replace('<=', '≤')} {limit:g}: {verdict}"


def thesis_table(plan: Plan, cstats: dict, root: Path, runs: list[dict] | None = None) -> list[str]:
    if not plan.thesis:
        return []
    lines = [
        "## The thesis side by side",
        "",
        "footsim: mean over seeds on the standard scenes [95 % bootstrap interval]; a change between two",
        "conditions with the same training seeds (e.g. a fine-tune and its parent) is the mean of the",
        "per-seed differences [their 95 % bootstrap interval]. Target: each target, met or not at the",
        "mean, with footsim's figure; where a row's target is not met, what was tried is listed below the",
        "table.",
        "",
        "| Question | Thesis | footsim | Target |",
        "|---|---|---|---|",
    ]
    tried = []
    for row in plan.thesis:
        figures, targets = [], []
        for fig in row["figures"]:
            value, text = figure_value(cstats, fig, plan, root, runs)
            figures.append(f"{fig['label']} {text}")
            if fig.get("target"):
                targets.append(target_verdict(fig, value))
        if row.get("tried"):  # the plan's own words, one item per attempt
            items = [row["tried"]] if isinstance(row["tried"], str) else row["tried"]
            tried += [f"**{row['question']}**", "", *(f"* {item}" for item in items), ""]
        lines.append(f"| {row['question']} | {row['thesis']} | {'; '.join(figures)} | {'; '.join(targets) or '—'} |")
    lines.append("")
    if tried:
        lines += ["### What was tried where a target is not met", "", *tried]
    return lines


# -- plots --------------------------------------------------------------------------------------
def plot_success_by_seed(path: Path, plan: Plan, runs: list[dict], cstats_rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tabled = [c for table in plan.tables for c in table["conditions"]]
    conds = [
        c for c in dict.fromkeys(tabled) if any(r["condition"] == c and r["scene_set"] == "standard" for r in runs)
    ]
    # one row per condition (the tables' order, top down), success along x: readable at any count
    fig, ax = plt.subplots(figsize=(9, 0.32 * len(conds) + 1.6))
    stats = {
        (r["condition"], r["kind"], r["name"]): r
        for r in cstats_rows
        if r["scene_set"] == "standard" and r["metric"] == "success"
    }
    for i, cond in enumerate(conds):
        seeds = [_number(r["success"]) for r in policy_rows(runs, cond)]
        ax.plot(seeds, [i] * len(seeds), "o", color="tab:blue", alpha=0.5, label="seed")
        row = stats.get((cond, "policy", "policy"))
        if row is not None and not math.isnan(_number(row["ci_low"])):
            mean, low, high = (_number(row[c]) for c in ("mean", "ci_low", "ci_high"))
            ax.errorbar(
                [mean],
                [i + 0.2],
                xerr=[[mean - low], [high - mean]],
                fmt="s",
                markersize=4,
                color="black",
                capsize=3,
                label="mean, 95 % CI",
            )
        for j, (controller, cs) in enumerate(plan.baselines.items()):
            brow = stats.get((cond, "baseline", controller))
            if cond in cs and brow is not None:
                ax.plot(
                    [_number(brow["mean"])],
                    [i - 0.2 - 0.1 * j],
                    "x",
                    color=f"C{j + 2}",
                    label=f"{controller} baseline",
                )
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles))
    ax.legend(unique.values(), unique.keys(), fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_yticks(range(len(conds)), conds, fontsize=8)
    ax.set_ylim(len(conds) - 0.5, -0.5)
    ax.set_xlabel("success (standard scenes)")
    ax.set_xlim(-0.02, 1.02)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    atomic_save(lambda tmp: fig.savefig(tmp, dpi=110, format="png"), path, ".png")
    plt.close(fig)


def mean_curve(plan: Plan, cond: Condition, root: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """A trained condition's zoo learning curves (training success rate over the run's own steps) on a
    common grid of 100 steps over the range all seeds cover: ``(grid, values[seed, step])``; None
    when no seed's entry has a curve."""
    available = set(zoo.names(root))
    curves = []
    for s in cond.seeds:
        name = plan.entry(cond, s)
        file = root / name / zoo.CURVE_FILE
        if name in available and file.is_file():
            rows = read_csv(file)
            curves.append(
                (np.array([float(r["step"]) for r in rows]), np.array([float(r["success_rate"]) for r in rows]))
            )
    if not curves:
        return None
    grid = np.linspace(max(c[0][0] for c in curves), min(c[0][-1] for c in curves), 100)
    return grid, np.array([np.interp(grid, x, y) for x, y in curves])


def plot_learning_curves(path: Path, plan: Plan, root: Path) -> bool:
    """Training success rate over steps per trained condition (zoo ``learning_curve.csv``): the mean
    over seeds and the pointwise 95 % bootstrap band, one panel per training backend (2D runs take
    millions of steps, 3D ones hundreds of thousands).  False when no entry has a curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = [(cond, mean_curve(plan, cond, root)) for cond in plan.conditions.values() if not cond.policies]
    drawn = [(cond, curve) for cond, curve in curves if curve is not None]
    if not drawn:
        return False
    backends = list(dict.fromkeys(cond.backend for cond, _ in drawn))
    fig, axes = plt.subplots(len(backends), 1, figsize=(10, 3.4 * len(backends)), squeeze=False)
    colors = [plt.get_cmap("tab20")(k) for k in range(20)]
    for ax, backend in zip(axes[:, 0], backends):
        for i, (cond, (grid, values)) in enumerate(c for c in drawn if c[0].backend == backend):
            color = colors[i % len(colors)]
            seeds = f"{len(values)} seed{'s' if len(values) > 1 else ''}"
            ax.plot(grid, values.mean(axis=0), color=color, label=f"{cond.name} ({seeds})")
            if len(values) > 1:
                bands = np.array([bootstrap_interval(values[:, k], n_resamples=2000) for k in range(len(grid))])
                ax.fill_between(grid, bands[:, 0], bands[:, 1], color=color, alpha=0.2)
        ax.set_title(f"trained on {backend}", fontsize=10)
        ax.set_xlabel("training steps (each run's own: a fine-tune counts from 0)")
        ax.set_ylabel("training success rate\n(last 100 episodes)")
        ax.set_ylim(-0.02, 1.02)
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    atomic_save(lambda tmp: fig.savefig(tmp, dpi=110, format="png"), path, ".png")
    plt.close(fig)
    return True


def path_plot_name(spec: dict, k: int) -> str:
    return f"paths_{spec['condition']}_{spec['set']}_{k}.png"


def path_jobs(plan: Plan, spec: dict, root: Path) -> list[Job]:
    """What a path plot shows: the condition's first zoo policy (if the zoo has it) and the
    baselines the plan runs under that condition, each as the evaluation runs it."""
    cond = plan.conditions[spec["condition"]]
    common = _evaluated_as(cond, *plan.scene_sets[spec["set"]])
    common["backend_settings"] = _job_settings(cond, plan.backends)  # as plan_jobs runs them
    jobs = []
    seeds = plan.seeds(cond)
    if seeds and plan.entry(cond, seeds[0]) in set(zoo.names(root)):
        entry = plan.entry(cond, seeds[0])
        jobs.append(Job(cond.name, spec["set"], "policy", entry, seeds[0], **common, beta_action=cond.beta_action))
    for controller, conds in plan.baselines.items():
        if cond.name in conds:
            jobs.append(Job(cond.name, spec["set"], "baseline", controller, None, **common))
    return jobs


def plot_scene_paths(plan: Plan, root: Path, out: Path) -> list[str]:
    """The plan's per-scene path plots (``paths:``): for each listed scene, the footsteps of the
    condition's policy and baselines side by side, each the same episode as in the evaluation
    (``paths_<condition>_<set>_<k>.png`` in ``out``).  Returns the files written."""
    from footsim.planners.report import episode_path, plot_paths
    from footsim.robots.registry import get_robot
    from footsim.tasks.scenes import sample_scenes

    written = []
    for spec in plan.paths:
        jobs = path_jobs(plan, spec, root)
        if not jobs:
            continue
        last = max(spec["scenes"])
        episodes: dict[int, dict] = {k: {} for k in spec["scenes"]}
        scene_of: dict[int, Any] = {}  # the set's scenes (the same for every job: same task and seed)
        robot = None
        for job in jobs:
            with _quiet():
                env, controller = job_env_and_controller(job, root)
                try:
                    robot = robot or env.robot
                    scenes = sample_scenes(env.sampler, last + 1, job.scenes_seed)
                    for k in spec["scenes"]:
                        scene_of[k] = scenes[k]
                        label = "policy " + job.name if job.kind == "policy" else job.name
                        episodes[k][label] = episode_path(env, controller, scenes[k], seed=k)
                finally:
                    env.close()
        for k, runs in episodes.items():
            name = path_plot_name(spec, k)
            plot_paths(out / name, scene_of[k], runs, robot or get_robot("wolfgang"))
            written.append(name)
    return written


# -- the command --------------------------------------------------------------------------------
def reproduce(
    plan: Plan,
    out: Path,
    page: Path,
    root: Path,
    only: str | None = None,
    n_scenes: int | None = None,
    sets: Sequence[str] | None = None,
    workers: int = 1,
    shard_size: int = 50,
    baselines: bool = True,
    progress: bool = True,
    plots: bool = True,
    backend_settings: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict:
    """Evaluate, write the data files, page and plots; returns ``{"differences": [...], "missing": [...], ...}``."""
    sets = list(sets or plan.scene_sets)
    for name in sets:
        if name not in plan.scene_sets:
            raise PlanError(f"sets={','.join(sets)}: no scene set {name!r} in the plan ({', '.join(plan.scene_sets)})")
    conditions = select(plan, only)
    if backend_settings:
        check_backend_settings(backend_settings)
    evaluated_at = {
        b: {**plan.backends.get(b, {}), **(backend_settings or {}).get(b, {})}
        for b in {*plan.backends, *(backend_settings or {})}
    }
    jobs, missing = plan_jobs(plan, conditions, root, n_scenes, sets, baselines, evaluated_at)
    old_runs = read_csv(out / RUNS_FILE)
    recorded = {tuple(r[k] for k in KEY): int(r["n_scenes"]) for r in old_runs}
    if backend_settings:  # other physics must not replace the recorded evaluations
        held = [j for j in jobs if j.backend in backend_settings and tuple(str(v) for v in j.key) in recorded]
        if held:
            raise PlanError(
                f"{out / RUNS_FILE} holds {'/'.join(held[0].key)} and {len(held) - 1} more of the evaluations "
                f"backends.* would redo at other settings: give out=DIR and page=FILE elsewhere"
            )
    fewer = [j for j in jobs if n_scenes is not None and recorded.get(tuple(str(v) for v in j.key), 0) > j.n_scenes]
    if fewer:  # a quick look (n_scenes=20) must not replace the full evaluations in the data files
        j = fewer[0]
        raise PlanError(
            f"{out / RUNS_FILE} holds {recorded[j.key]}-scene evaluations ({'/'.join(j.key)} and "
            f"{len(fewer) - 1} more); n_scenes={j.n_scenes} would replace them: give out=DIR and page=FILE elsewhere"
        )
    if missing:
        print(f"not in the zoo ({len(missing)}), not evaluated: {', '.join(missing)}")
    started = time.time()
    results, seconds = run_jobs(jobs, root, workers, shard_size, progress)
    wall = time.time() - started
    new_runs = [run_row(job, results[job.key]) for job in jobs]

    changed = differences(old_runs, new_runs, KEY, ("n_scenes", *METRICS))
    runs, dropped = planned_rows(plan, merge_rows(old_runs, new_runs, KEY))
    if dropped:
        print(f"dropped {len(dropped)} row(s) of the data files the plan no longer has: {', '.join(dropped)}")
    old_conds = read_csv(out / CONDITIONS_FILE)
    cond_rows = condition_rows(runs)
    changed += differences(old_conds, cond_rows, (*KEY, "metric"), STAT_COLUMNS)
    # conditions.csv is computed from runs.csv: the pair is written together, so that an interrupted
    # write leaves both as they were
    atomic_write_texts(
        {
            out / RUNS_FILE: csv_text((*KEY, *INFO, *METRICS), runs),
            out / CONDITIONS_FILE: csv_text(
                (*KEY, "metric", *STAT_COLUMNS), [{k: _text(v) for k, v in r.items()} for r in cond_rows]
            ),
        }
    )
    cond_rows = read_csv(out / CONDITIONS_FILE)  # the page shows what the file holds
    if plots:
        plot_success_by_seed(out / "success_by_seed.png", plan, runs, cond_rows)
        plot_learning_curves(out / "learning_curves.png", plan, root)
        plot_scene_paths(plan, root, out)
        cstats = index_stats(cond_rows)
        for matrix in plan.matrices:
            plot_matrix(out / matrix_plot_name(matrix), matrix, cstats)
    data_dir = os.path.relpath(out)  # as the reader types it from where the command ran (the repository top)
    atomic_write_text(page, render_page(plan, runs, cond_rows, root, data_dir))
    episodes = sum(j.n_scenes for j in jobs)
    print(f"evaluated {len(jobs)} policies and baselines ({episodes} episodes) in {wall:.0f} s; {out}, {page}")
    if backend_settings:
        shown = " ".join(f"backends.{b}.{k}={v}" for b, values in backend_settings.items() for k, v in values.items())
        print(f"at {shown}, over each backend's preset and the plan's settings (not the study's physics)")
    by_kind: dict[str, float] = {}
    for job in jobs:
        label = f"{job.backend} {'policies' if job.kind == 'policy' else job.name + ' baseline'}"
        by_kind[label] = by_kind.get(label, 0.0) + seconds[job.key]
    print("worker seconds: " + ", ".join(f"{label} {s:.0f} s" for label, s in sorted(by_kind.items())))
    evaluated = {job.key for job in jobs}
    kept = sum(1 for r in runs if tuple(r[k] for k in KEY) not in evaluated)
    if kept:
        print(
            f"{kept} of the data files' {len(runs)} evaluations were not re-evaluated by this selection and keep "
            "their values (footsim-reproduce all=true re-evaluates every one)"
        )
    if changed:
        print(f"{len(changed)} cell(s) differ from the data files there before:")
        for line in changed:
            print(f"  {line}")
    else:
        print("no cell differs from the data files there before" if old_runs else "no data files before: all new")
    return {
        "differences": changed,
        "missing": missing,
        "jobs": len(jobs),
        "episodes": episodes,
        "kept": kept,
        "wall_s": wall,
        "worker_s": by_kind,
    }


# -- training -----------------------------------------------------------------------------------
def _training_order(plan: Plan, conditions: Sequence[Condition]) -> list[Condition]:
    """Trained conditions, each after its parent."""
    order: list[Condition] = []

    def visit(cond: Condition) -> None:
        if cond in order or cond.policies:
            return
        if cond.parent:
            visit(plan.conditions[cond.parent])
        order.append(cond)

    for cond in conditions:
        visit(cond)
    return order


def train_commands(
    plan: Plan, conditions: Sequence[Condition], runs_dir: Path, launcher: str | None
) -> list[list[str]]:
    """The ``footsim-train`` commands of the plan's trainings (parents first).  Without a launcher one
    command per seed; with one, one multirun per condition (``seed=0,1,...``) on that launcher."""
    commands = []
    for cond in _training_order(plan, conditions):
        target = runs_dir / cond.name
        if launcher is None:
            for s in cond.seeds:
                cmd = ["footsim-train", *plan.train_overrides(cond), f"seed={s}"]
                if cond.parent:
                    cmd.append(f"init_from={runs_dir / cond.parent / f'seed{s}'}")
                commands.append([*cmd, f"hydra.run.dir={target / f'seed{s}'}"])
        else:
            cmd = [
                "footsim-train",
                "-m",
                f"+launcher={launcher}",
                *plan.train_overrides(cond),
                f"seed={','.join(str(s) for s in cond.seeds)}",
            ]
            if cond.parent:
                cmd.append(f"init_from={runs_dir / cond.parent}/seed${{seed}}")
            commands.append([*cmd, f"hydra.sweep.dir={target}", "hydra.sweep.subdir=seed${seed}"])
    return commands


def train(
    plan: Plan,
    conditions: Sequence[Condition],
    runs_dir: Path,
    root: Path,
    launcher: str | None = None,
    dry_run: bool = False,
    add: bool = True,
) -> list[list[str]]:
    """Run the trainings (a seed whose run already has ``eval/summary.json`` is skipped: re-running
    resumes the study), then add each finished run to the zoo as its plan name."""
    commands = train_commands(plan, conditions, runs_dir, launcher)
    for cmd in commands:
        line = shlex.join(cmd)
        if launcher is None:
            done = Path(cmd[-1].split("=", 1)[1]) / "eval" / "summary.json"
            if done.is_file():
                print(f"done already: {line}")
                continue
        print(line, flush=True)
        if not dry_run:
            subprocess.run([sys.executable, "-c", "from footsim.tools.train import main; main()", *cmd[1:]], check=True)
    if add and not dry_run:
        for cond in (c for c in _training_order(plan, conditions) if c.shipped):
            for s in cond.seeds:
                run = runs_dir / cond.name / f"seed{s}"
                if (run / "model.zip").is_file():
                    zoo.add(run, plan.entry(cond, s), root, condition=cond.name, force=True)
                    print(f"added {run} to the zoo as {plan.entry(cond, s)}")
    return commands
