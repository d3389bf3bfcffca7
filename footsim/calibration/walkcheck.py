"""Open-loop walking checks (``footsim-walkcheck``, :mod:`footsim.tools.walkcheck`): does it walk?

Runs open-loop double-step sequences on each backend and compares the executed displacement with
the commanded one, the displacement the planar footstep geometry predicts (what the 2D backend
executes).  Two kinds of sequence:

* **required** — walking in place, forward, backward, lateral each side and turning each side at
  :data:`REQUIRED_SHARE` of the step limits, 20 double steps each, and start-and-stop.  The
  default 3D setup must walk them without a fall (``pass``);
* **measured** — the same directions at the step limits and 50 random double steps over the
  whole action box.  A fall there is information about the robot and its gait, not a failure.

Also the cross-backend consistency report (final planar pose differences per backend pair, the 2D
backend included) and :func:`timestep_convergence`: the required sequences at the physics
timestep and at a fraction of it (the physics-setting check of ``docs/BACKENDS.md``), with
:func:`perturbation_sensitivity`, the same comparison between a run and its twin pushed by a
negligible force (how close two runs can agree at all), and :func:`ensemble_convergence`, the
timestep check between ensembles of such pushed runs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from itertools import combinations
from typing import Any

import numpy as np

from footsim import config as fconf
from footsim.calibration.execution_model import ExecutionModel
from footsim.geometry import Pose2D, wrap_angle
from footsim.scene import Scene
from footsim.tasks.nav import tilted_over
from footsim.walk.footsteps import DoubleStep

TOLERANCE = 0.25  # executed vs commanded displacement, reported for every sequence
REQUIRED_SHARE = 0.4  # required sequences: this share of the step limits
# Timestep convergence: halving the physics timestep may move a required sequence's final planar
# pose by less than this, and change no outcome.
CONVERGED_POSITION, CONVERGED_YAW = 0.02, math.radians(2.0)


@dataclass(frozen=True)
class Sequence:
    name: str
    actions: np.ndarray  # (n, 6) in [-1, 1]
    measure: str  # "translation" or "yaw"
    stop: bool = False  # run the stop sequence and stand for a second at the end
    required: bool = False  # the default setup must walk it without a fall


def _repeat(action, n: int = 20) -> np.ndarray:
    return np.tile(np.asarray(action, dtype=float), (n, 1))


def required_sequences() -> list[Sequence]:
    """Walking in place, the six directions at :data:`REQUIRED_SHARE` of the limits, start-and-stop."""
    s = REQUIRED_SHARE
    return [
        Sequence("in place", _repeat([0, 0, 0, 0, 0, 0]), "translation", required=True),
        Sequence("forward", _repeat([s, 0, 0, s, 0, 0]), "translation", required=True),
        Sequence("backward", _repeat([-s, 0, 0, -s, 0, 0]), "translation", required=True),
        Sequence("lateral left", _repeat([0, s, 0, 0, s, 0]), "translation", required=True),
        Sequence("lateral right", _repeat([0, -s, 0, 0, -s, 0]), "translation", required=True),
        Sequence("turn left", _repeat([0, 0, s, 0, 0, s]), "yaw", required=True),
        Sequence("turn right", _repeat([0, 0, -s, 0, 0, -s]), "yaw", required=True),
        Sequence("start and stop", _repeat([0.5, 0, 0, 0.5, 0, 0], 4), "translation", stop=True, required=True),
    ]


def measured_sequences() -> list[Sequence]:
    """The six directions at the step limits and 50 random double steps over the action box."""
    rng = np.random.default_rng(2022)
    return [
        Sequence("forward max", _repeat([1, 0, 0, 1, 0, 0]), "translation"),
        Sequence("backward max", _repeat([-1, 0, 0, -1, 0, 0]), "translation"),
        Sequence("lateral left max", _repeat([0, 1, 0, 0, 1, 0]), "translation"),
        Sequence("lateral right max", _repeat([0, -1, 0, 0, -1, 0]), "translation"),
        Sequence("turn left max", _repeat([0, 0, 1, 0, 0, 1]), "yaw"),
        Sequence("turn right max", _repeat([0, 0, -1, 0, 0, -1]), "yaw"),
        Sequence("random within limits", rng.uniform(-1, 1, size=(50, 6)), "translation"),
    ]


def standard_sequences() -> list[Sequence]:
    """Every walkcheck sequence: the required ones, then the measured ones."""
    return required_sequences() + measured_sequences()


def run_sequence(backend, sequence: Sequence, seed: int = 0, push: np.ndarray | None = None) -> dict:
    """Execute a sequence on a backend from the origin in an empty scene; ``push`` [N] (world
    frame): a force on the torso during the first double step (:func:`perturbation_sensitivity`)."""
    start = backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(seed))

    pose, fell, error, steps, total_yaw = start, False, None, 0, 0.0
    for action in sequence.actions:
        pushed = push is not None and steps == 0
        if pushed:
            backend.sim.apply_base_force(push)
        result = backend.execute(DoubleStep.from_action(action, backend.robot.step_limits))
        if pushed:
            backend.sim.apply_base_force(np.zeros(3))
        steps += 1
        if result.sim_error is not None:
            error = result.sim_error
            break
        total_yaw += wrap_angle(result.pose.theta - pose.theta)  # unwrapped heading change
        pose = result.pose
        if tilted_over(result):
            fell = True
            break
    if sequence.stop and not fell and error is None and hasattr(backend, "stop_walking"):
        backend.stop_walking()
        backend.hold(1.0)
        fell = backend._fallen()
        end = backend.planar_pose()
        total_yaw += wrap_angle(end.theta - pose.theta)
        pose = end
    return {
        "pose": pose,
        "fell": fell,
        "sim_error": error,
        "steps": steps,
        "yaw": total_yaw,
        "displacement": (pose.x - start.x, pose.y - start.y),
    }


def error_ratio(executed: dict, commanded: dict, measure: str) -> float:
    if measure == "yaw":
        return abs(executed["yaw"] - commanded["yaw"]) / max(abs(commanded["yaw"]), 1e-9)
    ex, ey = executed["displacement"]
    cx, cy = commanded["displacement"]
    scale = max(math.hypot(cx, cy), 0.1)  # walking in place: error relative to 0.1 m
    return math.hypot(ex - cx, ey - cy) / scale


def make_backend(
    name: str,
    walk: str | Mapping | None = None,
    robot: str | Mapping | None = None,
    backend_overrides: Mapping | None = None,
):
    """The backend ``name`` with its default walk (or ``walk``: a preset or a mapping over the
    default), robot (default Wolfgang-OP) and its config merged with ``backend_overrides``, composed
    as the env composes them."""
    groups = fconf.env_config(backend={"name": name, **dict(backend_overrides or {})}, walk=walk, robot=robot)
    return fconf.build_backend(groups["backend"], fconf.build_robot(groups["robot"]), fconf.build_walk(groups["walk"]))


def walkcheck(
    backends: list[str],
    walk: str | Mapping | None = None,
    robot: str | Mapping | None = None,
    backend_overrides: Mapping | None = None,
) -> tuple[dict, str]:
    """Every sequence on each backend (and the 2D reference); ``(results, markdown report)``."""
    sequences = standard_sequences()
    results: dict[str, dict[str, dict]] = {}
    for name in ["pymunk", *backends]:
        backend = make_backend(name, walk, robot, None if name == "pymunk" else backend_overrides)
        try:
            results[name] = {seq.name: run_sequence(backend, seq) for seq in sequences}
        finally:
            backend.close()
    lines = []
    for name in backends:
        lines += [
            f"### {name}",
            "",
            "| sequence | kind | double steps | fell? | commanded (dx, dy) [m] / yaw [rad] | executed | error | pass |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for seq in sequences:
            cmd, ex = results["pymunk"][seq.name], results[name][seq.name]
            ratio = error_ratio(ex, cmd, seq.measure)
            walked = not ex["fell"] and ex["sim_error"] is None
            fmt = (
                (lambda r: f"{r['yaw']:+.2f} rad")
                if seq.measure == "yaw"
                else (lambda r: f"({r['displacement'][0]:+.2f}, {r['displacement'][1]:+.2f})")
            )
            fell = "sim error" if ex["sim_error"] else ("yes" if ex["fell"] else "no")
            verdict = ("yes" if walked else "NO") if seq.required else "(measured)"
            lines.append(
                f"| {seq.name} | {'required' if seq.required else 'measured'} | {ex['steps']}/{len(seq.actions)} | "
                f"{fell} | {fmt(cmd)} | {fmt(ex)} | {100 * ratio:.0f} % | {verdict} |"
            )
        lines.append("")
    lines += [
        "### Cross-backend consistency (final planar pose, same sequences)",
        "",
        "| pair | position diff mean [m] | max [m] | yaw diff mean [rad] | max [rad] |",
        "|---|---|---|---|---|",
    ]
    for a, b in combinations(results, 2):
        dp, dy = [], []
        for seq in sequences:
            pa, pb = results[a][seq.name]["pose"], results[b][seq.name]["pose"]
            dp.append(math.hypot(pa.x - pb.x, pa.y - pb.y))
            dy.append(abs(wrap_angle(pa.theta - pb.theta)))
        lines.append(f"| {a} – {b} | {np.mean(dp):.3f} | {np.max(dp):.3f} | {np.mean(dy):.3f} | {np.max(dy):.3f} |")
    return results, "\n".join(lines)


def required_passed(results: Mapping[str, Mapping[str, dict]], backend: str) -> bool:
    """Did ``backend`` walk every required sequence without a fall or sim error?"""
    return all(
        not results[backend][s.name]["fell"] and results[backend][s.name]["sim_error"] is None
        for s in required_sequences()
    )


def timestep_convergence(
    backend: str,
    walk: str | Mapping | None = None,
    robot: str | Mapping | None = None,
    backend_overrides: Mapping | None = None,
    divisor: int = 2,
) -> tuple[list[dict], str]:
    """The required sequences at the backend's physics timestep and at ``1/divisor`` of it (the
    control period unchanged): per sequence the final planar poses' distance and heading
    difference and whether the outcome (fall or not) changed.  Converged: no outcome changed, and
    every sequence walked in both runs ends less than :data:`CONVERGED_POSITION` and
    :data:`CONVERGED_YAW` apart."""
    (coarse,), (fine,), title, control_dt = _at_two_timesteps(backend, walk, robot, backend_overrides, divisor)
    title += f" (control_dt {control_dt * 1000:g} ms)"
    return _compare_runs(coarse, fine, title, f"dt, dt/{divisor}", "converged")


def compare_settings(
    backend: str,
    first: Mapping,
    second: Mapping,
    walk: str | Mapping | None = None,
    robot: str | Mapping | None = None,
) -> tuple[list[dict], str]:
    """The required sequences under two sets of backend overrides (e.g. solver iterations 10 and
    50), compared as :func:`timestep_convergence` compares two timesteps."""
    (a,), _ = _required_runs(backend, walk, robot, first)
    (b,), _ = _required_runs(backend, walk, robot, second)
    first_label, second_label = (", ".join(f"{k}={v}" for k, v in o.items()) or "defaults" for o in (first, second))
    title = f"### {backend}: {first_label} vs {second_label}"
    return _compare_runs(a, b, title, "first, second", "within the bound")


def perturbation_sensitivity(
    backend: str,
    walk: str | Mapping | None = None,
    robot: str | Mapping | None = None,
    backend_overrides: Mapping | None = None,
    push: float = 1e-4,
) -> tuple[list[dict], str]:
    """The floor under :func:`timestep_convergence`: the required sequences at one timestep, once
    as they are and once with a push of ``push`` newtons along +x on the torso during the first
    double step (1e-4 N moves the 6.1 kg model by micrometres), compared as the convergence check
    compares two timesteps.  Where the pushed twin already ends further apart than the bound, no
    timestep can pass it: the gap measures how the walk amplifies any small difference (its
    contact events), not the integration error."""
    (plain, pushed), (physics_dt, _) = _required_runs(
        backend, walk, robot, backend_overrides, pushes=(None, np.array([push, 0.0, 0.0]))
    )
    title = (
        f"### {backend}: physics_dt {physics_dt * 1000:g} ms, unpushed vs pushed by {push:g} N in the first double step"
    )
    return _compare_runs(plain, pushed, title, "unpushed, pushed", "within the bound")


def ensemble_convergence(
    backend: str,
    walk: str | Mapping | None = None,
    robot: str | Mapping | None = None,
    backend_overrides: Mapping | None = None,
    divisor: int = 2,
    members: int = 20,
    push: float = 0.01,
    seed: int = 0,
) -> tuple[list[dict], str]:
    """:func:`timestep_convergence` for a walk that amplifies any small difference: one run against
    one run cannot tell integration error from the spread the walk's contact events make of a
    negligible push (:func:`perturbation_sensitivity`), an ensemble can.  The required sequences at
    the backend's timestep and at ``1/divisor`` of it, each run ``members`` times with a push of
    ``push`` newtons in a random horizontal direction on the torso during the first double step (the
    same pushes at both timesteps), compared by their ensembles (:func:`ensemble_rows`)."""
    angles = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, members)
    pushes = tuple(np.array([push * math.cos(a), push * math.sin(a), 0.0]) for a in angles)
    coarse, fine, title, _ = _at_two_timesteps(backend, walk, robot, backend_overrides, divisor, pushes)
    title += f", ensembles of {members} runs pushed by {push:g} N in random horizontal directions"
    return ensemble_rows(coarse, fine, title, f"dt, dt/{divisor}")


def ensemble_rows(
    a_runs: list[dict[str, dict]], b_runs: list[dict[str, dict]], title: str, pair: str
) -> tuple[list[dict], str]:
    """Per required sequence, two ensembles of runs compared: the falls in each; over the members
    that walked, the distance between the mean final positions and the difference of the circular
    mean headings, with its standard error (from each ensemble's sample spread) and the spreads
    themselves.  Converged: the same number of falls, and the means less than
    :data:`CONVERGED_POSITION` and :data:`CONVERGED_YAW` apart (or every member fell in both)."""

    def summary(runs: list[dict[str, dict]], name: str) -> dict:
        walked = [r[name]["pose"] for r in runs if not (r[name]["fell"] or r[name]["sim_error"])]
        theta = np.array([p.theta for p in walked])
        xy = np.array([(p.x, p.y) for p in walked]).reshape(-1, 2)
        mean_theta = math.atan2(np.sin(theta).mean(), np.cos(theta).mean()) if walked else math.nan
        deviation = np.array([wrap_angle(t - mean_theta) for t in theta])
        n = len(walked)
        return {
            "falls": len(runs) - n,
            "n": n,
            "xy": xy.mean(axis=0) if n else np.full(2, math.nan),
            "theta": mean_theta,
            "theta_sd": float(deviation.std(ddof=1)) if n > 1 else math.nan,
            "xy_sd": float(np.sqrt(((xy - xy.mean(axis=0)) ** 2).sum(axis=1).sum() / (n - 1))) if n > 1 else math.nan,
        }

    rows: list[dict[str, Any]] = []
    for s in required_sequences():
        a, b = summary(a_runs, s.name), summary(b_runs, s.name)
        both = a["n"] > 0 and b["n"] > 0
        distance = float(np.hypot(*(a["xy"] - b["xy"]))) if both else math.nan
        heading = abs(wrap_angle(a["theta"] - b["theta"])) if both else math.nan
        heading_se = math.sqrt(a["theta_sd"] ** 2 / a["n"] + b["theta_sd"] ** 2 / b["n"]) if both else math.nan
        rows.append(
            {
                "sequence": s.name,
                "falls": (a["falls"], b["falls"]),
                "distance": distance,
                "heading": heading,
                "heading_se": heading_se,
                "heading_sd": (a["theta_sd"], b["theta_sd"]),
                "position_sd": (a["xy_sd"], b["xy_sd"]),
                "converged": a["falls"] == b["falls"]
                and (not both or (distance < CONVERGED_POSITION and heading < CONVERGED_YAW)),
            }
        )
    lines = [
        title,
        "",
        f"| sequence | falls ({pair}) | mean position diff [m] | mean heading diff [deg] (± s.e.) "
        f"| members' spread ({pair}) [m; deg] | converged |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        spread = ", ".join(
            f"{p:.3f}; {math.degrees(h):.1f}" for p, h in zip(r["position_sd"], r["heading_sd"], strict=True)
        )
        lines.append(
            f"| {r['sequence']} | {r['falls'][0]}, {r['falls'][1]} | {r['distance']:.3f} | "
            f"{math.degrees(r['heading']):.1f} ± {math.degrees(r['heading_se']):.1f} | {spread} | "
            f"{'yes' if r['converged'] else 'NO'} |"
        )
    return rows, "\n".join(lines)


def _at_two_timesteps(
    backend: str,
    walk: str | Mapping | None,
    robot: str | Mapping | None,
    overrides: Mapping | None,
    divisor: int,
    pushes: tuple[np.ndarray | None, ...] = (None,),
) -> tuple[list[dict[str, dict]], list[dict[str, dict]], str, float]:
    """The required sequences (once per push) at the backend's physics timestep and at ``1/divisor``
    of it, the control period unchanged: ``(coarse runs, fine runs, title, control_dt)``."""
    overrides = dict(overrides or {})
    coarse, (physics_dt, control_dt) = _required_runs(backend, walk, robot, overrides, pushes)
    fine, _ = _required_runs(
        backend, walk, robot, {**overrides, "physics_dt": physics_dt / divisor, "control_dt": control_dt}, pushes
    )
    title = f"### {backend}: physics_dt {physics_dt * 1000:g} ms vs {physics_dt / divisor * 1000:g} ms"
    return coarse, fine, title, control_dt


def _required_runs(
    backend: str,
    walk: str | Mapping | None,
    robot: str | Mapping | None,
    overrides: Mapping | None,
    pushes: tuple[np.ndarray | None, ...] = (None,),
) -> tuple[list[dict[str, dict]], tuple[float, float]]:
    """The required sequences on one backend built with ``overrides``, once per push (see
    :func:`run_sequence`), and that backend's (physics_dt, control_dt)."""
    sim = make_backend(backend, walk, robot, overrides)
    try:
        runs = [{s.name: run_sequence(sim, s, push=push) for s in required_sequences()} for push in pushes]
        return runs, (sim.physics_dt, sim.control_dt)
    finally:
        sim.close()


def _compare_runs(
    a_runs: Mapping[str, dict], b_runs: Mapping[str, dict], title: str, pair: str, verdict: str
) -> tuple[list[dict], str]:
    """Per required sequence: the final planar poses' distance and heading difference between two
    runs, whether the outcome changed, and whether they agree within the convergence bound."""
    rows: list[dict[str, Any]] = []
    for s in required_sequences():
        a, b = a_runs[s.name], b_runs[s.name]
        fell_a, fell_b = bool(a["fell"] or a["sim_error"]), bool(b["fell"] or b["sim_error"])
        distance = math.hypot(a["pose"].x - b["pose"].x, a["pose"].y - b["pose"].y)
        heading = abs(wrap_angle(a["pose"].theta - b["pose"].theta))
        rows.append(
            {
                "sequence": s.name,
                "fell": (fell_a, fell_b),
                "distance": distance,
                "heading": heading,
                # A fall in both runs is the same outcome; where the robot lies then is not compared.
                "converged": fell_a == fell_b
                and (fell_a or (distance < CONVERGED_POSITION and heading < CONVERGED_YAW)),
            }
        )
    lines = [
        title,
        "",
        f"| sequence | fell ({pair}) | final position diff [m] | heading diff [deg] | {verdict} |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['sequence']} | {'yes' if r['fell'][0] else 'no'}, {'yes' if r['fell'][1] else 'no'} | "
            f"{r['distance']:.3f} | {math.degrees(r['heading']):.1f} | {'yes' if r['converged'] else 'NO'} |"
        )
    return rows, "\n".join(lines)


# -- 2D vs 3D consistency -----------------------------------------------------------------------
def execution_model_consistency(model_path: str, backend3d: str = "mujoco", seed: int = 0) -> tuple[list[dict], str]:
    """The measured walkcheck sequences (the action box's edges and random steps) on pymunk
    (geometry), pymunk + model (mean, and with noise) and the 3D backend: final planar pose
    differences to the 3D backend, over the full sequences and with the 2D runs cut at the double
    step where the 3D robot fell."""
    ExecutionModel.load(model_path)  # a bad file fails before the 3D runs
    sequences = measured_sequences()
    ref_backend = make_backend(backend3d)
    try:
        ref = {s.name: run_sequence(ref_backend, s, seed=seed) for s in sequences}
    finally:
        ref_backend.close()
    walk = fconf.build_walk(fconf.load_preset("walk", backend="pymunk"))
    robot = fconf.build_robot("wolfgang")
    variants: dict[str, dict[str, Any]] = {
        "pymunk (geometry)": {},
        "pymunk + model (mean)": {"execution_model": model_path, "execution_noise": False},
        "pymunk + model (with noise)": {"execution_model": model_path},
    }
    rows = []
    for label, options in variants.items():
        backend = fconf.build_backend({"name": "pymunk", **options}, robot, walk)
        try:
            for cut in (False, True):
                dp, dy, dyaw = [], [], []
                for s in sequences:
                    seq = s
                    if cut and ref[s.name]["steps"] < len(s.actions):
                        seq = Sequence(s.name, s.actions[: ref[s.name]["steps"]], s.measure, s.stop)
                    ra = run_sequence(backend, seq, seed=seed)
                    a, b = ra["pose"], ref[s.name]["pose"]
                    dyaw.append(abs(ra["yaw"] - ref[s.name]["yaw"]))
                    dp.append(math.hypot(a.x - b.x, a.y - b.y))
                    dy.append(abs(wrap_angle(a.theta - b.theta)))
                rows.append(
                    {
                        "pair": f"{label} – {backend3d}",
                        "sequences": "cut at 3D fall" if cut else "full",
                        "pos_mean": float(np.mean(dp)),
                        "pos_max": float(np.max(dp)),
                        "yaw_mean": float(np.mean(dy)),
                        "yaw_max": float(np.max(dy)),
                        "turn_mean": float(np.mean(dyaw)),
                        "turn_max": float(np.max(dyaw)),
                    }
                )
        finally:
            backend.close()
    lines = [
        "| pair | sequences | position diff mean [m] | max [m] | yaw diff mean [rad] | max [rad] "
        "| total turn diff mean [rad] | max [rad] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in sorted(rows, key=lambda r: r["sequences"] != "full"):
        lines.append(
            f"| {r['pair']} | {r['sequences']} | {r['pos_mean']:.3f} | {r['pos_max']:.3f} | "
            f"{r['yaw_mean']:.3f} | {r['yaw_max']:.3f} | {r['turn_mean']:.3f} | {r['turn_max']:.3f} |"
        )
    falls = [
        f"{s.name} ({ref[s.name]['steps']}/{len(s.actions)})"
        for s in sequences
        if ref[s.name]["fell"] or ref[s.name]["sim_error"]
    ]
    lines += ["", f"{backend3d} fell in: {', '.join(falls) if falls else 'none'}"]
    return rows, "\n".join(lines)
