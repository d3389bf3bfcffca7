"""Scenes: a goal pose, obstacles and the ball, sampled as in thesis 5.1, and scene files.

Scene file format (JSON)::

    {"scenes": [{"goal": [x, y, theta],
                 "obstacles": [[x, y, r], ...],
                 "ball": [x, y, r] or null}, ...]}

The robot always starts at the origin facing +x.  ``footsim-scenes out=FILE n=500 seed=S
obstacles=true|false`` writes such a file; ``footsim-eval scenes=FILE`` reads it.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.kernels2d import circle_array


class Obstacle(NamedTuple):
    """A circle: an obstacle or the ball (a named tuple: a scene draws seven of them per reset)."""

    x: float
    y: float
    r: float


@dataclass(frozen=True)
class Scene:
    goal: Pose2D
    obstacles: tuple[Obstacle, ...] = ()
    ball: Obstacle | None = None

    def __post_init__(self) -> None:
        # Plain (x, y, θ) / (x, y, r) sequences from user code become Pose2D / Obstacle here, with
        # a clear error if malformed; the sampler's and the loader's scenes pass through as they are.
        if not isinstance(self.goal, Pose2D):
            object.__setattr__(self, "goal", Pose2D.of(*_finite_list(self.goal, 3, "Scene.goal")))
        if type(self.obstacles) is not tuple or not all(type(o) is Obstacle for o in self.obstacles):
            object.__setattr__(
                self,
                "obstacles",
                tuple(
                    o if type(o) is Obstacle else Obstacle(*_circle(o, f"Scene.obstacles[{k}]"))
                    for k, o in enumerate(self.obstacles)
                ),
            )
        if self.ball is not None and type(self.ball) is not Obstacle:
            object.__setattr__(self, "ball", Obstacle(*_circle(self.ball, "Scene.ball")))

    @cached_property
    def all_obstacles(self) -> tuple[Obstacle, ...]:
        """Obstacles and the ball: everything a ray or a foot can hit."""
        return self.obstacles + ((self.ball,) if self.ball is not None else ())

    # ``(x, y, r)`` tuples for the per-step hot paths: an ``Obstacle`` is one already.
    @property
    def circles(self) -> tuple[tuple[float, float, float], ...]:
        """``all_obstacles`` as ``(x, y, r)`` tuples."""
        return self.all_obstacles

    @property
    def obstacle_circles(self) -> tuple[tuple[float, float, float], ...]:
        """``obstacles`` (without the ball) as ``(x, y, r)`` tuples."""
        return self.obstacles

    @cached_property
    def circle_array(self) -> np.ndarray:
        """``circles`` as the float64 ``(n, 3)`` array the compiled kernels take
        (:func:`footsim.kernels2d.circle_array`), built once per scene and shared by the backend and
        the task; the obstacles are the first ``len(obstacles)`` rows, the ball the last."""
        return circle_array(self.circles)

    def to_dict(self) -> dict:
        return {
            "goal": [self.goal.x, self.goal.y, self.goal.theta],
            "obstacles": [[o.x, o.y, o.r] for o in self.obstacles],
            "ball": None if self.ball is None else [self.ball.x, self.ball.y, self.ball.r],
        }

    @classmethod
    def from_dict(cls, data: dict, index: int = 0) -> Scene:
        where = f"scene {index}"
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected an object with 'goal', 'obstacles', 'ball', got {type(data).__name__}")
        try:
            goal = _finite_list(data["goal"], 3, f"{where}: 'goal'")
            obstacles = tuple(
                Obstacle(*_circle(o, f"{where}: obstacle {k}")) for k, o in enumerate(data.get("obstacles") or [])
            )
            ball_raw = data.get("ball")
            ball = None if ball_raw is None else Obstacle(*_circle(ball_raw, f"{where}: 'ball'"))
        except KeyError as err:
            raise ValueError(f"{where}: missing key {err}") from None
        return cls(Pose2D.of(*goal), obstacles, ball)


def _finite_list(value, n: int, what: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ValueError(f"{what} must be a list of {n} numbers, got {value!r}")
    try:
        out = [float(v) for v in value]
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a list of {n} numbers, got {value!r}") from None
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{what} contains NaN or inf: {value!r}")
    return out


def _circle(value, what: str) -> list[float]:
    x, y, r = _finite_list(value, 3, what)
    if r <= 0:
        raise ValueError(f"{what}: radius must be > 0, got {r}")
    return [x, y, r]


@dataclass(frozen=True)
class SceneSampler:
    """Thesis 5.1 goal and obstacle distribution.

    The ball (a RoboCup KidSize ball, radius ``ball_radius``) sits ``ball_offset`` in front of
    the goal pose, where the robot would kick it.  An obstacle is resampled while it overlaps
    the robot's start footprint or the robot standing at the goal (both modelled as a circle of
    ``robot_radius``); a scene whose ball overlaps the start footprint is redrawn whole.
    """

    obstacles: bool = False
    goal_sigma_xy: float = 1.0
    goal_sigma_theta: float = 1.5
    n_obstacles_robot: int = 3
    n_obstacles_goal: int = 3
    obstacle_offset_sigma: float = 0.5
    obstacle_radius_min: float = 0.1
    obstacle_radius_max: float = 0.3
    ball_radius: float = 0.075
    ball_offset: float = 0.2
    robot_radius: float = 0.2

    def __post_init__(self) -> None:
        positive = (
            "goal_sigma_xy",
            "goal_sigma_theta",
            "obstacle_offset_sigma",
            "obstacle_radius_min",
            "obstacle_radius_max",
            "ball_radius",
            "robot_radius",
        )
        for key in positive:
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"task.scenes.{key} must be a positive number, got {value!r}")
        for key in ("n_obstacles_robot", "n_obstacles_goal"):
            if int(getattr(self, key)) < 0:
                raise ValueError(f"task.scenes.{key} must be >= 0, got {getattr(self, key)!r}")
        if self.obstacle_radius_max < self.obstacle_radius_min:
            raise ValueError("task.scenes.obstacle_radius_max must be >= task.scenes.obstacle_radius_min")
        if self.ball_offset < 0:
            raise ValueError(f"task.scenes.ball_offset must be >= 0, got {self.ball_offset!r}")

    def sample(self, rng: np.random.Generator) -> Scene:
        # sigma * standard_normal() is rng.normal(0, sigma)'s draw and value (numpy computes
        # loc + scale * z) without the array machinery; a scene is ~15 such draws.
        normal = rng.standard_normal
        while True:
            sigma = self.goal_sigma_xy
            gx, gy = sigma * normal(), sigma * normal()
            goal = Pose2D(gx, gy, wrap_angle(self.goal_sigma_theta * normal()))
            if not self.obstacles:
                return Scene(goal)
            ball = Obstacle(*goal.transform_point(self.ball_offset, 0.0), self.ball_radius)
            if math.hypot(ball.x, ball.y) < ball.r + self.robot_radius:
                continue  # the robot would start touching the ball
            obstacles = [self._obstacle_near(0.0, 0.0, goal, rng) for _ in range(int(self.n_obstacles_robot))]
            obstacles += [self._obstacle_near(goal.x, goal.y, goal, rng) for _ in range(int(self.n_obstacles_goal))]
            return Scene(goal, tuple(obstacles), ball)

    def _obstacle_near(self, cx: float, cy: float, goal: Pose2D, rng: np.random.Generator) -> Obstacle:
        sigma, normal = self.obstacle_offset_sigma, rng.standard_normal
        while True:
            dx, dy = sigma * normal(), sigma * normal()  # rng.normal(0, sigma, size=2), see sample()
            r = uniform(rng, self.obstacle_radius_min, self.obstacle_radius_max)
            x, y = cx + dx, cy + dy
            clear_of_start = math.hypot(x, y) >= r + self.robot_radius
            clear_of_goal = math.hypot(x - goal.x, y - goal.y) >= r + self.robot_radius
            if clear_of_start and clear_of_goal:
                return Obstacle(x, y, r)


def uniform(rng: np.random.Generator, low: float, high: float) -> float:
    """``float(rng.uniform(low, high))``, the same draw and value (numpy computes
    ``low + (high - low) * rng.random()``) without the array machinery of a scalar call."""
    return low + (high - low) * rng.random()


def sample_scenes(sampler: SceneSampler, n: int, seed: int) -> list[Scene]:
    if n <= 0:
        raise ValueError(f"n must be > 0, got {n}")
    rng = np.random.default_rng(seed)
    return [sampler.sample(rng) for _ in range(n)]


def _default_file_mode() -> int:
    """What ``open()`` would give a new file under the current umask (``mkstemp`` gives 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_save(save: Callable[[str], None], path: str | os.PathLike, suffix: str = ".tmp") -> None:
    """Let ``save`` write a temporary file beside ``path``, then move it into place: a crash
    leaves either the old or the new file, never a half one.  The file gets the usual
    permissions (umask), not ``mkstemp``'s owner-only ones."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    try:
        save(tmp)
        os.chmod(tmp, _default_file_mode())
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """``text`` into ``path`` atomically (``atomic_save``), synced to disk before the move."""

    def save(tmp: str) -> None:
        with open(tmp, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())

    atomic_save(save, path)


def save_scenes(path: str | os.PathLike, scenes: list[Scene], meta: dict | None = None) -> None:
    payload = {"scenes": [s.to_dict() for s in scenes]}
    if meta:
        payload["meta"] = meta
    atomic_write_text(path, json.dumps(payload, indent=1))


def load_scenes(path: str | os.PathLike) -> list[Scene]:
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"scene file not found: {path}") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"scene file {path} is not valid JSON: {err}") from None
    if not isinstance(data, dict) or not isinstance(data.get("scenes"), list):
        raise ValueError(f"scene file {path} must be a JSON object with a list under 'scenes'")
    if not data["scenes"]:
        raise ValueError(f"scene file {path} holds no scenes")
    return [Scene.from_dict(s, i) for i, s in enumerate(data["scenes"])]


def parse_kv_args(argv: list[str], allowed: dict[str, object], command: str) -> dict:
    """Parse ``key=value`` arguments (the Hydra-like style of every footsim command)."""
    out = dict(allowed)
    for arg in argv:
        if "=" not in arg:
            raise SystemExit(f"{command}: expected key=value, got {arg!r}; keys: {sorted(allowed)}")
        key, value = arg.split("=", 1)
        if key not in allowed:
            raise SystemExit(f"{command}: unknown key {key!r}; keys: {sorted(allowed)}")
        out[key] = value
    return out


def main(argv: list[str] | None = None) -> None:
    """``footsim-scenes out=FILE n=500 seed=S obstacles=true|false``."""
    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {"out": None, "n": "500", "seed": "0", "obstacles": "false"},
        "footsim-scenes",
    )
    if not args["out"]:
        raise SystemExit("footsim-scenes: out=FILE is required")
    try:
        n, seed = int(args["n"]), int(args["seed"])
    except ValueError:
        raise SystemExit(f"footsim-scenes: n and seed must be integers, got n={args['n']!r} seed={args['seed']!r}")
    if n <= 0:
        raise SystemExit(f"footsim-scenes: n must be > 0, got {n}")
    flag = str(args["obstacles"]).lower()
    if flag not in ("true", "false"):
        raise SystemExit(f"footsim-scenes: obstacles must be true or false, got {args['obstacles']!r}")
    scenes = sample_scenes(SceneSampler(obstacles=flag == "true"), n, seed)
    save_scenes(args["out"], scenes, meta={"n": n, "seed": seed, "obstacles": flag == "true"})
    print(f"wrote {n} scenes to {args['out']}")
