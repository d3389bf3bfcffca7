"""Baseline evaluation report: thesis-style tables, per-scene comparisons, Fig. 6.4-style paths.

``python -m footsim.planners.report OUT [backend=pymunk] [paths=4]`` reads the evaluation
directories ``OUT/<backend>/<controller>/<scene set>/<noise>/`` written by
``scripts/eval_baselines.sh`` (``summary.json`` + ``episodes.csv`` from footsim-eval) and writes
into ``OUT/<backend>/``:

* ``tables.md``: one thesis Table 6.1/6.2-style table per scene set × noise, one row per
  controller (plus the planners' failure reasons);
* ``compare_<set>_<noise>.png``: per-scene time to goal of each pair of controllers (one point
  per scene, coloured by who succeeded);
* ``paths_<k>.png``: the footsteps of each controller on the same obstacle scene (thesis Fig. 6.4).
"""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from footsim.config import load_preset
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.planners.controllers import make_controller
from footsim.rl.common import LoadedPolicy
from footsim.rl.evaluate import EpisodeRecord, PolicyController, format_table
from footsim.robots.registry import get_robot
from footsim.tasks.scenes import load_scenes
from footsim.utils import atomic_save, parse_kv_args
from footsim.walk.footsteps import Side

SETS = ("free", "obstacles")
NOISES = ("none", "localization")
CONTROLLER_ORDER = ("policy", "velocity", "footstep")


def _load(root: Path):
    """{(set, noise): {controller: (summary, records)}}"""
    out: dict = {}
    for summary_path in sorted(root.glob("*/*/*/summary.json")):
        controller, scene_set, noise = summary_path.parts[-4:-1]
        summary = json.loads(summary_path.read_text())
        with open(summary_path.parent / "episodes.csv") as fh:
            records = list(csv.DictReader(fh))
        out.setdefault((scene_set, noise), {})[controller] = (summary, records)
    return out


def write_tables(root: Path, data: dict) -> str:
    parts = []
    for scene_set in SETS:
        for noise in NOISES:
            rows = data.get((scene_set, noise))
            if not rows:
                continue
            ordered = {c: rows[c][0] for c in CONTROLLER_ORDER if c in rows}
            ordered.update({c: rows[c][0] for c in rows if c not in ordered})
            title = (
                f"### {'With obstacles' if scene_set == 'obstacles' else 'Obstacle-free'}, noise: {noise} "
                f"({next(iter(ordered.values()))['episodes']} scenes)"
            )
            parts.append(title + "\n\n" + format_table(ordered))
            reasons = {c: s.get("planner_status") for c, s in ordered.items() if s.get("planner_status")}
            if reasons:
                parts.append(
                    "Planner status at episode end: "
                    + "; ".join(f"{c}: " + ", ".join(f"{k} {v}" for k, v in r.items()) for c, r in reasons.items())
                )
    text = "\n\n".join(parts) + "\n"
    (root / "tables.md").write_text(text)
    return text


def plot_comparisons(root: Path, data: dict) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for (scene_set, noise), rows in sorted(data.items()):
        names = [c for c in CONTROLLER_ORDER if c in rows]
        pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1 :]]
        if not pairs:
            continue
        fig, axes = plt.subplots(1, len(pairs), figsize=(5.5 * len(pairs), 5), squeeze=False)
        for ax, (a, b) in zip(axes[0], pairs):
            ra, rb = rows[a][1], rows[b][1]
            n = min(len(ra), len(rb))
            ta = np.array([float(r["time_s"]) for r in ra[:n]])
            tb = np.array([float(r["time_s"]) for r in rb[:n]])
            sa = np.array([r["outcome"] == "success" for r in ra[:n]])
            sb = np.array([r["outcome"] == "success" for r in rb[:n]])
            for mask, colour, label in (
                (sa & sb, "tab:green", "both succeed"),
                (sa & ~sb, "tab:blue", f"only {a}"),
                (~sa & sb, "tab:orange", f"only {b}"),
                (~sa & ~sb, "tab:red", "neither"),
            ):
                if mask.any():
                    ax.scatter(ta[mask], tb[mask], s=10, c=colour, label=f"{label} ({int(mask.sum())})")
            hi = max(ta.max(), tb.max()) * 1.05
            ax.plot([0, hi], [0, hi], "k--", lw=0.8)
            ax.set_xlabel(f"{a}: episode time [s]")
            ax.set_ylabel(f"{b}: episode time [s]")
            ax.set_title(f"{scene_set}, noise {noise}: per scene")
            ax.legend(fontsize=8)
        path = root / f"compare_{scene_set}_{noise}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    return written


