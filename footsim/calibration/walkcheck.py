"""Open-loop walking checks (``footsim-walkcheck``, :mod:`footsim.tools.walkcheck`): does it walk?

Runs a standard set of open-loop double-step sequences on each backend and compares the
executed displacement with the commanded one — the displacement the planar footstep geometry
predicts (what the 2D backend executes).  A sequence passes when the robot does not fall and
the executed displacement is within 25 % of the commanded one (translation, or yaw for the
turning sequences).  Also prints the cross-backend consistency report: final planar pose
differences per backend pair, the 2D backend included.
"""

from __future__ import annotations

import math
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

TOLERANCE = 0.25


@dataclass(frozen=True)
class Sequence:
    name: str
    actions: np.ndarray  # (n, 6) in [-1, 1]
    measure: str  # "translation" or "yaw"
    stop: bool = False  # run the stop sequence and stand for a second at the end


def standard_sequences() -> list[Sequence]:
    def repeat(action, n=20):
        return np.tile(np.asarray(action, dtype=float), (n, 1))

    rng = np.random.default_rng(2022)
    return [
        Sequence("forward max", repeat([1, 0, 0, 1, 0, 0]), "translation"),
        Sequence("backward max", repeat([-1, 0, 0, -1, 0, 0]), "translation"),
        Sequence("lateral left max", repeat([0, 1, 0, 0, 1, 0]), "translation"),
        Sequence("lateral right max", repeat([0, -1, 0, 0, -1, 0]), "translation"),
        Sequence("turn left max", repeat([0, 0, 1, 0, 0, 1]), "yaw"),
        Sequence("turn right max", repeat([0, 0, -1, 0, 0, -1]), "yaw"),
        Sequence("random within limits", rng.uniform(-1, 1, size=(50, 6)), "translation"),
        Sequence("start and stop", repeat([0.5, 0, 0, 0.5, 0, 0], 4), "translation", stop=True),
    ]


def run_sequence(backend, sequence: Sequence, seed: int = 0) -> dict:
    """Execute a sequence on a backend from the origin in an empty scene."""
    start = backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(seed))

    pose, fell, error, steps, total_yaw = start, False, None, 0, 0.0
    for action in sequence.actions:
        result = backend.execute(DoubleStep.from_action(action, backend.robot.step_limits))
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
    return math.hypot(ex - cx, ey - cy) / max(math.hypot(cx, cy), 1e-9)


def make_backend(name: str):
    walk = fconf.build_walk(fconf.load_preset("walk", backend=name))
    robot = fconf.build_robot("wolfgang")
    return fconf.build_backend(fconf.load_preset("backend", {"name": name}), robot, walk)


def walkcheck(backends: list[str]) -> tuple[dict, str]:
    sequences = standard_sequences()
    results: dict[str, dict[str, dict]] = {}
    for name in ["pymunk", *backends]:
        backend = make_backend(name)
        try:
            results[name] = {seq.name: run_sequence(backend, seq) for seq in sequences}
        finally:
            backend.close()
    lines = []
    for name in backends:
        lines += [
            f"### {name}",
            "",
            "| sequence | double steps | fell? | commanded (dx, dy) [m] / yaw [rad] | executed | error | pass |",
            "|---|---|---|---|---|---|---|",
        ]
        for seq in sequences:
            cmd, ex = results["pymunk"][seq.name], results[name][seq.name]
            ratio = error_ratio(ex, cmd, seq.measure)
            ok = not ex["fell"] and ex["sim_error"] is None and ratio <= TOLERANCE
            fmt = (
                (lambda r: f"{r['yaw']:+.2f} rad")
                if seq.measure == "yaw"
                else (lambda r: f"({r['displacement'][0]:+.2f}, {r['displacement'][1]:+.2f})")
            )
            fell = "sim error" if ex["sim_error"] else ("yes" if ex["fell"] else "no")
            lines.append(
                f"| {seq.name} | {ex['steps']}/{len(seq.actions)} | {fell} | {fmt(cmd)} | {fmt(ex)} | "
                f"{100 * ratio:.0f} % | {'yes' if ok else 'NO'} |"
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


# -- 2D vs 3D consistency -----------------------------------------------------------------------
def execution_model_consistency(model_path: str, backend3d: str = "mujoco", seed: int = 0) -> tuple[list[dict], str]:
    """Walkcheck sequences on pymunk (geometry), pymunk + model (mean, and with noise) and the 3D
    backend: final planar pose differences to the 3D backend, over the full sequences (as
    ``footsim-walkcheck``) and with the 2D runs cut at the double step where the 3D robot fell."""
    ExecutionModel.load(model_path)  # a bad file fails before the 3D runs
    sequences = standard_sequences()
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
