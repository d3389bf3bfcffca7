"""The capability map (``footsim-capability``, :mod:`footsim.tools.capability`): which double steps
can the robot execute?

For each cell of a grid over the kinematic action box (the unit action space [-1, 1]^6 of
:meth:`footsim.walk.footsteps.DoubleStep.from_unit`, scaled by the robot's step limits) a trial
is: reset the backend (a fresh episode, so per-episode randomization is drawn anew), walk
``warmup`` double steps in place, command the cell's double step, then one more double step in
place.  A trial falls when a step reports ``fell`` or its ``max_tilt`` exceeds the task's fall
threshold, in the commanded step or the in-place step after it (a step that is too large often
topples the robot while it stops).  The landing error is measured right after the commanded
step: the planar distance and yaw difference of each sole from where
:meth:`~footsim.walk.footsteps.FootstepGeometry.execute` puts it when started from the measured
soles before the step (the landing the 2D backend executes); a trial's error is the mean over
its two feet, taken only when the commanded step ended without a fall or a simulation error.
A trial that falls while walking in place before the cell's step counts as a fall of the cell and
as a warm-up failure (the gait itself is not steady; the cell's step was never commanded).

Every trial starts from a fresh reset rather than after a recovery step, so the trials are
independent and each draws its own randomization; without randomization the simulators are
deterministic and the repeats of a cell agree exactly (``repeats`` matters with ``randomization``).

The map is a CSV (one row per cell) and heatmaps of slices of the box where both feet take the
same step (:func:`slice_panels`); :func:`compare_maps` draws where two maps disagree.
"""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from footsim import config as fconf
from footsim.backends.base import Backend, StepResult
from footsim.geometry import Pose2D, wrap_angle
from footsim.scene import Scene
from footsim.tasks.nav import NavTaskConfig, tilted_over
from footsim.utils import atomic_save, atomic_write_text
from footsim.walk.footsteps import DoubleStep, FeetState

#: The task's default fall threshold [rad] (largest trunk roll or pitch of a step).
FALL_THRESHOLD: float = NavTaskConfig().fall_threshold
AXES = ("x", "y", "theta")
#: Unit-action columns: the right foot's step (it flies first), then the left foot's.
ACTION_COLUMNS = ("right_x", "right_y", "right_theta", "left_x", "left_y", "left_theta")
DEFAULT_GRID = "same:5"


# -- the grid -----------------------------------------------------------------------------------
def _levels(text: str, where: str) -> np.ndarray:
    try:
        values = np.array([float(v) for v in text.split(",") if v.strip()], dtype=float)
    except ValueError:
        raise ValueError(f"grid: {where} levels must be numbers in [-1, 1], got {text!r}") from None
    if values.size == 0 or not np.all(np.isfinite(values)) or np.any(np.abs(values) > 1.0):
        raise ValueError(f"grid: {where} levels must be numbers in [-1, 1], got {text!r}")
    return np.unique(values)


def _count(text: str, mode: str) -> int:
    if not text.isdigit() or int(text) < 2:
        raise ValueError(f"grid: {mode}:N needs a whole number of levels N >= 2, got {text!r}")
    return int(text)


def capability_grid(spec: str = DEFAULT_GRID) -> np.ndarray:
    """The grid's cells as unit actions, shape ``(n, 6)`` (columns :data:`ACTION_COLUMNS`).

    ``spec`` is one of

    * ``same:N`` (``same`` = ``same:5``): both feet take the same step, N evenly spaced levels
      from -1 to 1 per axis (N^3 cells);
    * ``full:N`` (``full`` = ``full:3``): the two feet independent (N^6 cells);
    * ``x:LEVELS/y:LEVELS/theta:LEVELS``: both feet the same step at the listed levels (comma
      separated, in [-1, 1]); an axis left out stays at 0.  E.g. ``x:-1,0,1/y:0/theta:0``.
    """
    spec = spec.strip()
    mode, _, count = spec.partition(":")
    if mode in ("same", "full") and "/" not in spec:
        n = _count(count, mode) if count else (5 if mode == "same" else 3)
        axis = np.linspace(-1.0, 1.0, n)
        per_foot = np.array(np.meshgrid(axis, axis, axis, indexing="ij")).reshape(3, -1).T
        if mode == "same":
            return np.hstack([per_foot, per_foot])
        return np.array([np.concatenate([a, b]) for a in per_foot for b in per_foot])
    levels = {axis: np.zeros(1) for axis in AXES}
    for part in spec.split("/"):
        name, sep, values = part.partition(":")
        name = name.strip()
        if not sep or name not in AXES:
            raise ValueError(
                f"grid: expected same[:N], full[:N] or axis:levels parts joined by '/' with axes "
                f"{', '.join(AXES)}; got {spec!r}"
            )
        levels[name] = _levels(values, name)
    per_foot = np.array(np.meshgrid(levels["x"], levels["y"], levels["theta"], indexing="ij")).reshape(3, -1).T
    return np.hstack([per_foot, per_foot])


