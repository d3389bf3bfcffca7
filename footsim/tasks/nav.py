"""The footstep navigation task of thesis chapter 5: observation, reward and success.

Small stateless functions (``goal_features``, ``ray_distances``, ``reward_terms``) configured by
a ``NavTaskConfig``; nothing here knows which backend runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.tasks.scenes import Obstacle, Scene

#: Thesis 5.5 weight sets (each sums to 1).
WEIGHTS_NO_OBSTACLES = {"distance": 0.3, "angle": 0.3, "orientation": 0.2, "obstacle": 0.0, "continuity": 0.2}
WEIGHTS_OBSTACLES = {"distance": 0.25, "angle": 0.25, "orientation": 0.15, "obstacle": 0.2, "continuity": 0.15}


@dataclass(frozen=True)
class NavTaskConfig:
    obstacles: bool = False
    max_steps: int = 100
    success_distance: float = 0.05  # [m]
    success_angle: float = math.radians(10.0)  # [rad]
    distance_scale: float = 1.0  # observation: tanh(d / distance_scale)
    n_rays: int = 36  # 10° apart
    ray_range: float = 5.0  # a ray that hits nothing reports this [m]
    ray_scale: float = 1.0  # observation: tanh(ray / ray_scale)
    reward_weights: dict = field(default_factory=lambda: dict(WEIGHTS_NO_OBSTACLES))

    def __post_init__(self) -> None:
        for key in ("success_distance", "success_angle", "distance_scale", "ray_range", "ray_scale"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"task.{key} must be a positive number, got {value!r}")
        if int(self.max_steps) <= 0:
            raise ValueError(f"task.max_steps must be > 0, got {self.max_steps!r}")
        if int(self.n_rays) <= 0:
            raise ValueError(f"task.n_rays must be > 0, got {self.n_rays!r}")
        unknown = set(self.reward_weights) - set(WEIGHTS_NO_OBSTACLES)
        if unknown:
            raise ValueError(f"task.reward_weights: unknown term(s) {sorted(unknown)}; valid: {sorted(WEIGHTS_NO_OBSTACLES)}")
        for key, value in self.reward_weights.items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"task.reward_weights.{key} must be >= 0, got {value!r}")

    @property
    def observation_size(self) -> int:
        return 17 + (int(self.n_rays) if self.obstacles else 0)


def goal_features(pose: Pose2D, goal: Pose2D) -> tuple[float, float, float]:
    """Distance d, goal-orientation error α and bearing β (thesis Fig. 5.3), all from ``pose``.

    α: how far the robot must turn to take the goal's heading; β: how far to face the goal.
    """
    dx, dy = goal.x - pose.x, goal.y - pose.y
    d = math.hypot(dx, dy)
    alpha = wrap_angle(goal.theta - pose.theta)
    beta = wrap_angle(math.atan2(dy, dx) - pose.theta) if d > 0.0 else 0.0
    return d, alpha, beta


_RAY_DIRECTIONS: dict[int, np.ndarray] = {}


def ray_distances(pose: Pose2D, obstacles: tuple[Obstacle, ...], n_rays: int, max_range: float) -> np.ndarray:
    """Distance along each of ``n_rays`` evenly spaced rays from ``pose`` to the first circle hit.

    Ray k points at heading ``pose.theta + k·2π/n``; misses report ``max_range``; an origin inside
    a circle reports 0.
    """
    if not obstacles:
        return np.full(n_rays, max_range)
    base = _RAY_DIRECTIONS.get(n_rays)
    if base is None:
        k = np.arange(n_rays) * (2.0 * math.pi / n_rays)
        base = _RAY_DIRECTIONS[n_rays] = np.stack([np.cos(k), np.sin(k)])  # (2, n)
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    # Obstacle centres in the robot frame, so the ray directions need no rotation.
    rel = np.array([[c * (o.x - pose.x) + s * (o.y - pose.y), -s * (o.x - pose.x) + c * (o.y - pose.y),
                     (o.x - pose.x) ** 2 + (o.y - pose.y) ** 2 - o.r * o.r] for o in obstacles])  # (m, 3)
    # |t·u − c|² = r²  →  t = u·c − sqrt((u·c)² − (|c|² − r²))
    proj = rel[:, :2] @ base  # (m, n)
    disc = proj * proj - rel[:, 2:3]
    inside = rel[:, 2:3] <= 0.0
    t = proj - np.sqrt(np.maximum(disc, 0.0))
    t = np.where(inside, 0.0, np.where((disc >= 0.0) & (t >= 0.0), t, max_range))
    return np.minimum(t.min(axis=0), max_range)


def nearest_obstacle_distance(pose: Pose2D, obstacles: tuple[Obstacle, ...]) -> float:
    """Distance from the robot centre to the nearest obstacle surface (inf without obstacles)."""
    best = math.inf
    for o in obstacles:
        best = min(best, math.hypot(o.x - pose.x, o.y - pose.y) - o.r)
    return best


def reward_terms(pose: Pose2D, scene: Scene, action: np.ndarray, previous_action: np.ndarray,
                 features: tuple[float, float, float] | None = None) -> dict[str, float]:
    """The five thesis 5.5 reward terms, each in [0, 1].

    The ball is excluded from the obstacle term (it would create a local minimum before the goal).
    ``features`` may pass ``goal_features(pose, scene.goal)`` already computed by the caller.
    """
    d, alpha, beta = features if features is not None else goal_features(pose, scene.goal)
    d_obs = nearest_obstacle_distance(pose, scene.obstacles)
    if math.isinf(d_obs):
        r_obs = 1.0
    else:
        d_obs = max(d_obs, 1e-6)
        r_obs = math.exp(-0.0015 * (1.0 / d_obs) ** 2)
    return {
        "distance": math.exp(-0.5 * d),
        "angle": math.exp(-5.0 * d) * math.exp(-abs(alpha)),
        "orientation": 1.0 if d < 0.1 else math.exp(-abs(beta)),
        "obstacle": r_obs,
        "continuity": _continuity(action, previous_action),
    }


def _continuity(action, previous_action) -> float:
    """mean(exp(-3 |a(t) - a(t-1)|)) over the action components (plain floats: this is hot)."""
    a = action.tolist() if isinstance(action, np.ndarray) else list(action)
    b = previous_action.tolist() if isinstance(previous_action, np.ndarray) else list(previous_action)
    return sum(math.exp(-3.0 * abs(x - y)) for x, y in zip(a, b)) / len(a)


def weighted_reward(terms: dict[str, float], weights: dict[str, float]) -> float:
    return float(sum(weights.get(k, 0.0) * v for k, v in terms.items()))


def is_success(pose: Pose2D, goal: Pose2D, config: NavTaskConfig,
               features: tuple[float, float, float] | None = None) -> bool:
    d, alpha, _ = features if features is not None else goal_features(pose, goal)
    return d < config.success_distance and abs(alpha) < config.success_angle


def observation(
    believed: Pose2D, scene: Scene, previous_actions: tuple[np.ndarray, np.ndarray], config: NavTaskConfig,
    features: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """17-D (or 53-D with rays) observation from the pose the robot *believes* it has.

    Layout: [tanh(d), sin α, cos α, sin β, cos β, a(t−1) (6), a(t−2) (6), tanh(rays) (36)].
    """
    d, alpha, beta = features if features is not None else goal_features(believed, scene.goal)
    head = [math.tanh(d / config.distance_scale), math.sin(alpha), math.cos(alpha), math.sin(beta), math.cos(beta)]
    values = head + previous_actions[0].tolist() + previous_actions[1].tolist()
    if config.obstacles:
        rays = ray_distances(believed, scene.all_obstacles, int(config.n_rays), config.ray_range)
        values += np.tanh(rays / config.ray_scale).tolist()
    return np.array(values, dtype=np.float32)
