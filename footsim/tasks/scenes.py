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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.scene import Obstacle, Scene
from footsim.utils import atomic_write_text


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
            if not clear_of_footprint(ball, 0.0, 0.0, self.robot_radius):
                continue  # the robot would start touching the ball
            obstacles = [self._obstacle_near(0.0, 0.0, goal, rng) for _ in range(int(self.n_obstacles_robot))]
            obstacles += [self._obstacle_near(goal.x, goal.y, goal, rng) for _ in range(int(self.n_obstacles_goal))]
            return Scene(goal, tuple(obstacles), ball)

    def _obstacle_near(self, cx: float, cy: float, goal: Pose2D, rng: np.random.Generator) -> Obstacle:
        sigma, normal = self.obstacle_offset_sigma, rng.standard_normal
        while True:
            dx, dy = sigma * normal(), sigma * normal()  # rng.normal(0, sigma, size=2), see sample()
            r = uniform(rng, self.obstacle_radius_min, self.obstacle_radius_max)
            obstacle = Obstacle(cx + dx, cy + dy, r)
            clear_of_start = clear_of_footprint(obstacle, 0.0, 0.0, self.robot_radius)
            if clear_of_start and clear_of_footprint(obstacle, goal.x, goal.y, self.robot_radius):
                return obstacle

    def footprint_overlap(self, scene: Scene) -> str | None:
        """What of ``scene`` breaks the rule :meth:`sample` keeps (an obstacle on the robot's start
        footprint or on the robot standing at the goal, the ball on the start footprint; the ball
        lies at the goal's feet by design), or None."""
        radius = f"(task.scenes.robot_radius={self.robot_radius:g} m)"
        goal = scene.goal
        footprints = (
            ("the robot's start footprint at the origin", 0.0, 0.0),
            (f"the robot's footprint at the goal ({goal.x:g}, {goal.y:g})", goal.x, goal.y),
        )
        for k, obstacle in enumerate(scene.obstacles):
            for footprint, cx, cy in footprints:
                if not clear_of_footprint(obstacle, cx, cy, self.robot_radius):
                    return f"obstacle {k} {_circle_text(obstacle)} overlaps {footprint} {radius}"
        ball = scene.ball
        if ball is not None and not clear_of_footprint(ball, 0.0, 0.0, self.robot_radius):
            return f"the ball {_circle_text(ball)} overlaps {footprints[0][0]} {radius}"
        return None

    def check_scenes(self, scenes: list[Scene], where: str = "") -> None:
        """Refuse a scene the robot cannot start or finish in (:meth:`footprint_overlap`), naming
        the index of the first such scene (after ``where``, e.g. the argument's name)."""
        for i, scene in enumerate(scenes):
            problem = self.footprint_overlap(scene)
            if problem is not None:
                raise ValueError(f"{where}scene {i}: {problem}")


def clear_of_footprint(circle: Obstacle, cx: float, cy: float, robot_radius: float) -> bool:
    """Whether ``circle`` keeps clear of the robot's footprint, a circle of ``robot_radius`` at (cx, cy)."""
    return math.hypot(circle.x - cx, circle.y - cy) >= circle.r + robot_radius


def _circle_text(circle: Obstacle) -> str:
    return f"(x={circle.x:g}, y={circle.y:g}, r={circle.r:g})"


def uniform(rng: np.random.Generator, low: float, high: float) -> float:
    """``float(rng.uniform(low, high))``, the same draw and value (numpy computes
    ``low + (high - low) * rng.random()``) without the array machinery of a scalar call."""
    return low + (high - low) * rng.random()


def sample_scenes(sampler: SceneSampler, n: int, seed: int) -> list[Scene]:
    if n <= 0:
        raise ValueError(f"n must be > 0, got {n}")
    rng = np.random.default_rng(seed)
    return [sampler.sample(rng) for _ in range(n)]


def save_scenes(path: str | os.PathLike, scenes: list[Scene], meta: dict | None = None) -> None:
    payload: dict[str, Any] = {"scenes": [s.to_dict() for s in scenes]}
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