# -- one trial ----------------------------------------------------------------------------------
def sole_poses(backend: Backend) -> FeetState:
    """The measured planar poses of the soles (left, right): the sole frames' ground position and
    the heading of their x axes, read from the simulator (the 2D backend's feet as they are)."""
    feet = getattr(backend, "feet", None)
    if backend.kind == "2d":
        if feet is None:
            raise RuntimeError(f"backend {backend.name!r}: sole_poses() before reset()")
        return feet
    sim = backend.sim  # type: ignore[attr-defined]  # every 3D backend is a Physics3DBackend
    robot = backend.robot  # type: ignore[attr-defined]
    poses = []
    for side in ("left", "right"):
        link, origin = robot.sole(side)
        position, rotation = _link_frame(sim, link)
        sole = position + rotation @ np.asarray(origin.xyz)
        sole_rotation = rotation @ origin.rotation
        poses.append(Pose2D(float(sole[0]), float(sole[1]), math.atan2(sole_rotation[1, 0], sole_rotation[0, 0])))
    return FeetState(poses[0], poses[1])


def _link_frame(sim: Any, link: str) -> tuple[np.ndarray, np.ndarray]:
    """World position and rotation matrix of a robot link's frame in a 3D simulator."""
    if hasattr(sim, "robot_id"):  # PyBullet: the URDF link frame
        import pybullet as p

        state = p.getLinkState(
            sim.robot_id, sim.link_index[link], computeForwardKinematics=True, physicsClientId=sim.client
        )
        rotation = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4], dtype=float), rotation
    import mujoco

    if hasattr(sim, "physics"):  # dm-control wraps the raw MuJoCo structures
        model, data = sim.physics.model.ptr, sim.physics.data.ptr
    else:
        model, data = sim.model, sim.data
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, link)
    if body < 0:
        raise ValueError(f"the MuJoCo model has no body {link!r}")
    # body frames of the current state, computed in a scratch copy: the simulation's own derived
    # values (which its control law may read) stay as its last step left them
    scratch = mujoco.MjData(model)
    scratch.qpos[:] = data.qpos
    mujoco.mj_kinematics(model, scratch)
    return scratch.xpos[body].copy(), scratch.xmat[body].reshape(3, 3).copy()


@dataclass(frozen=True)
class Trial:
    """One commanded double step from a steady walk."""

    fell: bool
    sim_error: str | None
    #: where it fell or failed: "warmup" (the in-place walk before the cell's step), "step" (the
    #: commanded step) or "after" (the in-place step after it); None if it did neither
    phase: str | None
    position_error: float  # [m] mean over both soles; NaN when the commanded step fell or failed
    yaw_error: float  # [rad] likewise


def _failed(result: StepResult, threshold: float) -> tuple[bool, str | None]:
    if result.sim_error is not None:
        return False, result.sim_error
    return tilted_over(result, threshold), None


def landing_error(geometry: Any, before: FeetState, double_step: DoubleStep, after: FeetState) -> tuple[float, float]:
    """``(position [m], yaw [rad])`` error of the measured soles ``after`` a double step against the
    landing the footstep geometry predicts from the soles ``before`` it (means over both feet)."""
    _, predicted, _, _ = geometry.execute(before, double_step)
    position = [math.hypot(a.x - p.x, a.y - p.y) for a, p in zip(after, predicted)]
    yaw = [abs(wrap_angle(a.theta - p.theta)) for a, p in zip(after, predicted)]
    return float(np.mean(position)), float(np.mean(yaw))


