"""The footstep navigation task of thesis chapter 5: observation, reward terms and termination.

:class:`NavTask` owns the episode: from the truth the backend reports (``StepResult``) it decides
the reward (a table of terms, :mod:`footsim.tasks.terms`) and the outcome (a table of termination
terms in priority order), and it builds the observation.  Small stateless functions
(``goal_features``, ``ray_distances``, the terms) configured by a ``NavTaskConfig``; nothing here
knows which backend runs.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Any

import numpy as np

from footsim.geometry import Pose2D, wrap_angle
from footsim.planners.grid import Costmap, densify, plan_path
from footsim.scene import Obstacle, Scene, circle_array
from footsim.tasks import rays
from footsim.tasks.terms import (
    RewardTerm,
    StepContext,
    TerminationTerm,
    reward_table,
    reward_term,
    termination_table,
    termination_term,
)
from footsim.utils import check_count

#: The thesis 5.5 reward without obstacles (conf/task/nav.yaml), and the 3D options "stability"
#: (exp(-max trunk tilt / scale)) and "contact" (1 without an obstacle contact), weight 0 = off;
#: the order is the order of the weighted sum.
DEFAULT_REWARD: dict[str, dict[str, Any]] = {
    "distance": {"weight": 0.3},
    "angle": {"weight": 0.3},
    "orientation": {"weight": 0.2},
    "obstacle": {"weight": 0.0},
    "continuity": {"weight": 0.2},
    "stability": {"weight": 0.0, "params": {"scale": 0.2}},
    "contact": {"weight": 0.0},
}
#: Outcomes that end an episode, highest priority first; a step that ends none of them and
#: reaches ``max_steps`` is truncated with outcome "timeout".
DEFAULT_TERMINATIONS = {"sim_error": None, "fall": None, "collision": None, "success": None}
OUTCOMES = ("running", "success", "timeout", "fall", "collision", "sim_error")


#: [rad] Default fall threshold: fused roll or pitch beyond it is a fall (thesis 5.1.2).
FALL_THRESHOLD = 0.7


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
    reward: dict = field(default_factory=lambda: {k: dict(v) for k, v in DEFAULT_REWARD.items()})
    terminations: dict = field(default_factory=lambda: dict(DEFAULT_TERMINATIONS))
    fall_threshold: float = (
        FALL_THRESHOLD  # [rad] the step's largest trunk roll or pitch beyond this is a fall (thesis 5.1.2)
    )
    #: whether touching an obstacle ends the episode; None: by backend kind (2D yes, as in the
    #: thesis; 3D no, the contact is reported in ``info``), resolved by :class:`NavTask`
    collision_ends_episode: bool | None = None
    # Options beyond the thesis (off by default; measured on FootstepNav-v0, git show 94a1e0b:docs/RESULTS.md):
    observe_imu: bool = False  # append tanh(roll / imu_scale), tanh(pitch / ·), tanh(max tilt / ·)
    imu_scale: float = 0.35  # [rad]
    path_hint: bool = False  # append sin, cos of the bearing to a point on a global grid path (thesis ch. 9)
    path_hint_lookahead: float = 0.5  # [m] along the path past its point closest to the believed pose
    path_hint_clearance: float = 0.2  # [m] inflation of the obstacles for the path (footprint + margin)
    #: append the goal features and rays of this many earlier observations, newest first (the
    #: episode's first observation stands in for those before it): with the thesis's noise, fresh
    #: each step, the policy can average measurements of the same goal and obstacles
    observe_history: int = 0
    #: walk this many double steps in place at the start of each episode, whatever the actions: the
    #: robot starts from standing into a steady walk before it takes the policy's steps (a 3D step
    #: from standing falls on more of the action box than one from a steady walk: docs/capability/)
    start_in_place: int = 0
    #: those first double steps execute the policy's action times this instead of in place (0): a
    #: start into the box the walk check requires from standing (0.4 of the step limits) can still
    #: step away from an obstacle the walk's sway in place would touch
    start_step_scale: float = 0.0
    #: reward per remaining step on success; None: the maximum step reward, the sum of the reward
    #: weights (the thesis's 1): with a term added beside the thesis's five, a smaller bonus would
    #: make waiting pay more than arriving
    success_bonus: float | None = None
    # Derived in __post_init__ (not constructor arguments):
    uses_tilt: bool = field(init=False, repr=False, compare=False)
    reward_terms: tuple[RewardTerm, ...] = field(init=False, repr=False, compare=False)
    termination_terms: tuple[TerminationTerm, ...] = field(init=False, repr=False, compare=False)
    ray_directions: np.ndarray = field(init=False, repr=False, compare=False)
    ray_miss: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for key in (
            "success_distance",
            "success_angle",
            "distance_scale",
            "ray_range",
            "ray_scale",
            "imu_scale",
            "path_hint_lookahead",
            "path_hint_clearance",
        ):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"task.{key} must be a positive number, got {value!r}")
        check_count("task.max_steps", self.max_steps, least=1)
        check_count("task.n_rays", self.n_rays, least=1)
        check_count("task.observe_history", self.observe_history)
        check_count("task.start_in_place", self.start_in_place, below=("task.max_steps", int(self.max_steps)))
        if not 0.0 <= self.start_step_scale <= 1.0:
            raise ValueError(f"task.start_step_scale must be in [0, 1], got {self.start_step_scale!r}")
        if not 0.0 < self.fall_threshold < math.pi / 2:
            raise ValueError(f"task.fall_threshold must be in (0, pi/2) rad, got {self.fall_threshold!r}")
        if not (self.collision_ends_episode is None or isinstance(self.collision_ends_episode, bool)):
            raise ValueError(
                f"task.collision_ends_episode must be true, false or null, got {self.collision_ends_episode!r}"
            )
        rewards = reward_table(self.reward)
        bonus = self.success_bonus
        if bonus is None:  # every registered term lies in [0, 1]
            bonus = math.fsum(t.weight for t in rewards)
        if not (math.isfinite(bonus) and bonus >= 0):
            raise ValueError(f"task.success_bonus must be >= 0 or null, got {bonus!r}")
        object.__setattr__(self, "success_bonus", bonus)
        terminations = termination_table(self.terminations)
        # Derived once (the config is frozen; the task asks every step): whether the observation or
        # a weighted reward term needs the backend's trunk tilt, the terms computed each step (a
        # term needing the tilt only when the task uses it), and the ray block's directions and miss value.
        uses_tilt = bool(self.observe_imu or any(t.weight > 0.0 and "tilt" in t.needs for t in rewards))
        available = {"contact"} | ({"tilt"} if uses_tilt else set())  # every backend reports contacts
        object.__setattr__(self, "uses_tilt", uses_tilt)
        object.__setattr__(self, "reward_terms", tuple(t for t in rewards if t.needs <= available))
        object.__setattr__(self, "termination_terms", terminations)
        object.__setattr__(self, "ray_directions", _ray_directions(int(self.n_rays)))
        object.__setattr__(self, "ray_miss", float(np.tanh(self.ray_range / self.ray_scale)))  # a ray hitting nothing

    @property
    def observation_size(self) -> int:
        return sum(size for _, size in self.observation_layout)

    @property
    def observation_layout(self) -> tuple[tuple[str, int], ...]:
        """The observation's blocks in order: a run whose layout is a prefix of another's can
        seed it (``init_from`` gives the extra inputs zero weights)."""
        return observation_layout(
            self.obstacles, int(self.n_rays), self.observe_imu, self.path_hint, int(self.observe_history)
        )


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
_pack_floats: Callable[..., None] = struct.Struct("=17f").pack_into  # 17 floats into a float32 buffer


_RAY_DIRECTIONS: dict[int, np.ndarray] = {}


def observation_layout(
    obstacles: bool, n_rays: int, observe_imu: bool = False, path_hint: bool = False, history: int = 0
) -> tuple[tuple[str, int], ...]:
    """``(block, size)`` in observation order (see :func:`observation`; the history block,
    last, is :meth:`NavTask.observe`'s)."""
    blocks = [("goal_and_actions", 17)]
    if obstacles:
        blocks.append(("rays", n_rays))
    if observe_imu:
        blocks.append(("imu", 3))
    if path_hint:
        blocks.append(("path_hint", 2))
    if history:
        blocks.append(("history", history * (5 + (n_rays if obstacles else 0))))
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


# -- reward terms (thesis 5.5; each in [0, 1]) -------------------------------------------------
@reward_term()
def distance(step: StepContext) -> float:
    """exp(-d / 2): nearer the goal is better."""
    return math.exp(-0.5 * step.distance)


@reward_term()
def angle(step: StepContext) -> float:
    """exp(-5 d) · exp(-|α|): take the goal's heading, once near it."""
    return math.exp(-5.0 * step.distance) * math.exp(-abs(step.alpha))


@reward_term()
def orientation(step: StepContext) -> float:
    """exp(-|β|): face the goal while far from it (1 within 0.1 m)."""
    return 1.0 if step.distance < 0.1 else math.exp(-abs(step.beta))


@reward_term()
def obstacle(step: StepContext, epsilon: float = 0.0015, radius: float = 0.0) -> float:
    """exp(-epsilon / d_obs²) of the distance to the nearest obstacle edge (1 without obstacles);
    the thesis's epsilon is 0.0015 m² (0.86 at 0.1 m, 0.55 at 0.05 m).

    ``d_obs`` is measured from the robot centre (the thesis's), or with ``radius`` > 0 from a
    circle of that radius around it: the robot's planar outline rather than its centre, e.g. the
    scene sampler's 0.2 m, which the 3D robot's forearms reach at walk-ready (inside it: 0).
    The ball is excluded (it would create a local minimum before the goal)."""
    if not epsilon >= 0.0:
        raise ValueError(f"task.reward.obstacle.params.epsilon must be >= 0, got {epsilon!r}")
    if not (radius >= 0.0 and math.isfinite(radius)):
        raise ValueError(f"task.reward.obstacle.params.radius must be a number >= 0 [m], got {radius!r}")
    scene = step.scene
    if not scene.obstacles:
        return 1.0
    d_obs = _nearest_circle_distance(step.pose, scene.obstacle_circles, step.arrays[1])
    if d_obs == math.inf:
        return 1.0
    d_obs = max(d_obs - radius, 1e-6)
    return math.exp(-epsilon * (1.0 / d_obs) ** 2)


@reward_term()
def continuity(step: StepContext) -> float:
    """mean(exp(-3 |a(t) - a(t-1)|)) over the action components."""
    return _continuity(step.action, step.previous_action)


@reward_term(needs=("tilt",))
def stability(step: StepContext, scale: float) -> float:
    """exp(-max tilt / scale) of the largest trunk roll or pitch during the step (3D option)."""
    assert step.max_tilt is not None, "the task fills max_tilt when a weighted term needs the tilt"
    return math.exp(-abs(step.max_tilt) / scale)


@reward_term(needs=("contact",))
def contact(step: StepContext) -> float:
    """1 for a step without an obstacle or ball contact, else 0: a contact penalty for 3D, where a
    contact does not end the episode (option: ``task.reward.contact.weight=W``; weight 0 = off)."""
    return 0.0 if step.result.collided else 1.0


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
    total = 0.0
    for x, y in zip(a, b):
        total += exp(-3.0 * abs(x - y))
    return total / len(a)


# -- termination terms (priority order: the task config's ``terminations``) --------------------
@termination_term(settle=lambda reward, step: 0.0)
def sim_error(step: StepContext) -> bool:
    """The simulation became invalid (the backend's verdict, or a non-finite pose); reward 0."""
    return step.result.sim_error is not None


def tilted_over(result: Any, threshold: float = FALL_THRESHOLD) -> bool:
    """The fall rule: the step's largest trunk roll or pitch (``StepResult.max_tilt``) beyond
    ``threshold`` [rad].  The task's ``fall`` term and the walking tools use it."""
    return result.max_tilt > threshold


@termination_term()
def fall(step: StepContext) -> bool:
    """The step's largest trunk roll or pitch exceeded ``fall_threshold``."""
    return tilted_over(step.result, step.config.fall_threshold)


@termination_term()
def collision(step: StepContext) -> bool:
    """The robot touched an obstacle or the ball, where collisions end the episode."""
    return step.result.collided and step.config.collision_ends_episode


def _success_bonus(reward: float, step: StepContext) -> float:
    """The rest of the episode at the maximum step reward (``success_bonus`` per step; thesis: 1)."""
    config = step.config
    assert config.success_bonus is not None, "NavTaskConfig resolves a null bonus"
    return reward + config.success_bonus * float(config.max_steps - step.steps)


@termination_term(settle=_success_bonus)
def success(step: StepContext) -> bool:
    """Within ``success_distance`` of the goal and ``success_angle`` of its heading."""
    return is_success(step.pose, step.scene.goal, step.config, (step.distance, step.alpha, step.beta))


def reward_terms(
    pose: Pose2D,
    scene: Scene,
    action,
    previous_action,
    features: tuple[float, float, float] | None = None,
    max_tilt: float | None = None,
    arrays: tuple[np.ndarray, np.ndarray] | None = None,
    config: NavTaskConfig | None = None,
    collided: bool | None = None,
) -> dict[str, float]:
    """The values of ``config``'s reward terms (default: the thesis's five, "stability" and "contact") at one
    step, outside an env; "stability" (or any term needing the tilt) only with ``max_tilt``, a
    term needing the contact report ("contact") only with ``collided``.

    ``features`` may pass ``goal_features(pose, scene.goal)``, ``arrays`` the episode's
    :func:`scene_arrays`; the actions may be arrays or lists of 6 floats.
    """
    config = config or NavTaskConfig()
    step = StepContext(config)
    step.pose, step.scene, step.action, step.previous_action = pose, scene, action, previous_action
    step.distance, step.alpha, step.beta = features if features is not None else goal_features(pose, scene.goal)
    step.arrays = arrays if arrays is not None else scene_arrays(scene)
    step.max_tilt = max_tilt
    step.result = SimpleNamespace(collided=collided)
    given = {name for name, value in (("tilt", max_tilt), ("contact", collided)) if value is not None}
    return {t.name: t.call(step) for t in reward_table(config.reward) if t.needs <= given}


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


_ZERO_TILT = (0.0, 0.0, 0.0)
_NO_HINT = (0.0, 1.0)
_ZERO_ACTION = [0.0] * 6  # never mutated: actions are fresh lists
_isfinite = math.isfinite


class NavTask:
    """One navigation episode at a time: observation, reward and termination from the truth.

    ``backend_kind`` ("2d" or "3d") resolves ``collision_ends_episode: null``.  The env calls
    :meth:`reset` with the scene and start pose, :meth:`step` with each ``StepResult`` and
    :meth:`observe` with the pose the robot believes it has.

    Attributes (read-only for callers): ``config`` (collision rule resolved), ``scene``, ``pose``
    (true pose, the last finite one), ``previous_actions`` (a(t-1), a(t-2)), ``tilt`` (roll,
    pitch, max tilt of the last step; zeros unless the task uses the tilt), ``steps``, ``outcome``.

    With ``config.observe_history`` = H, :meth:`observe` appends the goal features and rays of the
    H observations before this step's, newest first; :meth:`step` moves the last observed block
    into that history, so observing twice between steps gives the same observation.
    """

    def __init__(self, config: NavTaskConfig, backend_kind: str):
        if config.collision_ends_episode is None:
            config = replace(config, collision_ends_episode=backend_kind == "2d")
        self.config = config
        self._rewards = tuple((t.name, t.call, t.weight) for t in config.reward_terms)
        self._terminations = tuple((t.name, t.call, t.settle) for t in config.termination_terms)
        self._step = StepContext(config)
        self.scene: Scene | None = None
        self.pose = Pose2D()
        self.previous_actions = (_ZERO_ACTION, _ZERO_ACTION)
        self.tilt = _ZERO_TILT
        self.steps = 0
        self.outcome = "running"
        self._features: tuple[float, float, float] | None = None  # goal features of self.pose after a step
        self._path_hint: PathHint | None = None
        self._arrays: tuple[np.ndarray, np.ndarray] | None = None
        self._history: np.ndarray | None = None  # the earlier observations' blocks, newest first
        self._observed: np.ndarray | None = None  # the block of the last observation

    @property
    def obstacles(self) -> bool:
        return self.config.obstacles

    @property
    def observation_size(self) -> int:
        return self.config.observation_size

    @property
    def observation_layout(self) -> tuple[tuple[str, int], ...]:
        return self.config.observation_layout

    def reset(self, scene: Scene, pose: Pose2D) -> None:
        self.scene, self.pose = scene, pose
        self.previous_actions = (_ZERO_ACTION, _ZERO_ACTION)
        self.tilt = _ZERO_TILT  # standing after reset
        self.steps = 0
        self.outcome = "running"
        self._features = None
        self._path_hint = PathHint(scene, pose, self.config) if self.config.path_hint else None
        self._arrays = scene_arrays(scene)  # the obstacles for the compiled kernels, once per episode
        self._history = self._observed = None
        step = self._step
        step.scene, step.arrays = scene, self._arrays

    def command(self, action: list[float]) -> list[float]:
        """The action the robot executes for the policy's ``action``: for the episode's first
        ``start_in_place`` double steps ``action`` times ``start_step_scale`` (in place at 0), else
        ``action`` itself."""
        config = self.config
        if self.steps >= config.start_in_place:
            return action
        scale = config.start_step_scale
        return [a * scale for a in action] if scale else _ZERO_ACTION

    def step(self, result: Any, action: list[float]) -> tuple[float, dict[str, float], bool, bool]:
        """``(reward, reward terms, terminated, truncated)`` of one executed double step.

        ``result`` is the backend's ``StepResult`` (a non-finite pose becomes a sim error and the
        last finite pose is kept: the learner never sees NaN); ``action`` the 6 unit-box floats."""
        config, step, scene = self.config, self._step, self.scene
        assert scene is not None, "reset() before step()"
        self.steps += 1
        pose = result.pose
        if result.sim_error is None and _isfinite(pose[0]) and _isfinite(pose[1]) and _isfinite(pose[2]):
            self.pose = pose
        else:
            result.sim_error = result.sim_error or "non-finite pose"
        features = self._features = goal_features(self.pose, scene.goal)
        step.pose, step.result, step.steps = self.pose, result, self.steps
        step.distance, step.alpha, step.beta = features
        step.action, step.previous_action = action, self.previous_actions[0]
        if config.uses_tilt:  # 3D options: IMU in the observation, stability in the reward
            step.max_tilt = result.max_tilt
            self.tilt = (*result.tilt, result.max_tilt)
        terms = {}
        reward = 0.0  # the weighted sum, left to right in table order
        for name, call, weight in self._rewards:
            value = terms[name] = call(step)
            reward += weight * value
        reward = float(reward)
        terminated = False
        for name, call, settle in self._terminations:
            if call(step):
                self.outcome, terminated = name, True
                if settle is not None:
                    reward = settle(reward, step)
                break
        truncated = not terminated and self.steps >= config.max_steps
        if truncated:
            self.outcome = "timeout"
        self.previous_actions = (action, self.previous_actions[0])
        if self._observed is not None and self._history is not None:
            self._history = np.concatenate([self._observed, self._history[: -self._observed.size]])
            self._observed = None
        return reward, terms, terminated, truncated

    def observe(self, believed: Pose2D) -> np.ndarray:
        """The observation from the pose the robot believes it has (see :func:`observation`)."""
        hint = _NO_HINT if self._path_hint is None else self._path_hint.bearing(believed)
        features = self._features if believed is self.pose else None
        assert self.scene is not None, "reset() before observe()"
        obs = observation(
            believed, self.scene, self.previous_actions, self.config, features, self.tilt, hint, self._arrays
        )
        history = int(self.config.observe_history)
        if not history:
            return obs
        n_rays = int(self.config.n_rays) if self.config.obstacles else 0
        block = np.concatenate([obs[:5], obs[17 : 17 + n_rays]])
        if self._history is None:  # the episode's first observation: no earlier ones
            self._history = np.tile(block, history)
        self._observed = block
        return np.concatenate([obs, self._history])
