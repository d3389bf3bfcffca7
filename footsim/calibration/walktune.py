"""The walk-tuning objective (``footsim-walktune``, :mod:`footsim.tools.walktune`): how fast does
this walk go without falling?

Measures the Hamburg Bit-Bots' walk-tuning objective (shared/FACTS.md, "Quintic walk engine")

    v₊ₓ + v₋ₓ + 2·v_y + 0.2·v_yaw

for the composed ``walk`` group on a 3D backend and returns it (higher is better), so that a
Hydra sweep with footsim's Optuna sweeper tunes the walk (``footsim-walktune -m
+hpo=walk_pybullet``, see ``conf/hpo/walk.yaml``).

Each direction (forward, backward, lateral, turn; with ``tune.symmetric`` lateral and turn are
measured to both sides and averaged) is one episode from standing: the commanded speed is
raised through ``tune.levels`` (shares of the robot's step limits); at each level the robot
walks ``tune.warmup`` double steps to reach the new speed, then ``tune.measure`` double steps
over which the executed speed is measured in the simulator (planar displacement along the
commanded direction in the heading frame at the window's start, or the unwrapped yaw change,
divided by the simulated time).  The ladder stops at the first fall (or simulator error) or when
a level is not faster than the best one so far; the direction scores the best speed of a level
completed without falling (m/s, rad/s; 0 when even the first level falls).  A configuration
that cannot stand ``tune.stand_time`` seconds scores 0, and so does one the backend rejects
(e.g. a ``foot_distance`` at which the feet overlap when turning; the reason is in
``walktune.json`` as ``invalid``).

Orders (``tune.command``): ``action`` — the same share of the step limit on both feet,
``DoubleStep.from_action`` as the policy and ``footsim-walkcheck`` use them; ``velocity`` — the
walk engine's velocity orders (``QuinticWalk.footsteps_from_velocity``, the Bit-Bots' walk
interface: lateral steps and turns only on the outward step, so the same level gives half the
lateral / turn speed).

Writes ``walktune.json`` (objective, speeds, every level) into the run directory; the Optuna
sweeper stores its scalars as the trial's user attributes.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import OmegaConf

from footsim import config as fconf
from footsim.backends.base import backend_class
from footsim.geometry import Pose2D, wrap_angle
from footsim.rl.common import write_json
from footsim.scene import Scene
from footsim.tasks.nav import tilted_over
from footsim.walk.footsteps import DoubleStep

DIRECTIONS = {
    "forward": ("v_forward", (1.0, 0.0, 0.0), "x", 1.0),
    "backward": ("v_backward", (-1.0, 0.0, 0.0), "x", -1.0),
    "left": ("v_lateral", (0.0, 1.0, 0.0), "y", 1.0),
    "right": ("v_lateral", (0.0, -1.0, 0.0), "y", -1.0),
    "turn_left": ("v_turn", (0.0, 0.0, 1.0), "yaw", 1.0),
    "turn_right": ("v_turn", (0.0, 0.0, -1.0), "yaw", -1.0),
}
#: The Bit-Bots' weights
WEIGHTS = {"v_forward": 1.0, "v_backward": 1.0, "v_lateral": 2.0, "v_turn": 0.2}


def _order(backend, pattern, level: float, command: str):
    x, y, yaw = (level * p for p in pattern)
    if command == "action":
        return DoubleStep.from_action([x, y, yaw, x, y, yaw], backend.robot.step_limits)
    if command == "velocity":
        # the speed whose per-step order reaches the step limit: v / (2 freq) · multiplier = limit
        engine, limits, p = backend.engine, backend.robot.step_limits, backend.walk_current
        scale = 2.0 * engine.freq
        return engine.footsteps_from_velocity(
            x * limits.x * scale / p.x_speed_multiplier,
            y * limits.y * scale / p.y_speed_multiplier,
            yaw * limits.theta * scale / p.yaw_speed_multiplier,
        )
    raise ValueError(f"tune.command must be 'action' or 'velocity', got {command!r}")


def _speed(start: Pose2D, end: Pose2D, yaw: float, axis: str, sign: float, seconds: float) -> float:
    if axis == "yaw":
        return sign * yaw / seconds
    dx, dy = end.x - start.x, end.y - start.y
    c, s = math.cos(start.theta), math.sin(start.theta)
    local = (c * dx + s * dy) if axis == "x" else (-s * dx + c * dy)
    return sign * local / seconds


def measure_direction(
    backend, name: str, levels, warmup: int, measure: int, command: str, min_gain: float, seed: int = 0
) -> dict:
    """One episode raising the commanded speed in ``name``'s direction; see the module docstring."""
    _, pattern, axis, sign = DIRECTIONS[name]
    backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(seed))
    rows, best, stop = [], 0.0, "all levels"
    for level in levels:
        order = _order(backend, pattern, float(level), command)
        fell, error, start, seconds, yaw = False, None, None, 0.0, 0.0
        for i in range(warmup + measure):
            if i == warmup:
                start, seconds, yaw = backend.planar_pose(), 0.0, 0.0
            before = backend.planar_pose()
            result = backend.execute(order)
            if result.sim_error is not None or tilted_over(result):
                fell, error = True, result.sim_error
                break
            seconds += result.duration_s
            yaw += wrap_angle(result.pose.theta - before.theta)
        row: dict[str, Any] = {"level": float(level), "fell": fell}
        if error is not None:
            row["sim_error"] = str(error)
        if fell:
            rows.append(row)
            stop = "fell" if error is None else "sim error"
            break
        assert start is not None  # measure >= 1: the warm-up's end was reached
        row["speed"] = _speed(start, backend.planar_pose(), yaw, axis, sign, seconds)
        rows.append(row)
        if rows[:-1] and row["speed"] <= best * (1.0 + min_gain):
            best = max(best, row["speed"])
            stop = "no gain"
            break
        best = max(best, row["speed"])
    return {"speed": best, "stop": stop, "levels": rows}