def run_trial(
    backend: Backend,
    action: np.ndarray,
    rng: np.random.Generator,
    *,
    warmup: int = 2,
    randomizer: Any = None,
    threshold: float = FALL_THRESHOLD,
) -> Trial:
    """Reset, walk ``warmup`` double steps in place, command ``action`` (6 unit values), then one
    double step in place; see the module docstring for what counts."""
    if randomizer is not None and randomizer.active:
        backend.apply_randomization(randomizer.episode(rng))
    backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), rng)
    limits = backend.robot.step_limits  # type: ignore[attr-defined]
    in_place = DoubleStep.from_action(np.zeros(6), limits)
    commanded = DoubleStep.from_action(action, limits)
    nan = math.nan

    def step(double_step: DoubleStep) -> StepResult:
        if randomizer is not None and randomizer.active:
            changed = randomizer.step(rng)
            if changed:
                backend.apply_randomization(changed)
        return backend.execute(double_step)

    for _ in range(warmup):
        fell, error = _failed(step(in_place), threshold)
        if fell or error:  # the walk itself is not steady: the cell's step is never commanded
            return Trial(fell, error, "warmup", nan, nan)
    before = sole_poses(backend)
    fell, error = _failed(step(commanded), threshold)
    if fell or error:
        return Trial(fell, error, "step", nan, nan)
    position, yaw = landing_error(backend.geometry, before, commanded, sole_poses(backend))  # type: ignore[attr-defined]
    fell, error = _failed(step(in_place), threshold)
    return Trial(fell, error, "after" if fell or error else None, position, yaw)


# -- the map ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Cell:
    """One row of ``capability.csv``."""

    action: tuple[float, ...]  # 6 unit values, :data:`ACTION_COLUMNS`
    n: int  # trials
    falls: int
    sim_errors: int
    warmup_failures: int  # trials that fell or failed before the cell's step (the walk is not steady)
    landed: int  # trials whose commanded step ended without a fall or a simulation error
    position_error_mean: float  # [m] over the landed trials (NaN if none)
    position_error_max: float
    yaw_error_mean: float  # [rad]
    yaw_error_max: float

    @property
    def fall_rate(self) -> float:
        return self.falls / self.n if self.n else math.nan

    @classmethod
    def from_trials(cls, action: Sequence[float], trials: Sequence[Trial]) -> Cell:
        position = [t.position_error for t in trials if not math.isnan(t.position_error)]
        yaw = [t.yaw_error for t in trials if not math.isnan(t.yaw_error)]
        nan = math.nan
        return cls(
            action=tuple(float(a) for a in action),
            n=len(trials),
            falls=sum(t.fell for t in trials),
            sim_errors=sum(t.sim_error is not None for t in trials),
            warmup_failures=sum(t.phase == "warmup" for t in trials),
            landed=len(position),
            position_error_mean=float(np.mean(position)) if position else nan,
            position_error_max=float(np.max(position)) if position else nan,
            yaw_error_mean=float(np.mean(yaw)) if yaw else nan,
            yaw_error_max=float(np.max(yaw)) if yaw else nan,
        )


CSV_COLUMNS = (
    *ACTION_COLUMNS,
    "fall_rate",
    "n",
    "falls",
    "sim_errors",
    "warmup_failures",
    "landed",
    "position_error_mean",
    "position_error_max",
    "yaw_error_mean",
    "yaw_error_max",
)
_COUNTS = ("n", "falls", "sim_errors", "warmup_failures", "landed")


