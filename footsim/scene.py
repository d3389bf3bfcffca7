"""The world a task poses and a backend builds: the goal pose, obstacle circles and the ball.

Plain data below both ``footsim.tasks`` (which samples and scores scenes) and ``footsim.backends``
(which place them in a simulator), so neither layer imports the other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from footsim.geometry import Pose2D


def circle_array(circles) -> np.ndarray:
    """``(x, y, r)`` triples (e.g. ``Scene.circles``) as a C-contiguous float64 ``(n, 3)`` array."""
    return np.ascontiguousarray(np.asarray(circles, dtype=np.float64).reshape(-1, 3))


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
            object.__setattr__(self, "goal", Pose2D.of(*finite_list(self.goal, 3, "Scene.goal")))
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
        (:func:`circle_array`), built once per scene and shared by the backend and
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
            goal = finite_list(data["goal"], 3, f"{where}: 'goal'")
            obstacles = tuple(
                Obstacle(*_circle(o, f"{where}: obstacle {k}")) for k, o in enumerate(data.get("obstacles") or [])
            )
            ball_raw = data.get("ball")
            ball = None if ball_raw is None else Obstacle(*_circle(ball_raw, f"{where}: 'ball'"))
        except KeyError as err:
            raise ValueError(f"{where}: missing key {err}") from None
        return cls(Pose2D.of(*goal), obstacles, ball)


def finite_list(value, n: int, what: str) -> list[float]:
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
    x, y, r = finite_list(value, 3, what)
    if r <= 0:
        raise ValueError(f"{what}: radius must be > 0, got {r}")
    return [x, y, r]
