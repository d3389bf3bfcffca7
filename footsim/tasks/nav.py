"""The footstep navigation task of thesis chapter 5: observation, reward and success.

Small stateless functions (``goal_features``, ``ray_distances``, ``reward_terms``) configured by
a ``NavTaskConfig``; nothing here knows which backend runs.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.scene import Obstacle, Scene, circle_array
from footsim.tasks import rays

WEIGHTS_NO_OBSTACLES = {"distance": 0.3, "angle": 0.3, "orientation": 0.2, "obstacle": 0.0, "continuity": 0.2}
WEIGHTS_OBSTACLES = {"distance": 0.25, "angle": 0.25, "orientation": 0.15, "obstacle": 0.2, "continuity": 0.15}
#: The thesis's five terms plus "stability" (3D option: exp(-max trunk tilt / stability_scale)).
REWARD_TERMS = frozenset(WEIGHTS_NO_OBSTACLES) | {"stability"}


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
    # Options beyond the thesis (off by default; docs/RESULTS.md measures their effect):
    observe_imu: bool = False  # append tanh(roll / imu_scale), tanh(pitch / ·), tanh(max tilt / ·)
    imu_scale: float = 0.35  # [rad]
    stability_scale: float = 0.2  # [rad] reward term "stability" = exp(-max tilt / this)
    path_hint: bool = False  # append sin, cos of the bearing to a point on a global grid path (thesis ch. 9)
    path_hint_lookahead: float = 0.5  # [m] along the path past its point closest to the believed pose
    path_hint_clearance: float = 0.2  # [m] inflation of the obstacles for the path (footprint + margin)
    success_bonus: float = 1.0  # reward per remaining step on success (thesis: 1, the maximum step reward)

    def __post_init__(self) -> None:
        for key in (
            "success_distance",
            "success_angle",
            "distance_scale",
            "ray_range",
            "ray_scale",
            "imu_scale",
            "stability_scale",
            "path_hint_lookahead",
            "path_hint_clearance",
        ):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"task.{key} must be a positive number, got {value!r}")
        if not (math.isfinite(self.success_bonus) and self.success_bonus >= 0):
            raise ValueError(f"task.success_bonus must be >= 0, got {self.success_bonus!r}")
        if int(self.max_steps) <= 0:
            raise ValueError(f"task.max_steps must be > 0, got {self.max_steps!r}")
        if int(self.n_rays) <= 0:
            raise ValueError(f"task.n_rays must be > 0, got {self.n_rays!r}")
        unknown = set(self.reward_weights) - REWARD_TERMS
        if unknown:
            raise ValueError(f"task.reward_weights: unknown term(s) {sorted(unknown)}; valid: {sorted(REWARD_TERMS)}")
        for key, value in self.reward_weights.items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"task.reward_weights.{key} must be >= 0, got {value!r}")
        # Derived once (the config is frozen; the env asks every step): whether the observation or
        # the reward needs the backend's trunk tilt, and the ray block's directions and miss value.
        object.__setattr__(self, "uses_tilt", bool(self.observe_imu or self.reward_weights.get("stability", 0.0) > 0.0))
        object.__setattr__(self, "ray_directions", _ray_directions(int(self.n_rays)))
        object.__setattr__(self, "ray_miss", float(np.tanh(self.ray_range / self.ray_scale)))  # a ray hitting nothing

    @property
    def observation_size(self) -> int:
        return sum(size for _, size in self.observation_layout)

    @property
    def observation_layout(self) -> tuple[tuple[str, int], ...]:
        """The observation's blocks in order: a run whose layout is a prefix of another's can
        seed it (``init_from`` gives the extra inputs zero weights)."""
        return observation_layout(self.obstacles, int(self.n_rays), self.observe_imu, self.path_hint)


def goal_features(pose: Pose2D, goal: Pose2D) -> tuple[float, float, float]:
    """Distance d, goal-orientation error α and bearing β (thesis Fig. 5.3), all from ``pose``.

    α: how far the robot must turn to take the goal's heading; β: how far to face the goal.
    """
    px, py, pt = pose
    gx, gy, gt = goal
    dx, dy = gx - px, gy - py
    d = math.hypot(dx, dy)
    # alpha = wrap_angle(gt - pt), beta = wrap_angle(atan2(dy, dx) - pt), the wraps inlined
    alpha = _fmod(gt - pt + _PI, _TWO_PI)
    if alpha <= 0.0:
        alpha += _TWO_PI
    alpha -= _PI
    if d > 0.0:
        beta = _fmod(math.atan2(dy, dx) - pt + _PI, _TWO_PI)
        if beta <= 0.0:
            beta += _TWO_PI
        beta -= _PI
    else:
        beta = 0.0
    return d, alpha, beta


_PI, _TWO_PI, _fmod = math.pi, 2.0 * math.pi, math.fmod
_pack_floats = struct.Struct("=17f").pack_into  # 17 floats into a float32 buffer


_RAY_DIRECTIONS: dict[int, np.ndarray] = {}


def observation_layout(
    obstacles: bool, n_rays: int, observe_imu: bool = False, path_hint: bool = False
) -> tuple[tuple[str, int], ...]:
    """``(block, size)`` in observation order (see :func:`observation`)."""
    blocks = [("goal_and_actions", 17)]
    if obstacles:
        blocks.append(("rays", n_rays))
    if observe_imu:
        blocks.append(("imu", 3))
    if path_hint:
        blocks.append(("path_hint", 2))
    return tuple(blocks)


def _ray_directions(n_rays: int) -> np.ndarray:
    """cos and sin of the ray headings ``k·2π/n`` in the robot frame, ``(2, n)`` (cached per n)."""
    base = _RAY_DIRECTIONS.get(n_rays)
    if base is None:
        base = _RAY_DIRECTIONS[n_rays] = rays.ray_directions(n_rays)
    return base


def scene_arrays(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """``scene.circles`` (obstacles and ball) and ``scene.obstacle_circles`` (no ball) as float64
    ``(n, 3)`` arrays for the compiled kernels (:mod:`footsim.tasks.rays`).

    Views of the scene's cached :attr:`Scene.circle_array`; the env takes them once per episode
    and passes them to :func:`observation` and :func:`reward_terms`.
    """
    circles = scene.circle_array
    return circles, circles[: len(scene.obstacles)]  # the ball, if any, is the last row


def ray_distances(pose: Pose2D, obstacles: tuple[Obstacle, ...], n_rays: int, max_range: float) -> np.ndarray:
    """Distance along each of ``n_rays`` evenly spaced rays from ``pose`` to the first circle hit.

    Ray k points at heading ``pose.theta + k·2π/n``; misses report ``max_range``; an origin inside
    a circle reports 0.  (Compiled: :func:`footsim.tasks.rays.scan_rays`.)
    """
    out = np.empty(int(n_rays))
    circles = circle_array([(o.x, o.y, o.r) for o in obstacles])
    rays.scan_rays(
        float(pose[0]), float(pose[1]), float(pose[2]), circles, _ray_directions(int(n_rays)), float(max_range), out
    )
    return out


def nearest_obstacle_distance(pose: Pose2D, obstacles: tuple[Obstacle, ...]) -> float:
    """Distance from the robot centre to the nearest obstacle surface (inf without obstacles)."""
    return _nearest_circle_distance(pose, tuple((o.x, o.y, o.r) for o in obstacles))


def _nearest_circle_distance(
    pose: Pose2D, circles: tuple[tuple[float, float, float], ...], array: np.ndarray | None = None
) -> float:
    """Distance from ``pose`` to the nearest edge of ``circles`` (``array``: the same circles as
    :func:`footsim.circle_array`); inf without circles.  The kernel picks the circle,
    ``math.hypot`` gives the distance (the C library's ``hypot`` can differ in the last bit)."""
    px, py = pose[0], pose[1]
    k = rays.nearest_circle(px, py, circle_array(circles) if array is None else array)
    if k < 0:
        return math.inf
    ox, oy, r = circles[k]
    return math.hypot(ox - px, oy - py) - r


def reward_terms(
    pose: Pose2D,
    scene: Scene,
    action,
    previous_action,
    features: tuple[float, float, float] | None = None,
    max_tilt: float | None = None,
    stability_scale: float = 0.2,
    arrays: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict[str, float]:
    """The five thesis 5.5 reward terms, each in [0, 1]; with ``max_tilt`` (the largest trunk
    roll or pitch during the step, 3D) also ``stability = exp(-max_tilt / stability_scale)``.

    The ball is excluded from the obstacle term (it would create a local minimum before the goal).
    ``features`` may pass ``goal_features(pose, scene.goal)`` already computed by the caller,
    ``arrays`` the episode's :func:`scene_arrays`; the actions may be arrays or lists of 6 floats.
    """
    d, alpha, beta = features if features is not None else goal_features(pose, scene.goal)
    d_obs = math.inf
    if scene.obstacles:
        d_obs = _nearest_circle_distance(pose, scene.obstacle_circles, None if arrays is None else arrays[1])
    if d_obs == math.inf:
        r_obs = 1.0
    else:
        d_obs = max(d_obs, 1e-6)
        r_obs = math.exp(-0.0015 * (1.0 / d_obs) ** 2)
    terms = {
        "distance": math.exp(-0.5 * d),
        "angle": math.exp(-5.0 * d) * math.exp(-abs(alpha)),
        "orientation": 1.0 if d < 0.1 else math.exp(-abs(beta)),
        "obstacle": r_obs,
        "continuity": _continuity(action, previous_action),
    }
    if max_tilt is not None:
        terms["stability"] = math.exp(-abs(max_tilt) / stability_scale)
    return terms


def _continuity(action, previous_action) -> float:
    """mean(exp(-3 |a(t) - a(t-1)|)) over the action components (plain floats: this is hot)."""
    a = action.tolist() if isinstance(action, np.ndarray) else action
    b = previous_action.tolist() if isinstance(previous_action, np.ndarray) else previous_action
    exp = math.exp
    if len(a) == 6 and len(b) == 6:  # the env's case, unrolled: the same sum, left to right
        a0, a1, a2, a3, a4, a5 = a
        b0, b1, b2, b3, b4, b5 = b
        return (
            exp(-3.0 * abs(a0 - b0))
            + exp(-3.0 * abs(a1 - b1))
            + exp(-3.0 * abs(a2 - b2))
            + exp(-3.0 * abs(a3 - b3))
            + exp(-3.0 * abs(a4 - b4))
            + exp(-3.0 * abs(a5 - b5))
        ) / 6
    total = 0
    for x, y in zip(a, b):
        total += exp(-3.0 * abs(x - y))
    return total / len(a)


def weighted_reward(terms: dict[str, float], weights: dict[str, float]) -> float:
    get = weights.get
    total = 0  # the same left-to-right sum as sum(...): bit-identical rewards
    for k, v in terms.items():
        total += get(k, 0.0) * v
    return float(total)


def is_success(
    pose: Pose2D, goal: Pose2D, config: NavTaskConfig, features: tuple[float, float, float] | None = None
) -> bool:
    d, alpha, _ = features if features is not None else goal_features(pose, goal)
    return d < config.success_distance and abs(alpha) < config.success_angle


def observation(
    believed: Pose2D,
    scene: Scene,
    previous_actions,
    config: NavTaskConfig,
    features: tuple[float, float, float] | None = None,
    tilt: tuple[float, float, float] = (0.0, 0.0, 0.0),
    hint: tuple[float, float] = (0.0, 1.0),
    arrays: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """17-D (or 53-D with rays) observation from the pose the robot *believes* it has.

    Layout: [tanh(d), sin α, cos α, sin β, cos β, a(t−1) (6), a(t−2) (6), tanh(rays) (36)], and
    with ``config.observe_imu`` then tanh(· / imu_scale) of ``tilt`` = (roll, pitch, max tilt), and
    with ``config.path_hint`` then ``hint`` = (sin, cos) of the bearing to the path's lookahead
    point (:class:`PathHint`).
    ``previous_actions`` holds a(t−1) and a(t−2), each an array or a list of 6 floats; ``arrays``
    may pass the episode's :func:`scene_arrays`.
    """
    d, alpha, beta = features if features is not None else goal_features(believed, scene.goal)
    a1, a2 = previous_actions
    head = (math.tanh(d / config.distance_scale), math.sin(alpha), math.cos(alpha), math.sin(beta), math.cos(beta))
    options = []
    if config.observe_imu:
        scale = config.imu_scale
        options += [math.tanh(tilt[0] / scale), math.tanh(tilt[1] / scale), math.tanh(tilt[2] / scale)]
    if config.path_hint:
        options += [hint[0], hint[1]]
    if not config.obstacles:
        return np.array([*head, *a1, *a2, *options], dtype=np.float32)
    # The ray block goes between the actions and the options: one compiled call (footsim.tasks.rays)
    # writes it into the observation.
    directions = config.ray_directions
    n = directions.shape[1]
    obs = np.empty(17 + n + len(options), dtype=np.float32)
    _pack_floats(obs, 0, *head, *a1, *a2)  # = obs[:17] = values (the same float32 rounding), a third of the cost
    circles = (arrays if arrays is not None else scene_arrays(scene))[0]
    rays.ray_observation(
        believed[0],
        believed[1],
        believed[2],
        circles,
        directions,
        config.ray_range,
        config.ray_scale,
        config.ray_miss,
        obs,
        17,
    )
    if options:
        obs[17 + n :] = options
    return obs


class PathHint:
    """A global path from the start to the goal around the scene's obstacles (ball included),
    planned once per episode (Theta* on a costmap inflated by ``path_hint_clearance``; a straight
    line when no path exists), and the bearing from a pose to the point ``path_hint_lookahead``
    metres along it past the path point closest to that pose (never moving back along the path).
    """

    def __init__(self, scene: Scene, start: Pose2D, config: NavTaskConfig):
        from footsim.planners.grid import Costmap, densify, plan_path

        self.lookahead = float(config.path_hint_lookahead)
        goal = (scene.goal.x, scene.goal.y)
        points = np.array([[start.x, start.y], goal], dtype=float)
        obstacles = scene.all_obstacles
        if obstacles:
            costmap = Costmap.from_obstacles(
                obstacles, [(start.x, start.y), goal], 0.05, float(config.path_hint_clearance)
            )
            path = plan_path(costmap, (start.x, start.y), goal, "theta_star")
            if path is not None:
                points = path.points
        self.spacing = 0.05
        self.points = densify(points, self.spacing)
        self.index = 0

    def bearing(self, pose: Pose2D) -> tuple[float, float]:
        """(sin, cos) of the lookahead point's bearing relative to the pose's heading."""
        pts = self.points[self.index :]
        self.index += int(np.argmin(np.hypot(pts[:, 0] - pose.x, pts[:, 1] - pose.y)))
        k = min(self.index + int(round(self.lookahead / self.spacing)), len(self.points) - 1)
        dx, dy = self.points[k, 0] - pose.x, self.points[k, 1] - pose.y
        if dx * dx + dy * dy < 1e-12:  # at the goal: point along the goal's heading
            return 0.0, 1.0
        angle = wrap_angle(math.atan2(dy, dx) - pose.theta)
        return math.sin(angle), math.cos(angle)