def cells_to_csv(cells: Sequence[Cell]) -> str:
    """The map as CSV text (floats written exactly: ``repr``)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for c in cells:
        stats = [getattr(c, f.name) for f in fields(Cell) if f.name != "action"]
        counts, errors = stats[: len(_COUNTS)], stats[len(_COUNTS) :]
        writer.writerow([*map(repr, c.action), repr(c.fall_rate), *counts, *map(repr, errors)])
    return out.getvalue()


def read_map(path: str | Path) -> list[Cell]:
    """``capability.csv`` (a file, or a directory holding one) back as cells."""
    path = Path(path)
    if path.is_dir():
        path = path / "capability.csv"
    if not path.is_file():
        raise FileNotFoundError(f"no capability map at {str(path)!r} (run footsim-capability first)")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        missing = sorted(set(CSV_COLUMNS) - set(reader.fieldnames or ()))
        if missing:
            raise ValueError(f"{path}: not a capability map, missing column(s) {missing}")
        cells = []
        for row in reader:
            cells.append(
                Cell(
                    action=tuple(float(row[c]) for c in ACTION_COLUMNS),
                    n=int(row["n"]),
                    falls=int(row["falls"]),
                    sim_errors=int(row["sim_errors"]),
                    warmup_failures=int(row["warmup_failures"]),
                    landed=int(row["landed"]),
                    position_error_mean=float(row["position_error_mean"]),
                    position_error_max=float(row["position_error_max"]),
                    yaw_error_mean=float(row["yaw_error_mean"]),
                    yaw_error_max=float(row["yaw_error_max"]),
                )
            )
    return cells


def summary(cells: Sequence[Cell]) -> dict[str, float]:
    """The stable share of the box (cells with fall rate 0 and no simulation error) and the
    median landing errors over the cells that landed."""
    stable = [c.falls == 0 and c.sim_errors == 0 for c in cells]
    position = [c.position_error_mean for c in cells if not math.isnan(c.position_error_mean)]
    yaw = [c.yaw_error_mean for c in cells if not math.isnan(c.yaw_error_mean)]
    return {
        "cells": len(cells),
        "stable_share": float(np.mean(stable)) if cells else math.nan,
        "median_position_error": float(np.median(position)) if position else math.nan,
        "median_yaw_error": float(np.median(yaw)) if yaw else math.nan,
        "trials": sum(c.n for c in cells),
        "falls": sum(c.falls for c in cells),
        "sim_errors": sum(c.sim_errors for c in cells),
        "warmup_failures": sum(c.warmup_failures for c in cells),
    }


def summary_text(cells: Sequence[Cell]) -> str:
    s = summary(cells)
    return (
        f"stable share of the action box: {100 * s['stable_share']:.1f} % of {s['cells']} cells "
        f"(fall rate 0); trials {s['trials']}, falls {s['falls']}, sim errors {s['sim_errors']} "
        f"({s['warmup_failures']} of the trials before the cell's step, walking in place); "
        + (
            f"median landing error {100 * s['median_position_error']:.1f} cm, "
            f"{math.degrees(s['median_yaw_error']):.1f} deg"
            if not math.isnan(s["median_position_error"])
            else "no commanded step landed"
        )
    )


def make_backend(backend: str, walk: str | Mapping | None = None, backend_overrides: Mapping | None = None) -> Backend:
    """The backend as :func:`footsim.calibration.walkcheck.make_backend` builds it (the
    backend's own walk preset), or with the walk ``walk`` (a preset name, or a mapping of walk keys
    over a preset, e.g. ``{"trunk_pitch": 0.3}``); ``backend_overrides`` over its config (e.g.
    ``{"rolling_friction": 0.0}``)."""
    from footsim.calibration.walkcheck import make_backend as walkcheck_backend

    return walkcheck_backend(backend, walk, backend_overrides=backend_overrides)


def capability_map(
    backend: str,
    *,
    walk: str | Mapping | None = None,
    randomization: str | None = None,
    grid: str = DEFAULT_GRID,
    repeats: int = 2,
    seed: int = 0,
    warmup: int = 2,
    progress: Callable[[int, int], None] | None = None,
    backend_overrides: Mapping | None = None,
) -> list[Cell]:
    """Measure every cell of ``grid`` ``repeats`` times on ``backend`` (its config merged with
    ``backend_overrides``); trial k of cell i runs with the generator seeded by ``(seed, i, k)``
    (resets, randomization draws)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats!r}")
    if warmup < 0:
        raise ValueError(f"warmup must be >= 0, got {warmup!r}")
    actions = capability_grid(grid)
    sim = make_backend(backend, walk, backend_overrides)
    try:
        randomizer = None
        if randomization not in (None, "", "none"):
            randomizer = fconf.build_randomizer(fconf.load_preset("randomization", randomization), sim)
        cells = []
        for i, action in enumerate(actions):
            trials = [
                run_trial(sim, action, np.random.default_rng([seed, i, k]), warmup=warmup, randomizer=randomizer)
                for k in range(repeats)
            ]
            cells.append(Cell.from_trials(action, trials))
            if progress is not None:
                progress(i + 1, len(actions))
    finally:
        sim.close()
    return cells


