"""``FootstepEnv``: the gymnasium environment tying task, noise and backend together.

One env step is one double step: action (6-D, [-1, 1]) → ``DoubleStep`` → backend →
``StepResult`` (truth) → task (reward, termination) → noise (believed pose) → task (observation).
The env is glue: the task (:class:`footsim.tasks.nav.NavTask`) decides what the truth means.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from footsim import config as fconf
from footsim.backends.base import RenderOverlay
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.tasks import nav
from footsim.tasks.nav import OUTCOMES
from footsim.walk.footsteps import DoubleStep, action_values

__all__ = ["OUTCOMES", "DeferredGenerator", "FootstepEnv", "make_env"]


class DeferredGenerator:
    """``np.random.default_rng(seed)``, created when first used (attribute access is forwarded)."""

    __slots__ = ("seed", "_generator")

    def __init__(self, seed: int):
        self.seed = seed
        self._generator: np.random.Generator | None = None

    @property
    def created(self) -> bool:
        """Has the generator been created (by a first draw)?"""
        return self._generator is not None

    @property
    def generator(self) -> np.random.Generator:
        if self._generator is None:
            self._generator = np.random.default_rng(self.seed)
        return self._generator

    def __getattr__(self, name: str):
        if name.startswith("_"):  # e.g. copy/pickle probing __setstate__, or an unset slot
            raise AttributeError(name)
        return getattr(self.generator, name)

    def __getstate__(self):
        return self.seed, self._generator

    def __setstate__(self, state) -> None:
        self.seed, self._generator = state


class FootstepEnv(gym.Env):
    """Footstep navigation to a goal pose (thesis chapter 5) on any footsim backend.

    Args:
        backend: backend preset name (``pymunk``, ``mujoco``, ``dm_control``, ``pybullet``) or a
            mapping with ``name`` and options.
        task: task preset (``nav``, ``nav_obstacles``) or a mapping merged over ``nav``.
        obstacles: shortcut — ``True`` selects ``nav_obstacles`` when ``task`` is not given.
        noise: noise preset (``none``, ``localization``, …) or mapping (``sigma_x`` …).
        randomization: domain-randomization preset (``none``, ``default``, ``strong``) or a
            mapping with ``terms_2d`` / ``terms_3d`` (see ``footsim.randomization``).
        robot, walk: presets or mappings of the ``robot`` and ``walk`` groups (``walk`` default:
            the backend's, ``conf/walk/<backend>.yaml``).
        A group left ``None`` takes its default from ``conf/env.yaml``; a mapping is merged over a
        preset (its ``name`` for backend, task and robot, else the group's default), and a key or
        type the group's schema (``footsim.schema``) does not allow fails naming the key.
        scenes: optional list of ``Scene`` to cycle through instead of sampling (evaluation);
            a scene can also be passed per episode as ``reset(options={"scene": scene})``.  A given
            scene with an obstacle on the robot's start footprint or at the goal (or the ball on
            the start footprint) is refused, as the sampler never draws one
            (``SceneSampler.footprint_overlap``).

    Actions outside [-1, 1] are clipped; NaN or inf raise ``ValueError``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(
        self,
        backend: str | Mapping = "pymunk",
        task: str | Mapping | None = None,
        obstacles: bool | None = None,
        noise: str | Mapping | None = None,
        robot: str | Mapping | None = None,
        walk: str | Mapping | None = None,
        randomization: str | Mapping | None = None,
        scenes: list[Scene] | None = None,
        render_mode: str | None = None,
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if task is None:
            task = "nav_obstacles" if obstacles else "nav"
        self.config = fconf.env_config(backend, task, noise, robot, walk, randomization)
        self.episode_seeds: dict[str, int] = {}  # filled by reset()
        if obstacles is not None and bool(obstacles) != bool(self.config["task"].get("obstacles")):
            raise ValueError(f"obstacles={obstacles} contradicts task {self.config['task'].get('name')!r}")
        self.sampler, task_config = fconf.build_task(self.config["task"])
        self.noise = fconf.build_noise(self.config["noise"])
        self.robot = fconf.build_robot(self.config["robot"])
        self.walk = fconf.build_walk(self.config["walk"])
        self.task = nav.NavTask(task_config, fconf.backend_kind(self.config["backend"]))
        self.backend = fconf.build_backend(self.config["backend"], self.robot, self.walk, self.task.config)
        try:
            self.randomizer = fconf.build_randomizer(self.config["randomization"], self.backend)
        except Exception:
            self.backend.close()
            raise
        self.limits = self.robot.step_limits
        self.render_mode = render_mode
        if scenes is not None:
            try:
                self.sampler.check_scenes(list(scenes), where="scenes: ")
            except ValueError:
                self.backend.close()
                raise
        self.fixed_scenes = list(scenes) if scenes is not None else None
        self._scene_index = 0

        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(6,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(self.task.observation_size,), dtype=np.float32)

        self.scene: Scene | None = None
        self.closed = False
        self._time = 0.0
        self._believed = Pose2D()
        self._walk_feet = None  # the walk's planned feet after the last step: the noise model's odometry

    # -- gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode (gymnasium API).  A closed env stays closed: ``reset()`` after
        :meth:`close` raises ``RuntimeError`` (the simulator is gone; make a new env)."""
        if self.closed:
            raise RuntimeError(self._closed_message("reset"))
        super().reset(seed=seed)
        options = options or {}
        if "scene" in options:
            problem = self.sampler.footprint_overlap(options["scene"])
            if problem is not None:
                raise ValueError(f"reset(options={{'scene': ...}}): {problem}")
            self.scene = options["scene"]
        elif self.fixed_scenes is not None:
            self.scene = self.fixed_scenes[self._scene_index % len(self.fixed_scenes)]
            self._scene_index += 1
        else:
            self.scene = self.sampler.sample(self.np_random)
        # Independent streams so that e.g. switching noise off leaves scene sampling unchanged.
        # Seeding a generator costs more than a 2D step and most episodes never draw from
        # some of them, so they are created on first use (same seeds, same streams).
        # The seeds are 63-bit words of the raw stream: what ``integers(2**63)`` returns (for that
        # bound numpy's bounded draw is the raw word shifted right by one), at a fifth of its cost.
        raw = self.np_random.bit_generator.random_raw
        self._noise_rng = DeferredGenerator(raw() >> 1)
        backend_seed = raw() >> 1
        backend_rng = (
            DeferredGenerator(backend_seed)
            if getattr(self.backend, "deferred_rng", False)
            else np.random.default_rng(backend_seed)
        )
        self._random_rng = DeferredGenerator(raw() >> 1)
        #: This episode's seeds of the noise, backend and randomization streams.
        self.episode_seeds = {
            "noise": self._noise_rng.seed,
            "backend": backend_seed,
            "randomization": self._random_rng.seed,
        }
        self._randomization = {}
        if self.randomizer.active:
            self._randomization = self.randomizer.episode(self._random_rng)
            self.backend.apply_randomization(self._randomization)
        pose = self.backend.reset(self.scene, backend_rng)
        self.task.reset(self.scene, pose)
        self._time = 0.0
        self.noise.reset(self._noise_rng)  # per-episode bias, empty delay buffer
        self._walk_feet = None
        self._believed = self.noise.believe(pose, self._noise_rng)
        return self.task.observe(self._believed), self._info({})

    def step(self, action):
        if self.scene is None:  # not reset yet, or closed (close() forgets the scene)
            raise RuntimeError(self._closed_message("step") if self.closed else "step() called before reset()")
        action = self.task.command(action_values(action))  # 6 finite floats clipped to [-1, 1]; raises otherwise
        double_step = DoubleStep.from_unit(action, self.limits)
        if self.randomizer.active:
            changed = self.randomizer.step(self._random_rng)
            if changed:
                self._randomization.update(changed)
                self.backend.apply_randomization(changed)
        result = self.backend.execute(double_step)
        self._time += result.duration_s
        reward, terms, terminated, truncated = self.task.step(result, action)
        odometry = None
        if self.noise.odometry_weight:
            odometry = self._walk_odometry(result)
            self._walk_feet = result.feet
        self._believed = self.noise.believe(self.task.pose, self._noise_rng, odometry)
        obs = self.task.observe(self._believed)
        return obs, reward, terminated, truncated, self._info(terms, result)

    def _walk_odometry(self, result) -> Pose2D | None:
        """The navigation pose's displacement over the step as the walk planned it, in the robot frame:
        the executed double step placed from the feet before by the footstep geometry, blind to where
        the feet really landed (2D footstep-landing randomization or execution model, 3D slip and creep).
        None on the first step of an episode or when the backend reports no feet."""
        before, geometry = self._walk_feet, getattr(self.backend, "geometry", None)
        if before is None or result.feet is None:
            return None
        if geometry is None or result.executed is None:  # a backend without the geometry: its reported feet
            return before.nav_pose.relative(result.feet.nav_pose)
        planned = geometry.execute(before, result.executed)[1]
        return before.nav_pose.relative(planned.nav_pose)

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.closed:
            raise RuntimeError(self._closed_message("render"))
        return self.backend.render(self.render_overlay())

    def render_overlay(self, footsteps: tuple[Pose2D, ...] = ()) -> RenderOverlay:
        """What a frame draws over the scene now: the goal (green once reached), the believed pose,
        the rays from it when the task observes obstacles, and ``footsteps`` (commanded put-downs,
        world frame) with the robot's foot size."""
        if self.scene is None:
            raise RuntimeError(self._closed_message("render") if self.closed else "render() called before reset()")
        rays = None
        config = self.task.config
        if config.obstacles:
            dists = nav.ray_distances(self._believed, self.scene.all_obstacles, config.n_rays, config.ray_range)
            angles = self._believed.theta + np.arange(config.n_rays) * (2 * math.pi / config.n_rays)
            rays = np.stack([self._believed.x + dists * np.cos(angles), self._believed.y + dists * np.sin(angles)], 1)
        return RenderOverlay(
            goal=self.scene.goal,
            ray_endpoints=rays,
            believed=self._believed,
            reached=nav.is_success(self.task.pose, self.scene.goal, self.task.config),
            footsteps=tuple(footsteps),
            foot_size=(self.robot.foot_length, self.robot.foot_width),
        )

    def close(self):
        """Release the simulator; calling it again does nothing.  After it, ``reset``, ``step`` and
        ``render`` raise ``RuntimeError``."""
        self.backend.close()
        self.closed = True
        self.scene = None

    def _closed_message(self, verb: str) -> str:
        backend = self.config["backend"]["name"]
        return f"{verb}() called after close(): this env's {backend} backend is released; make a new env"

    # -- helpers --------------------------------------------------------------------------
    def _info(self, terms: dict, result=None) -> dict[str, Any]:
        task = self.task
        executed = None if result is None else result.executed
        # one array for the poses (and the executed action), handed out as views: numpy's
        # per-array cost is a visible share of a 2D step
        values = np.array(
            (*task.pose, *self._believed)
            if executed is None
            else (*task.pose, *self._believed, *executed[0], *executed[1]),
            dtype=float,
        )
        info = {
            "pose": values[:3],
            "pose_estimate": values[3:6],
            "outcome": task.outcome,
            "time_s": self._time,
            "steps": task.steps,
            "reward_terms": terms,  # a fresh dict every step
        }
        if self.randomizer.active:
            info["randomization"] = dict(self._randomization)
        if result is not None:
            info["collided"] = bool(result.collided)
            info["executed_action"] = None if executed is None else values[6:]
            if result.sim_error is not None:
                info["sim_error"] = result.sim_error
            info.update(result.info)
        return info


#: FootstepNav-v0's backend presets: footsim 0.x's tuned 3D settings (conf/backend/*_v0.yaml).
V0_BACKENDS = {"mujoco": "mujoco_v0", "dm_control": "dm_control_v0", "pybullet": "pybullet_v0"}
V0_ROBOT = "wolfgang_simplified"


def footstep_nav_v0(backend: str | Mapping = "pymunk", robot: str | Mapping | None = None, **kwargs) -> FootstepEnv:
    """``footsim/FootstepNav-v0``: footsim 0.x's setup, kept so old results can be rerun and compared
    with FootstepNav-v1 (the default ``FootstepEnv``).  The simplified Wolfgang-OP
    (``robot=wolfgang_simplified``) and, on a 3D backend named by a string, that backend's v0 preset
    (``backend=mujoco_v0`` …: a 10 ms timestep, contact and servo values tuned for the old model, and
    its walk ``footsim_slow``).  A backend mapping is used as given."""
    if isinstance(backend, str):
        backend = V0_BACKENDS.get(backend, backend)
    return FootstepEnv(backend=backend, robot=V0_ROBOT if robot is None else robot, **kwargs)


def make_env(cfg, scenes: list[Scene] | None = None, render_mode: str | None = None) -> FootstepEnv:
    """Build an env from a composed Hydra config (groups ``backend task noise robot walk``)."""
    plain = fconf.to_plain(cfg)
    return FootstepEnv(
        backend=plain["backend"],
        task=plain["task"],
        noise=plain["noise"],
        robot=plain["robot"],
        walk=plain["walk"],
        randomization=plain.get("randomization", "none"),
        scenes=scenes,
        render_mode=render_mode,
    )