def episode_path(env, controller, scene, seed: int = 0) -> tuple[str, list, list[Pose2D]]:
    """One episode of ``controller`` on ``env`` in ``scene`` (as the evaluation runs episode
    ``seed``): its outcome, the footsteps put down (``[(side, pose)]``, from a backend that keeps
    a ``history``, e.g. the 2D one) and the navigation pose after the reset and each double step."""

    episode = EpisodeRecord(env, controller, scene, seed)
    episode.begin()
    navs = [Pose2D(*episode.info["pose"])]
    while not episode.done:
        navs.append(Pose2D(*episode.step()["pose"]))
    history = list(getattr(env.backend, "history", []) or [])
    return episode.info["outcome"], history, navs


def run_paths(scene, controllers: dict, backend: str = "pymunk", noise: str = "none", seed: int = 0) -> dict:
    """Run each controller on one scene; returns {name: (outcome, footsteps [(side, pose)], nav poses)}."""

    out = {}
    for name, make in controllers.items():
        env = FootstepEnv(backend=backend, task="nav_obstacles" if scene.all_obstacles else "nav", noise=noise)
        try:
            out[name] = episode_path(env, make(env), scene, seed)
        finally:
            env.close()
    return out


def plot_paths(path: Path, scene, runs: dict, robot) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 5), squeeze=False)
    hl, hw = 0.5 * robot.foot_length, 0.5 * robot.foot_width
    xs = [0.0, scene.goal.x] + [o.x for o in scene.all_obstacles]
    ys = [0.0, scene.goal.y] + [o.y for o in scene.all_obstacles]
    for ax, (name, (outcome, history, navs)) in zip(axes[0], runs.items()):
        for o in scene.obstacles:
            ax.add_patch(Circle((o.x, o.y), o.r, color=(0.3, 0.45, 0.85)))
        if scene.ball is not None:
            ax.add_patch(Circle((scene.ball.x, scene.ball.y), scene.ball.r, color="orange"))
        for side, foot in history:
            corners = [foot.transform_point(dx, dy) for dx, dy in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))]
            ax.add_patch(
                Polygon(
                    corners, closed=True, fill=False, lw=0.8, edgecolor="tab:green" if side is Side.LEFT else "tab:red"
                )
            )
        ax.plot([p.x for p in navs], [p.y for p in navs], "k.-", lw=0.6, ms=2)
        ax.arrow(
            scene.goal.x,
            scene.goal.y,
            0.2 * np.cos(scene.goal.theta),
            0.2 * np.sin(scene.goal.theta),
            width=0.015,
            color="c",
        )
        ax.set_title(f"{name}: {outcome}, {len(navs) - 1} double steps")
        ax.set_xlim(min(xs + [p.x for p in navs]) - 0.4, max(xs + [p.x for p in navs]) + 0.4)
        ax.set_ylim(min(ys + [p.y for p in navs]) - 0.4, max(ys + [p.y for p in navs]) + 0.4)
        ax.set_aspect("equal")
    fig.tight_layout()
    atomic_save(lambda tmp: fig.savefig(tmp, dpi=100, format="png"), path, ".png")
    plt.close(fig)


def example_paths(
    root: Path, scenes_file: Path, backend: str = "pymunk", count: int = 4, policy_run: str | None = None
) -> list[Path]:
    scenes = load_scenes(scenes_file)
    controllers: dict[str, Callable[..., Any]] = {
        name: (lambda env, n=name: make_controller(env, _conf(n))) for name in ("velocity", "footstep")
    }
    if policy_run:
        controllers = {"policy": lambda env: PolicyController(LoadedPolicy(Path(policy_run))), **controllers}
    written = []
    robot = None
    for k, scene in enumerate(scenes[:count]):
        runs = run_paths(scene, controllers, backend)
        if robot is None:
            robot = get_robot("wolfgang")
        path = root / f"paths_{k}.png"
        plot_paths(path, scene, runs, robot)
        written.append(path)
    return written


def _conf(name: str) -> dict:
    """A controller's preset, composed from conf/controller/<name>.yaml."""
    return load_preset("controller", name)


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        raise SystemExit("usage: python -m footsim.planners.report OUT [backend=pymunk] [paths=4] [policy_run=RUN]")
    out = Path(argv[0])
    args = parse_kv_args(argv[1:], {"backend": "pymunk", "paths": "4", "policy_run": ""}, "report")
    root = out / args["backend"]
    data = _load(root)
    print(write_tables(root, data))
    for p in plot_comparisons(root, data):
        print("wrote", p)
    scenes_file = out / "scenes_obstacles.json"
    if int(args["paths"]) > 0 and scenes_file.is_file():
        for p in example_paths(root, scenes_file, args["backend"], int(args["paths"]), args["policy_run"] or None):
            print("wrote", p)


if __name__ == "__main__":
    main()