# -- pictures -----------------------------------------------------------------------------------
def _same_step(cells: Sequence[Cell]) -> dict[tuple[float, ...], Cell]:
    """The cells where both feet take the same step, by that step's (x, y, theta)."""
    return {c.action[:3]: c for c in cells if c.action[:3] == c.action[3:]}


def _slice(same: Mapping[tuple[float, ...], Any], horizontal: str, vertical: str, held: str, level: float):
    """``(horizontal levels, vertical levels, {(h, v): value})`` of the slice with ``held`` at ``level``."""
    index = {a: AXES.index(a) for a in AXES}
    keys = [k for k in same if k[index[held]] == level]
    hs = sorted({k[index[horizontal]] for k in keys})
    vs = sorted({k[index[vertical]] for k in keys})
    values = {(k[index[horizontal]], k[index[vertical]]): same[k] for k in keys}
    return hs, vs, values


def slice_panels(keys: Sequence[tuple[float, ...]]) -> list[list[tuple[str, str, str, float]]]:
    """The heatmap panels ``(horizontal, vertical, held axis, held level)`` in rows: x–y at every
    theta level of the grid (together: every same-step cell), then x–theta at y and y–theta at x,
    each held at its level nearest 0."""

    def nearest_zero(axis: str) -> float:
        return min({k[AXES.index(axis)] for k in keys}, key=abs)

    thetas = sorted({k[2] for k in keys})
    return [
        [("x", "y", "theta", t) for t in thetas],
        [("x", "theta", "y", nearest_zero("y")), ("y", "theta", "x", nearest_zero("x"))],
    ]