def can_stand(backend, seconds: float, seed: int = 0) -> bool:
    backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(seed))
    backend.hold(seconds)
    error, fell = backend._status()
    return error is None and not fell


def evaluate_walk(backend, tune) -> dict:
    """The objective and its parts for a built backend; ``tune`` is the config's ``tune`` section."""
    levels = [float(v) for v in tune["levels"]]
    if not levels or not all(0.0 < v <= 1.0 for v in levels) or levels != sorted(levels):
        raise ValueError(f"tune.levels must be increasing shares of the step limit in (0, 1], got {levels}")
    warmup, measure = int(tune["warmup"]), int(tune["measure"])
    if warmup < 0 or measure < 1:
        raise ValueError(f"tune.warmup must be >= 0 and tune.measure >= 1, got {warmup}, {measure}")
    names = ["forward", "backward", "left", "turn_left"]
    if tune["symmetric"]:
        names += ["right", "turn_right"]
    started = time.process_time()
    out: dict = {"stands": can_stand(backend, float(tune["stand_time"]), int(tune["seed"]))}
    directions = {}
    if out["stands"]:
        for name in names:
            directions[name] = measure_direction(
                backend, name, levels, warmup, measure, str(tune["command"]), float(tune["min_gain"]), int(tune["seed"])
            )
    terms = {}
    for term in WEIGHTS:
        speeds = [d["speed"] for n, d in directions.items() if DIRECTIONS[n][0] == term]
        terms[term] = float(np.mean(speeds)) if speeds else 0.0
    out.update(terms)
    out["objective"] = float(sum(WEIGHTS[t] * terms[t] for t in WEIGHTS))
    out.update({f"speed_{n}": d["speed"] for n, d in directions.items()})  # scalars: Optuna user attributes
    out["directions"] = directions
    out["cpu_s"] = time.process_time() - started
    return out


def format_result(result: dict) -> str:
    lines = [
        f"objective {result['objective']:.4f} = v+x {result['v_forward']:.3f} + v-x {result['v_backward']:.3f}"
        f" + 2 × v_y {result['v_lateral']:.3f} + 0.2 × v_yaw {result['v_turn']:.3f}"
        f"   (stands: {result['stands']}, {result['cpu_s']:.1f} s CPU)"
    ]
    for name, d in result["directions"].items():
        ladder = "  ".join(f"{r['level']:.2f}:" + ("FELL" if r["fell"] else f"{r['speed']:+.3f}") for r in d["levels"])
        lines.append(f"  {name:10s} best {d['speed']:.3f} ({d['stop']})  {ladder}")
    return "\n".join(lines)


def run(cfg, run_dir: Path | None = None) -> dict:
    """Build the backend from a composed config (``backend``, ``robot``, ``walk``, ``tune``) and
    measure; writes ``walktune.json`` into ``run_dir`` when given."""

    plain = fconf.to_plain(cfg)
    robot = fconf.build_robot(plain["robot"])
    walk = fconf.build_walk(plain["walk"])  # unknown / non-numeric walk keys raise here
    if backend_class(plain["backend"]["name"]).kind != "3d":
        raise ValueError(
            f"footsim-walktune needs a 3D backend (mujoco, dm_control, pybullet), got {plain['backend']['name']!r}"
        )
    try:
        backend = fconf.build_backend(plain["backend"], robot, walk)
    except ValueError as err:  # e.g. feet overlapping at rest: this walk cannot stand, it scores 0
        result = {
            "stands": False,
            **{t: 0.0 for t in WEIGHTS},
            "objective": 0.0,
            "directions": {},
            "cpu_s": 0.0,
            "invalid": str(err),
        }
    else:
        try:
            result = evaluate_walk(backend, plain["tune"])
        finally:
            backend.close()
    result["backend"] = plain["backend"]["name"]
    result["walk"] = plain["walk"]
    if run_dir is not None:
        write_json(Path(run_dir) / "walktune.json", result)
    return result


def enqueue_walk(storage: str, study_name: str, walk: str | dict, keys=None, fixed=()) -> dict:
    """Put a walk preset (name, e.g. ``"pybullet"``, or a mapping) into an Optuna study as its next
    trial, so a sweep starts from the current tuned values (``study.enqueue_trial``).  Only the
    searched ``keys`` (default: the ``walk.*`` params of ``conf/hpo/walk.yaml`` except those in
    ``fixed``, e.g. ``("freq",)`` when the sweep fixes ``walk.freq``) are enqueued; creates the study
    (direction maximize) when missing.  Returns the enqueued params.

        python -c "from footsim.calibration.walktune import enqueue_walk; enqueue_walk(
            'sqlite:///multirun/hpo/walk_pybullet/optuna.db', 'walk_pybullet', 'pybullet')"
    """
    import optuna

    values = fconf.load_preset("walk", walk)
    if keys is None:
        params = OmegaConf.load(fconf.conf_dir() / "hpo" / "walk.yaml").hydra.sweeper.params
        keys = [k[len("walk.") :] for k in params if k[len("walk.") :] not in fixed]
    if storage.startswith("sqlite:///"):
        Path(storage[len("sqlite:///") :]).expanduser().parent.mkdir(parents=True, exist_ok=True)
    study = optuna.create_study(study_name=study_name, storage=storage, direction="maximize", load_if_exists=True)
    enqueued = {f"walk.{k}": float(values[k]) for k in keys}
    study.enqueue_trial(enqueued, user_attrs={"enqueued": str(walk) if isinstance(walk, str) else "mapping"})
    return enqueued
