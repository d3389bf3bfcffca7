"""Evaluation on a fixed scene set: ``footsim-eval run=RUN_DIR [scenes=FILE] [backend=B] [task=T] [noise=N]``.

Baselines run the same way without a run: ``footsim-eval controller=velocity|footstep
[backend=B] [task=T] [noise=N] [scenes=FILE]`` (``footsim.planners``).

Writes ``summary.json``, ``episodes.csv`` and ``goals.png`` (thesis Fig. 6.3 style) into its own
Hydra output directory and prints the thesis-style table.

Shards: ``shard=K/N`` evaluates only the K-th of N contiguous slices of the scene set (episode
``i`` keeps scene ``i`` and seed ``seed + i``) and writes ``shards/K-of-N.json`` (its episodes,
atomically) into the output directory; when all N shard files are there, they are merged into
``summary.json`` / ``episodes.csv`` / ``goals.png``, the same files, episode for episode, as one
process evaluating every scene (:func:`merge_shards`, also ``footsim-eval merge=DIR``).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from omegaconf import DictConfig, ListConfig, OmegaConf

from footsim import config as fconf
from footsim.env import FootstepEnv, make_env
from footsim.planners.controllers import make_controller
from footsim.rl.common import LoadedPolicy, load_run_config, write_json
from footsim.scene import Scene
from footsim.tasks.scenes import load_scenes, sample_scenes
from footsim.utils import atomic_save, atomic_write_text, note_not_honoured

OUTCOME_COLUMNS = ("success", "timeout", "fall", "collision", "sim_error")


class Controller(Protocol):
    """Anything that turns an observation (and the env's info) into a 6-D action; :meth:`reset`
    starts an episode (``seed`` is the episode's, for a controller that samples)."""

    def reset(self, scene: Scene, info: dict, seed: int) -> None: ...

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray: ...


class PolicyController:
    """A trained policy as a controller (it sees only the observation)."""

    def __init__(self, policy: Callable, deterministic: bool = True):
        self.policy, self.deterministic = policy, deterministic

    def reset(self, scene: Scene, info: dict, seed: int) -> None:
        """A stochastic policy samples from torch's generator seeded with the episode's seed, so an
        episode's actions do not depend on the episodes before it (shards match a single process)."""
        if not self.deterministic:
            import torch

            torch.manual_seed(seed)

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        return self.policy(obs, deterministic=self.deterministic)


class EpisodeRecord:
    """One episode of ``controller`` on ``env`` in ``scene`` (seed ``seed``), a double step at a
    time: :meth:`begin`, then :meth:`step` until ``done``, then :meth:`record` (what
    ``episodes.csv`` holds).  :func:`run_episode` runs it in one go; ``footsim.rl.video.side_by_side``
    steps several in lock step."""

    def __init__(self, env, controller: Controller, scene: Scene, seed: int):
        self.env, self.controller, self.scene, self.seed = env, controller, scene, seed
        self.done = False
        self.total = 0.0
        self.contact_steps = 0  # 3D: double steps with a robot-obstacle contact (they do not end the episode)
        self.obs: Any = None  # the last observation (an array once begun)
        self.info: dict = {}

    def begin(self) -> None:
        self.obs, self.info = self.env.reset(seed=self.seed, options={"scene": self.scene})
        self.controller.reset(self.scene, self.info, self.seed)

    def step(self) -> dict:
        obs, reward, terminated, truncated, info = self.env.step(self.controller(self.obs, self.info))
        self.obs, self.info = obs, info
        self.total += reward
        self.contact_steps += bool(info.get("collided", False))
        self.done = bool(terminated or truncated)
        return info

    def record(self) -> dict:
        info, scene = self.info, self.scene
        pose = info["pose"]
        record = {
            "outcome": info["outcome"],
            "time_s": float(info["time_s"]),
            "steps": int(info["steps"]),
            "return": float(self.total),
            "contact_steps": self.contact_steps,
            "final_x": float(pose[0]),
            "final_y": float(pose[1]),
            "final_theta": float(pose[2]),
            "goal_x": scene.goal.x,
            "goal_y": scene.goal.y,
            "goal_theta": scene.goal.theta,
        }
        if hasattr(self.controller, "episode_info"):  # e.g. a planner's failure reason and planning times
            record.update(self.controller.episode_info())
        return record


def run_episode(env, controller: Controller, scene: Scene, seed: int, record_frames: bool = False, film=None):
    """One episode; returns ``(record, frames)``.  ``record_frames``: ``env.render()`` after the
    reset and after each double step (one frame per double step); ``film``: a
    ``footsim.rl.video.EpisodeFilm`` that films it at the simulator's pace (it takes the frames)."""
    episode = EpisodeRecord(env, controller, scene, seed)
    episode.begin()
    frames = [env.render()] if record_frames else []
    if film is not None:
        film.start()
    try:
        while not episode.done:
            info = episode.step()
            if film is not None:
                film.stepped(info)
            if record_frames:
                frames.append(env.render())
        if film is not None:
            film.finish(episode.info)
    finally:
        if film is not None:
            film.detach()
    return episode.record(), frames


def evaluate(
    env,
    controller: Controller,
    scenes: list[Scene],
    seed: int = 0,
    progress: bool = True,
    video_dir: Path | None = None,
    video_episodes: int = 0,
    indices: Sequence[int] | None = None,
    video_fps: float = 30.0,
    video_label: str = "",
) -> list[dict]:
    """Run every scene once (or the scenes at ``indices``); episode ``i`` runs scene ``i`` with seed
    ``seed + i``.  With ``video_dir``, episodes ``i < video_episodes`` are filmed at ``video_fps``
    frames per simulated second into ``episode_III.mp4`` (``footsim.rl.video``; GIF without the
    ``video`` extra), captioned ``video_label``.  Filming does not change an episode.  A scene the
    robot cannot start or finish in is refused before any episode, naming its index."""
    env.unwrapped.sampler.check_scenes(scenes)
    records = []
    iterator: Sequence[int] = range(len(scenes)) if indices is None else indices
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="evaluating", unit="scene", leave=False)
    for i in iterator:
        if video_dir is not None and i < video_episodes:
            from footsim.rl.video import film_episode

            record, _, _ = film_episode(
                env, controller, scenes[i], seed + i, video_dir / f"episode_{i:03d}.mp4", video_fps, label=video_label
            )
        else:
            record, _ = run_episode(env, controller, scenes[i], seed=seed + i)
        records.append({"scene": i, **record})
    return records


def summarize(records: list[dict]) -> dict:
    n = len(records)
    summary: dict = {"episodes": n}
    for outcome in OUTCOME_COLUMNS:
        summary[outcome] = sum(r["outcome"] == outcome for r in records) / n if n else 0.0
    ok = [r for r in records if r["outcome"] == "success"]
    times = np.array([r["time_s"] for r in ok]) if ok else np.array([])
    steps = np.array([r["steps"] for r in ok]) if ok else np.array([])
    summary["success_time_mean"] = float(times.mean()) if ok else math.nan
    summary["success_time_std"] = float(times.std()) if ok else math.nan
    summary["success_steps_mean"] = float(steps.mean()) if ok else math.nan
    summary["success_steps_std"] = float(steps.std()) if ok else math.nan
    # Share of episodes with any robot-obstacle contact (in 3D contacts do not end the episode).
    summary["contact"] = sum(r.get("contact_steps", 0) > 0 for r in records) / n if n else 0.0
    return summary


def format_table(rows: dict[str, dict]) -> str:
    """Thesis Tables 6.1/6.2 as markdown: one row per approach."""
    lines = [
        "| Approach | Success | Timeout | Fall | Collision | Success time [s] | Success steps |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, s in rows.items():
        lines.append(
            f"| {name} | {s['success']:.3f} | {s['timeout']:.3f} | {s['fall']:.3f} | {s['collision']:.3f} | "
            f"{_mean_std(s['success_time_mean'], s['success_time_std'])} | "
            f"{_mean_std(s['success_steps_mean'], s['success_steps_std'])} |"
        )
    return "\n".join(lines)


def _mean_std(mean, std) -> str:
    """``mean ± std`` with 2 decimals; "—" when undefined (no successful episode: NaN in memory,
    null in summary.json)."""
    if mean is None or math.isnan(mean):
        return "—"
    return f"{mean:.2f} ± {std:.2f}"


def write_results(
    out_dir: Path,
    records: list[dict],
    summary: dict,
    scenes: list[Scene] | None = None,
    plot: bool = True,
    title: str = "",
) -> None:

    out_dir.mkdir(parents=True, exist_ok=True)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(records[0].keys()))
    writer.writeheader()
    writer.writerows(records)
    atomic_write_text(out_dir / "episodes.csv", buffer.getvalue())
    write_json(out_dir / "summary.json", summary)
    if plot:
        plot_goals(out_dir / "goals.png", records, title=title)


def plot_goals(path: Path, records: list[dict], title: str = "") -> None:
    """Goal poses coloured by time to reach (log scale); fall red, timeout black, collision cyan."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    fig, ax = plt.subplots(figsize=(7, 6))
    ok = [r for r in records if r["outcome"] == "success"]
    if ok:
        times = np.array([r["time_s"] for r in ok])
        q = ax.quiver(
            [r["goal_x"] for r in ok],
            [r["goal_y"] for r in ok],
            np.cos([r["goal_theta"] for r in ok]),
            np.sin([r["goal_theta"] for r in ok]),
            times,
            cmap="viridis",
            norm=LogNorm(vmin=max(times.min(), 1e-2), vmax=max(times.max(), 1e-1)),
            scale=30,
            width=0.004,
        )
        fig.colorbar(q, ax=ax, label="time to reach [s]")
    for outcome, colour in (("fall", "red"), ("timeout", "black"), ("collision", "cyan"), ("sim_error", "magenta")):
        bad = [r for r in records if r["outcome"] == outcome]
        if bad:
            ax.quiver(
                [r["goal_x"] for r in bad],
                [r["goal_y"] for r in bad],
                np.cos([r["goal_theta"] for r in bad]),
                np.sin([r["goal_theta"] for r in bad]),
                color=colour,
                scale=30,
                width=0.004,
                label=f"{outcome} ({len(bad)})",
            )
    ax.plot([0], [0], "k+", markersize=12)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or "goal poses by time to reach")
    if any(r["outcome"] != "success" for r in records):
        ax.legend(loc="upper right", fontsize=8)
    atomic_save(lambda tmp: fig.savefig(tmp, dpi=110, format="png"), path, ".png")
    plt.close(fig)


def eval_scenes(cfg_eval, sampler) -> list[Scene]:
    """The eval scene set: a file, or ``n_scenes`` sampled from ``scenes_seed`` for the task."""
    if cfg_eval.get("scenes"):
        return load_scenes(cfg_eval.scenes)
    return sample_scenes(sampler, int(cfg_eval.n_scenes), int(cfg_eval.scenes_seed))


# -- shards -------------------------------------------------------------------------------------
SHARDS_DIR = "shards"


@dataclass(frozen=True)
class Shard:
    """The ``index``-th of ``count`` contiguous slices of a scene set (``shard=K/N``)."""

    index: int
    count: int

    @classmethod
    def parse(cls, text: Any) -> Shard:
        try:
            index, count = (int(part) for part in str(text).split("/"))
        except ValueError:
            raise ValueError(f"shard must be K/N (shard K of N, 0 <= K < N), got {text!r}") from None
        if not 0 <= index < count:
            raise ValueError(f"shard must be K/N with 0 <= K < N, got {text!r}")
        return cls(index, count)

    @property
    def name(self) -> str:
        return f"{self.index}/{self.count}"

    def path(self, out_dir: Path) -> Path:
        return out_dir / SHARDS_DIR / f"{self.index}-of-{self.count}.json"

    def scenes(self, n_scenes: int) -> range:
        """This shard's scene indices: shard sizes differ by at most one."""
        if self.count > n_scenes:
            raise ValueError(f"shard={self.name}: {self.count} shards for {n_scenes} scenes; use at most {n_scenes}")
        return range(self.index * n_scenes // self.count, (self.index + 1) * n_scenes // self.count)


def shard_of(cfg_eval) -> Shard | None:
    """The eval config's ``shard`` (None: every scene in this process)."""
    text = cfg_eval.get("shard")
    return None if text in (None, "") else Shard.parse(text)


def evaluation_id(scenes: list[Scene], **setting: Any) -> str:
    """A digest of the scene set and of everything else an episode depends on: shards merge only
    with shards of the same evaluation."""
    payload = json.dumps(
        {"scenes": [s.to_dict() for s in scenes], **setting}, sort_keys=True, default=str, allow_nan=True
    )
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def _results(
    out_dir: Path, records: list[dict], label: str, plot: bool, baseline: bool, config_used: dict | None
) -> dict:
    """summary.json, episodes.csv (and goals.png, config_used.json) of a whole evaluation; prints the table."""
    summary = summarize(records)
    if baseline:
        statuses = [r["planner_status"] for r in records if "planner_status" in r]
        summary["planner_status"] = {k: statuses.count(k) for k in sorted(set(statuses))}
    summary["label"] = label
    write_results(out_dir, records, summary, plot=plot, title=label)
    if config_used is not None:
        write_json(out_dir / "config_used.json", config_used)
    print(format_table({label: summary}))
    print(f"results in {out_dir}")
    return summary


def _finish(
    out_dir: Path,
    records: list[dict],
    label: str,
    cfg_eval,
    shard: Shard | None,
    evaluation: str,
    n_scenes: int,
    baseline: bool = False,
    config_used: dict | None = None,
) -> dict:
    plot = bool(cfg_eval.get("plot", True))
    if shard is None:
        return _results(out_dir, records, label, plot, baseline, config_used)
    part = {
        "shard": shard.name,
        "index": shard.index,
        "count": shard.count,
        "n_scenes": n_scenes,
        "evaluation": evaluation,
        "label": label,
        "baseline": baseline,
        "config_used": config_used,
        "records": records,
    }
    # allow_nan: the records round-trip exactly (NaN included), so the merged CSV is the single run's
    atomic_write_text(shard.path(out_dir), json.dumps(part, allow_nan=True, default=float) + "\n")
    print(f"shard {shard.name} ({len(records)} episodes) written to {shard.path(out_dir)}")
    merged = merge_shards(out_dir, plot=plot, require_all=False)
    return merged if merged is not None else {**summarize(records), "label": label, "shard": shard.name}


def merge_shards(out_dir: str | Path, plot: bool = True, require_all: bool = True) -> dict | None:
    """Merge ``out_dir/shards/K-of-N.json`` into ``out_dir``'s summary.json / episodes.csv.

    Missing shards are named (with their scenes): an error with ``require_all``, else a note and
    None.  Shards of different evaluations (scene set, policy, conditions) or shard counts in one
    directory are an error naming the files.  Shard files are kept.
    """
    out_dir = Path(out_dir)
    files = sorted((out_dir / SHARDS_DIR).glob("*-of-*.json"))
    if not files:
        raise FileNotFoundError(f"merge: no shard files ({SHARDS_DIR}/K-of-N.json) in {out_dir}")
    parts = []
    for path in files:
        try:
            parts.append((path, json.loads(path.read_text())))
        except (OSError, ValueError) as err:
            raise ValueError(f"merge: unreadable shard file {path}: {err}") from None
    kinds = {(p["evaluation"], p["count"], p["n_scenes"]) for _, p in parts}
    if len(kinds) > 1:
        listing = "; ".join(f"{path.name}: evaluation {p['evaluation']}, {p['count']} shards" for path, p in parts)
        raise ValueError(
            f"merge: {out_dir / SHARDS_DIR} holds shards of different evaluations ({listing}); "
            "give each evaluation its own output directory"
        )
    by_index = {p["index"]: p for _, p in parts}
    first = parts[0][1]
    count, n_scenes = int(first["count"]), int(first["n_scenes"])
    missing = [Shard(k, count) for k in range(count) if k not in by_index]
    if missing:
        names = ", ".join(
            f"{m.name} (scenes {m.scenes(n_scenes).start}..{m.scenes(n_scenes).stop - 1})" for m in missing
        )
        message = (
            f"{len(missing)} of {count} shards missing in {out_dir / SHARDS_DIR}: {names}; run each alone with "
            f"the same footsim-eval command and shard=K/N hydra.run.dir={out_dir}"
        )
        if require_all:
            raise FileNotFoundError(f"merge: {message}")
        print(f"note: {message}; merged when all are there")
        return None
    records = [r for k in range(count) for r in by_index[k]["records"]]
    if [r["scene"] for r in records] != list(range(n_scenes)):
        raise ValueError(f"merge: the shards in {out_dir / SHARDS_DIR} do not cover scenes 0..{n_scenes - 1} once each")
    return _results(out_dir, records, first["label"], plot, bool(first["baseline"]), first["config_used"])


def _conditions(backend: str, task: str, noise: str, randomization: str | None) -> str:
    """A result label's conditions; randomization only when there is any."""
    text = f"{backend}, {task}, noise={noise}"
    return text if randomization in (None, "", "none") else f"{text}, randomization={randomization}"


def eval_run_config(run_dir: Path, cfg_eval) -> DictConfig:
    """The config ``footsim-eval run=RUN_DIR`` evaluates: the run's saved one, with the groups set
    on the command line (``backend``, ``task``, ``noise``, ``randomization``, ``walk``; a mapping
    merges over its preset) in place of the run's.

    On another backend the policy walks with that backend's walk preset (:func:`walk_on_backend`),
    and a note says so when that differs from the run's walk; ``walk=W`` (e.g. ``walk=bitbots_sim
    walk.trunk_pitch=0.3``) sets the walk instead.  A task whose observation differs from the run's
    (rays, IMU, path hint) is refused: the policy cannot read it.
    """
    run_cfg = load_run_config(run_dir)
    OmegaConf.set_struct(run_cfg, False)
    if cfg_eval.get("task") is not None:
        task = fconf.load_preset("task", cfg_eval.task)
        trained = fconf.build_task(fconf.to_plain(run_cfg.task))[1].observation_layout
        asked = fconf.build_task(task)[1].observation_layout
        if asked != trained:
            raise SystemExit(
                f"footsim-eval: task={task['name']} cannot be evaluated with the policy of {run_dir}: it reads "
                f"{_layout_text(trained)} (its task {run_cfg.task.name}), task {task['name']} gives "
                f"{_layout_text(asked)}. Leave task= out to evaluate on the run's task."
            )
        run_cfg.task = task
    if cfg_eval.get("walk") is not None:
        run_cfg.walk = fconf.load_preset("walk", cfg_eval.walk)
    elif cfg_eval.get("backend") is not None:
        name = cfg_eval.backend.name
        walk, differing = walk_on_backend(run_cfg, name)
        if differing:
            shown = _listed([f"walk.{k}" for k in differing])
            note_not_honoured(
                f"backend={name}",
                f"walking with the {name} backend's walk preset (conf/walk/{name}.yaml)",
                f"the run's walk ({shown} differ)",
            )
        run_cfg.walk = walk
    for group in ("backend", "noise", "randomization"):
        if cfg_eval.get(group) is not None:
            asked = fconf.load_preset(group, cfg_eval[group])
            _note_dropped_settings(group, fconf.to_plain(run_cfg.get(group) or {}), asked)
            run_cfg[group] = asked
    return run_cfg


def _note_dropped_settings(group: str, recorded: dict, asked: dict) -> None:
    """Say which of the run's own settings of ``group`` (values its preset does not have) the asked
    preset of the same name drops, e.g. the study's 2 ms MuJoCo step under ``backend=mujoco``."""
    name = asked.get("name")
    if recorded.get("name") != name:
        return
    preset = fconf.load_preset(group, name)
    dropped = [k for k in sorted(recorded) if k in preset and recorded[k] != preset[k] and asked.get(k) == preset[k]]
    if dropped:
        note_not_honoured(
            f"{group}={name}",
            f"the conf/{group}/{name}.yaml preset with the command line's keys",
            f"the run's recorded {_listed([f'{group}.{k}={recorded[k]}' for k in dropped])} "
            "(give them on the command line to keep them)",
        )


def _listed(items: list[str], most: int = 4) -> str:
    """The first ``most`` items, comma-separated, and an ellipsis when there are more."""
    return ", ".join(items[:most]) + (", …" if len(items) > most else "")


def walk_on_backend(run_cfg, backend: str) -> tuple[dict, list[str]]:
    """The walk a run's policy walks with on ``backend``, and the walk keys in which it differs from
    the run's: on its training backend the run's own walk, on another that backend's walk preset
    (``conf/walk/<backend>.yaml``; a gait is tuned per simulator)."""
    run_walk = fconf.to_plain(run_cfg.walk)
    if backend == run_cfg.backend.name:
        return run_walk, []
    walk = fconf.load_preset("walk", backend=backend)
    return walk, sorted(k for k in set(walk) | set(run_walk) if walk.get(k) != run_walk.get(k))


def _layout_text(layout: tuple[tuple[str, int], ...]) -> str:
    """``goal_and_actions 17 + rays 36 = 53 inputs``"""
    return " + ".join(f"{block} {size}" for block, size in layout) + f" = {sum(s for _, s in layout)} inputs"


def evaluate_run(run_cfg, run_dir: Path, out_dir: Path, cfg_eval, label: str | None = None) -> dict:
    """Evaluate a run's trained policy with the (possibly overridden) run config."""

    video = bool(cfg_eval.get("video", False))
    shard = shard_of(cfg_eval)
    env = make_env(run_cfg, render_mode="rgb_array" if video else None)
    try:
        scenes = eval_scenes(cfg_eval, env.sampler)
        if bool(scenes[0].obstacles) != bool(env.task.obstacles):
            print("note: the scene set and the task disagree about obstacles; evaluating as given")
        policy = LoadedPolicy(run_dir, beta_action=cfg_eval.get("beta_action"))
        controller = PolicyController(policy, deterministic=bool(cfg_eval.deterministic))
        records = evaluate(
            env,
            controller,
            scenes,
            seed=int(cfg_eval.get("seed", 0)),
            video_dir=out_dir / "videos" if video else None,
            video_episodes=int(cfg_eval.get("video_episodes", 3)),
            indices=None if shard is None else shard.scenes(len(scenes)),
            video_fps=float(cfg_eval.get("video_fps", 30.0)),
            video_label=env.config["backend"]["name"],
        )
    finally:
        env.close()
    randomization = (run_cfg.get("randomization") or {}).get("name")
    conditions = _conditions(run_cfg.backend.name, run_cfg.task.name, run_cfg.noise.get("name", ""), randomization)
    if cfg_eval.get("beta_action"):
        conditions += f", Beta {cfg_eval.beta_action}"
    name = label or f"policy ({conditions})"
    evaluation = (
        ""
        if shard is None
        else evaluation_id(
            scenes,
            run=str(run_dir),
            config=fconf.to_plain(run_cfg),
            seed=int(cfg_eval.get("seed", 0)),
            deterministic=bool(cfg_eval.deterministic),
            **({"beta_action": cfg_eval.beta_action} if cfg_eval.get("beta_action") else {}),
        )
    )
    return _finish(out_dir, records, name, cfg_eval, shard, evaluation, len(scenes))


def evaluate_baseline(cfg_eval, out_dir: Path, label: str | None = None) -> dict:
    """Evaluate a baseline controller (``cfg_eval.controller``) on the eval scene set.

    ``backend``/``task``/``noise``/``randomization`` are the eval config's groups (defaults
    pymunk, the scene file's task or nav, none, none); the walk is the backend's preset, as in
    training.
    """

    scenes = load_scenes(cfg_eval.scenes) if cfg_eval.get("scenes") else None
    task = cfg_eval.get("task")
    if task is None:
        task = "nav_obstacles" if scenes is not None and any(s.all_obstacles for s in scenes) else "nav"
    backend = cfg_eval.get("backend") or "pymunk"
    noise = cfg_eval.get("noise") or "none"
    randomization = cfg_eval.get("randomization") or "none"
    video = bool(cfg_eval.get("video", False))
    shard = shard_of(cfg_eval)
    env = FootstepEnv(
        backend=fconf.to_plain(backend),
        task=fconf.to_plain(task),
        noise=fconf.to_plain(noise),
        randomization=fconf.to_plain(randomization),
        render_mode="rgb_array" if video else None,
    )
    try:
        if scenes is None:
            scenes = eval_scenes(cfg_eval, env.sampler)
        controller_cfg = fconf.to_plain(cfg_eval.controller)
        controller = make_controller(env, controller_cfg)
        records = evaluate(
            env,
            controller,
            scenes,
            seed=int(cfg_eval.get("seed", 0)),
            video_dir=out_dir / "videos" if video else None,
            video_episodes=int(cfg_eval.get("video_episodes", 3)),
            indices=None if shard is None else shard.scenes(len(scenes)),
            video_fps=float(cfg_eval.get("video_fps", 30.0)),
            video_label=env.config["backend"]["name"],
        )
        cfg_used = {"controller": controller_cfg, **env.config}
    finally:
        env.close()
    config = env.config
    conditions = _conditions(
        config["backend"]["name"],
        config["task"]["name"],
        config["noise"].get("name", ""),
        (config.get("randomization") or {}).get("name"),
    )
    name = label or f"{controller_cfg['name']} baseline ({conditions})"
    evaluation = "" if shard is None else evaluation_id(scenes, config=cfg_used, seed=int(cfg_eval.get("seed", 0)))
    return _finish(
        out_dir, records, name, cfg_eval, shard, evaluation, len(scenes), baseline=True, config_used=cfg_used
    )


def evaluate_side_by_side(run_dir: Path, out_dir: Path, cfg_eval) -> list[dict]:
    """``footsim-eval run=RUN_DIR video=true backends=[A,B,...]`` (or ``'backends=A,B'``): the run's
    policy on each backend (each walking with that backend's walk preset, as ``backend=B`` does), on the first
    ``video_episodes`` scenes of the eval set, filmed side by side into
    ``videos/side_by_side_III.mp4`` (``footsim.rl.video.side_by_side``); the episodes' records go to
    ``side_by_side.json``.  Returns them (one per scene and backend)."""
    from footsim.backends.base import require_known_backends
    from footsim.rl.video import side_by_side

    given = cfg_eval.backends
    parts = list(given) if isinstance(given, (list, tuple, ListConfig)) else str(given).split(",")
    names = [str(n).strip() for n in parts if str(n).strip()]
    if len(names) < 2:
        raise SystemExit(f"footsim-eval: backends= needs two or more backends (A,B), got {cfg_eval.backends!r}")
    require_known_backends(names, "footsim-eval")
    if not bool(cfg_eval.get("video", False)):
        raise SystemExit("footsim-eval: backends= films the backends side by side; add video=true")
    if cfg_eval.get("backend") is not None:
        note_not_honoured(f"backend={cfg_eval.backend.name}", f"the backends {', '.join(names)}", "backend=")
    fps = float(cfg_eval.get("video_fps", 30.0))
    policy = LoadedPolicy(run_dir, beta_action=cfg_eval.get("beta_action"))
    envs: list[FootstepEnv] = []
    try:
        for name in names:
            sub = cfg_eval.copy()
            OmegaConf.set_struct(sub, False)
            sub.backend = fconf.load_preset("backend", name)
            envs.append(make_env(eval_run_config(run_dir, sub), render_mode="rgb_array"))
        scenes = eval_scenes(cfg_eval, envs[0].sampler)
        for env in envs:
            env.sampler.check_scenes(scenes)
        controllers = [PolicyController(policy, deterministic=bool(cfg_eval.deterministic)) for _ in envs]
        records = []
        for i in range(min(int(cfg_eval.get("video_episodes", 3)), len(scenes))):
            episodes, path, frames = side_by_side(
                envs, controllers, names, scenes[i], int(cfg_eval.get("seed", 0)) + i,
                out_dir / "videos" / f"side_by_side_{i:03d}.mp4", fps,
            )  # fmt: skip
            records += [{"scene": i, "backend": name, **r} for name, r in zip(names, episodes)]
            outcomes = ", ".join(f"{name} {r['outcome']} ({r['time_s']:.1f} s)" for name, r in zip(names, episodes))
            print(f"scene {i}: {outcomes} -> {path} ({frames} frames)")
    finally:
        for env in envs:
            env.close()
    write_json(out_dir / "side_by_side.json", {"run": str(run_dir), "backends": names, "episodes": records})
    return records