def _draw_slices(
    same: Mapping[tuple[float, ...], Any],
    colour: Callable[[Any], float],
    label: Callable[[Any], str],
    title: str,
    colour_label: str,
    cmap: str,
    vmin: float,
    vmax: float,
    path: str | Path,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = slice_panels(list(same))
    ncols = max(len(row) for row in panels)
    fig, axes = plt.subplots(
        len(panels), ncols, figsize=(4.2 * ncols, 4.0 * len(panels)), constrained_layout=True, squeeze=False
    )
    image = None
    for r, row in enumerate(panels):
        for c in range(len(row), ncols):
            axes[r, c].set_axis_off()
        for ax, (horizontal, vertical, held, level) in zip(axes[r], row):
            hs, vs, values = _slice(same, horizontal, vertical, held, level)
            grid = np.full((len(vs), len(hs)), np.nan)
            for (h, v), value in values.items():
                grid[vs.index(v), hs.index(h)] = colour(value)
            image = ax.imshow(grid, origin="lower", cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto")
            for (h, v), value in values.items():
                ax.text(
                    hs.index(h),
                    vs.index(v),
                    label(value),
                    ha="center",
                    va="center",
                    fontsize=6.5,
                    bbox={"facecolor": "white", "alpha": 0.6, "linewidth": 0, "pad": 1},
                )
            ax.set_xticks(range(len(hs)), [f"{h:+.2g}" for h in hs])
            ax.set_yticks(range(len(vs)), [f"{v:+.2g}" for v in vs])
            ax.set_xlabel(f"{horizontal} (unit action)")
            ax.set_ylabel(f"{vertical} (unit action)")
            ax.set_title(f"{horizontal}–{vertical} at {held} = {level:+.2g}")
    if image is not None:
        fig.colorbar(image, ax=axes, label=colour_label, shrink=0.6)
    fig.suptitle(title)
    atomic_save(lambda tmp: fig.savefig(tmp, format="png", dpi=100), path, suffix=".png")
    plt.close(fig)


def _error_label(position: float, yaw: float) -> str:
    if math.isnan(position):
        return "–"
    return f"{100 * position:.1f}cm\n{math.degrees(yaw):.0f}°"


def plot_map(cells: Sequence[Cell], path: str | Path, title: str = "capability map") -> None:
    """Heatmaps of the same-step slices: colour = fall rate, text = mean landing error."""
    same = _same_step(cells)
    if not same:
        raise ValueError("the map has no cells where both feet take the same step: nothing to draw")
    _draw_slices(
        same,
        lambda c: c.fall_rate,
        lambda c: _error_label(c.position_error_mean, c.yaw_error_mean),
        f"{title} — colour: fall rate; text: mean landing error (position, yaw)",
        "fall rate",
        "RdYlGn_r",
        0.0,
        1.0,
        path,
    )


@dataclass(frozen=True)
class CellDifference:
    """A − B for one cell both maps hold."""

    fall_rate: float
    position_error: float  # [m] NaN where either map has no landing
    yaw_error: float  # [rad]


def map_difference(a: Sequence[Cell], b: Sequence[Cell]) -> dict[tuple[float, ...], CellDifference]:
    """Per common cell, A − B of fall rate and mean landing error."""
    by_action = {c.action: c for c in b}
    out = {}
    for c in a:
        other = by_action.get(c.action)
        if other is not None:
            out[c.action] = CellDifference(
                c.fall_rate - other.fall_rate,
                c.position_error_mean - other.position_error_mean,
                c.yaw_error_mean - other.yaw_error_mean,
            )
    if not out:
        raise ValueError("the two capability maps have no cell in common (different grids?)")
    return out


def compare_maps(a: Sequence[Cell], b: Sequence[Cell], path: str | Path, names: tuple[str, str] = ("A", "B")) -> str:
    """Draw where two maps disagree (same-step slices: colour = fall rate A − B, text = landing
    error A − B); returns a one-line summary."""
    diff = map_difference(a, b)
    same = {k[:3]: d for k, d in diff.items() if k[:3] == k[3:]}
    if not same:
        raise ValueError("the two maps share no cell where both feet take the same step: nothing to draw")

    def label(d: CellDifference) -> str:
        if math.isnan(d.position_error):
            return "–"
        return f"{100 * d.position_error:+.1f}cm\n{math.degrees(d.yaw_error):+.0f}°"

    _draw_slices(
        same,
        lambda d: d.fall_rate,
        label,
        f"{names[0]} − {names[1]} — colour: fall rate difference; text: landing error difference",
        f"fall rate {names[0]} − {names[1]}",
        "RdBu_r",
        -1.0,
        1.0,
        path,
    )
    rates = np.array([d.fall_rate for d in diff.values()])
    position = np.array([d.position_error for d in diff.values()])
    landed = position[~np.isnan(position)]
    return (
        f"{len(diff)} common cells; fall rate differs in {int(np.count_nonzero(rates))} "
        f"(mean |difference| {np.mean(np.abs(rates)):.2f}); mean |landing error difference| "
        f"{100 * np.mean(np.abs(landed)) if landed.size else math.nan:.1f} cm over {landed.size} cells landed on both"
    )


def write_map(cells: Sequence[Cell], out: str | Path, title: str) -> tuple[Path, Path]:
    """``capability.csv`` and ``capability.png`` into the directory ``out`` (atomically)."""
    out = Path(out)
    csv_path, png_path = out / "capability.csv", out / "capability.png"
    atomic_write_text(csv_path, cells_to_csv(cells))
    plot_map(cells, png_path, title)
    return csv_path, png_path


def timed_map(backend: str, **options: Any) -> tuple[list[Cell], float]:
    """:func:`capability_map` and its wall time [s]."""
    start = time.perf_counter()
    cells = capability_map(backend, **options)
    return cells, time.perf_counter() - start
