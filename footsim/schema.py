"""Structured-config schemas of every Hydra group, registered in Hydra's ConfigStore.

A schema gives a group's keys and their types; the YAML presets in ``conf/`` hold the values
(each starts with ``defaults: [/schema/<group>@_here_, _self_]``, or inherits a preset of its
group that does).  Every field is ``???`` (MISSING) in the schema, so a schema never supplies a
value: a key a preset leaves out takes the default of the code that reads it.  Composing a
preset with a key the schema lacks, or a value of the wrong type, fails naming the key.

Where a runtime class already lists the keys (``WalkParams``, ``NoiseModel``, the planners'
parameter classes), the schema is derived from its fields, so the keys live in one place.

Schemas (ConfigStore ``group/name``): ``schema/backend/{pymunk,mujoco,pybullet}`` (``mujoco``
serves both MuJoCo-engine backends, mujoco and dm_control), ``schema/robot``, ``schema/walk``,
``schema/task``, ``schema/noise``, ``schema/randomization``, ``schema/agent``,
``schema/controller/{policy,velocity,footstep}``, ``schema/train`` and ``schema/eval`` (the
top-level sections of ``footsim-train``), ``schema/eval_app`` (``footsim-eval``'s config).

The groups ``experiment``, ``hpo`` and ``launcher`` are ``@package _global_``: a preset of theirs
writes into the root of the app that composes it, so the app's root schema is theirs:
``schema/train_app`` (``footsim-train``: ``experiment``, ``hpo/ppo_*``, ``launcher``) and
``schema/walktune_app`` (``footsim-walktune``: ``hpo/walk*``; the ``launcher`` presets are
``footsim-train``'s, since they also switch its progress bar off).  Their ``hydra.*``
keys are typed by Hydra's own schemas of the launcher and sweeper plugins they select.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional  # noqa: UP035  (OmegaConf reads these annotations)

from omegaconf import MISSING

from footsim.tasks.noise import NoiseModel
from footsim.walk.params import WalkParams

# ruff: noqa: UP006, UP007, UP045  (structured configs need typing's Dict / List / Optional)


# -- backend ------------------------------------------------------------------------------------
@dataclass
class PymunkBackendConfig:
    """2D geometric backend (``footsim.backends.pymunk2d.Pymunk2DBackend``)."""

    name: str = MISSING
    collision_model: str = MISSING
    collision_distance: float = MISSING
    execution_model: Optional[str] = MISSING
    execution_noise: bool = MISSING
    execution_falls: bool = MISSING
    fall_model: Optional[str] = MISSING


@dataclass
class CameraConfig:
    """The 3D backends' render camera (``footsim.backends.base.TrackingCamera``: its defaults)."""

    distance: float = MISSING
    elevation: float = MISSING
    azimuth: float = MISSING
    fov: float = MISSING
    height: float = MISSING
    shadows: bool = MISSING


@dataclass
class Physics3DConfig:
    """Options of the shared 3D driver (``footsim.backends.physics3d.Physics3DBackend``)."""

    name: str = MISSING
    control_dt: float = MISSING
    physics_dt: float = MISSING
    stabilizer: Optional[Dict[str, float]] = MISSING
    contact_check_every: int = MISSING
    settle_time: float = MISSING
    out_of_bounds: float = MISSING
    render_size: List[int] = MISSING
    camera: CameraConfig = MISSING  # unset: TrackingCamera's defaults
    rigid_upper_body: bool = MISSING


@dataclass
class MujocoBackendConfig(Physics3DConfig):
    """The MuJoCo-engine backends (mujoco and dm_control): the driver plus the model options."""

    integrator: str = MISSING
    torsional_friction: Optional[float] = MISSING
    rolling_friction: Optional[float] = MISSING
    servo_kp_scale: float = MISSING
    servo_damping_scale: float = MISSING
    servo_kv: float = MISSING
    servo_force_limit: Optional[float] = MISSING
    joint_ref: Dict[str, float] = MISSING
    contact_solref: Optional[List[float]] = MISSING
    friction_cone: str = MISSING
    impratio: float = MISSING
    obstacle_inflation: float = MISSING
    max_render_size: int = MISSING


@dataclass
class PybulletBackendConfig(Physics3DConfig):
    """The PyBullet backend: the driver plus Bullet's contact, motor and solver options."""

    lateral_friction: float = MISSING
    spinning_friction: float = MISSING
    rolling_friction: float = MISSING
    position_gain_scale: float = MISSING
    position_rate: Optional[float] = MISSING
    velocity_gain: float = MISSING
    motor_max_velocity: bool = MISSING
    solver_iterations: int = MISSING
    motor: str = MISSING
    servo_kp_scale: float = MISSING
    servo_damping_scale: float = MISSING
    servo_kv: float = MISSING
    armature_scale: float = MISSING
    obstacle_height: float = MISSING
    self_collision: bool = MISSING
    max_base_speed: float = MISSING


# -- robot, task ---------------------------------------------------------------------------------
@dataclass
class RobotConfig:
    name: str = MISSING
    # Wolfgang-OP's option (footsim.robots.wolfgang): mass [kg] added at the torso's COM (the real
    # robot with cables ≈ +1.4 kg; the Bit-Bots' MuJoCo model +1.0); null = the URDF's 6.12 kg.
    torso_extra_mass: Optional[float] = None


@dataclass
class ScenesConfig:
    """Scene sampling (``footsim.tasks.scenes.SceneSampler``, thesis 5.1)."""

    goal_sigma_xy: float = MISSING
    goal_sigma_theta: float = MISSING
    n_obstacles_robot: int = MISSING
    n_obstacles_goal: int = MISSING
    obstacle_offset_sigma: float = MISSING
    obstacle_radius_min: float = MISSING
    obstacle_radius_max: float = MISSING
    ball_radius: float = MISSING
    ball_offset: float = MISSING
    robot_radius: float = MISSING


@dataclass
class TaskConfig:
    """The navigation task (``footsim.tasks.nav.NavTaskConfig``; angles in degrees here)."""

    name: str = MISSING
    obstacles: bool = MISSING
    max_steps: int = MISSING
    success_distance: float = MISSING
    success_angle_deg: float = MISSING
    distance_scale: float = MISSING
    n_rays: int = MISSING
    ray_range: float = MISSING
    ray_scale: float = MISSING
    # Term tables (footsim.tasks.terms): name -> {weight, params, func} / name -> {params, func} or
    # null.  The values are untyped so that `+task.reward.NAME={weight: W, func: ...}` can add a term
    # on the command line (OmegaConf cannot add a dict to a Dict[str, <dataclass>]); the task checks
    # each entry's keys and types when it is built (footsim.tasks.terms.reward_table).
    reward: Dict[str, Any] = MISSING
    terminations: Dict[str, Any] = MISSING
    fall_threshold: float = MISSING
    collision_ends_episode: Optional[bool] = MISSING
    observe_imu: bool = MISSING
    imu_scale: float = MISSING
    path_hint: bool = MISSING
    path_hint_lookahead: float = MISSING
    path_hint_clearance: float = MISSING
    observe_history: int = MISSING
    start_in_place: int = MISSING
    start_step_scale: float = MISSING
    success_bonus: Optional[float] = MISSING
    scenes: ScenesConfig = MISSING


@dataclass
class RandomizationConfig:
    """Domain randomization: term name → ``{dist, low/high | mean/std | value, when}``
    (``footsim.randomization.TermSpec`` checks each entry)."""

    name: str = MISSING
    terms_2d: Dict[str, Any] = MISSING
    terms_3d: Dict[str, Any] = MISSING


# -- agent, command-line sections -----------------------------------------------------------------
@dataclass
class NetArchConfig:
    pi: List[int] = MISSING
    vf: List[int] = MISSING


@dataclass
class AgentConfig:
    """PPO (stable-baselines3) and its policy network."""

    name: str = MISSING
    distribution: str = MISSING
    beta_action: str = MISSING
    net_arch: NetArchConfig = MISSING
    activation: str = MISSING
    learning_rate: float = MISSING
    lr_schedule: str = MISSING
    n_steps: int = MISSING
    batch_size: int = MISSING
    n_epochs: int = MISSING
    gamma: float = MISSING
    gae_lambda: float = MISSING
    clip_range: float = MISSING
    ent_coef: float = MISSING
    vf_coef: float = MISSING
    max_grad_norm: float = MISSING
    log_std_init: float = MISSING
    reset_log_std: bool = MISSING
    normalize_reward: bool = MISSING
    normalize_obs: bool = MISSING


@dataclass
class SelectSection:
    """``train.select``: keep the best policy on validation scenes (``footsim.rl.selection``)."""

    every: int = MISSING
    n_scenes: int = MISSING
    scenes_seed: int = MISSING
    noise: Optional[str] = None  # a conf/noise preset to validate under; None: the run's own


@dataclass
class ReplaySection:
    """``train.replay``: replay failed scenes in training (``footsim.rl.replay``)."""

    prob: float = 0.0
    capacity: int = 1000


@dataclass
class TrainSection:
    """``footsim-train``'s ``train`` section."""

    total_timesteps: int = MISSING
    n_envs: int = MISSING
    vec_env: str = MISSING
    checkpoint_freq: int = MISSING
    progress_bar: bool = MISSING
    tensorboard: bool = MISSING
    select: SelectSection = MISSING
    replay: ReplaySection = field(default_factory=ReplaySection)


@dataclass
class EvalSection:
    """``footsim-train``'s ``eval`` section (the evaluation after training)."""

    after_train: bool = MISSING
    scenes: Optional[str] = MISSING
    n_scenes: int = MISSING
    scenes_seed: int = MISSING
    deterministic: bool = MISSING
    plot: bool = MISSING
    video: bool = MISSING
    video_episodes: int = MISSING
    video_fps: float = MISSING
    noise: Optional[str] = None  # a conf/noise preset to evaluate under; None: the run's own


@dataclass
class EvalAppConfig:
    """``footsim-eval``'s own keys; its groups (controller, and the backend, task, noise,
    randomization and walk that replace a run's) are composed into the ``Any`` fields, None when unset."""

    controller: Any = None
    backend: Any = None
    task: Any = None
    noise: Any = None
    randomization: Any = None
    walk: Any = None
    run: Optional[str] = MISSING
    scenes: Optional[str] = MISSING
    n_scenes: int = MISSING
    scenes_seed: int = MISSING
    deterministic: bool = MISSING
    beta_action: Optional[str] = MISSING
    seed: int = MISSING
    plot: bool = MISSING
    video: bool = MISSING
    video_episodes: int = MISSING
    video_fps: float = MISSING
    shard: Optional[str] = MISSING
    merge: Optional[str] = MISSING
    backends: Any = MISSING  # a list [A,B] or a string 'A,B' (footsim-eval's side-by-side video)


@dataclass
class TrainAppConfig:
    """``footsim-train``'s root (``conf/config.yaml``): the env's groups and ``agent`` (each typed by
    its own group schema, so ``Any`` here), the ``train`` / ``eval`` sections and the run keys.  A
    global-package preset (``+experiment=``, ``+hpo=``, ``+launcher=``) that writes a key outside
    these fails naming the key."""

    backend: Any = MISSING
    robot: Any = MISSING
    walk: Any = MISSING
    task: Any = MISSING
    noise: Any = MISSING
    randomization: Any = MISSING
    agent: Any = MISSING
    train: TrainSection = MISSING
    eval: EvalSection = MISSING
    seed: int = MISSING
    resume: Optional[str] = MISSING
    init_from: Optional[str] = MISSING


@dataclass
class TuneSection:
    """``footsim-walktune``'s ``tune`` section (read by :func:`footsim.calibration.walktune.run`)."""

    command: str = MISSING
    levels: List[float] = MISSING
    warmup: int = MISSING
    measure: int = MISSING
    min_gain: float = MISSING
    symmetric: bool = MISSING
    stand_time: float = MISSING
    seed: int = MISSING


@dataclass
class WalktuneAppConfig:
    """``footsim-walktune``'s root (``conf/walktune.yaml``): the robot on a backend with a walk, and
    the ``tune`` section; ``+hpo=walk*`` presets write into it."""

    backend: Any = MISSING
    robot: Any = MISSING
    walk: Any = MISSING
    tune: TuneSection = MISSING


@dataclass
class PolicyControllerConfig:
    name: str = MISSING


def _annotation(hint: Any) -> Any:
    """An OmegaConf-readable type for a runtime dataclass field's type hint."""
    if hint in (int, float, bool, str):
        return hint
    if hint in (tuple, list) or typing.get_origin(hint) in (tuple, list):
        return List[float]
    return Any


def derived_schema(cls_name: str, source: type, *, named: bool, doc: str) -> type:
    """A schema with the public init fields of the dataclass ``source`` (all MISSING), plus
    ``name: str`` when ``named``: the keys live once, in ``source``."""
    hints = typing.get_type_hints(source)
    fields_ = [("name", str, field(default=MISSING))] if named else []
    fields_ += [
        (f.name, _annotation(hints[f.name]), field(default=MISSING))
        for f in dataclasses.fields(source)
        if f.init and not f.name.startswith("_")
    ]
    schema = dataclasses.make_dataclass(cls_name, fields_)
    schema.__doc__ = doc
    schema.__module__ = __name__
    return schema


def _env_derived() -> dict[str, type]:

    return {
        "walk": derived_schema("WalkConfig", WalkParams, named=False, doc="The walk engine's parameters (WalkParams)."),
        "noise": derived_schema("NoiseConfig", NoiseModel, named=True, doc="Localization noise (NoiseModel)."),
    }


def _controller_derived() -> dict[str, type]:
    from footsim.planners.footstep import FootstepParams
    from footsim.planners.velocity import VelocityParams

    return {
        "controller/policy": PolicyControllerConfig,
        "eval_app": EvalAppConfig,
        "controller/velocity": derived_schema(
            "VelocityControllerConfig", VelocityParams, named=True, doc="The velocity baseline (VelocityParams)."
        ),
        "controller/footstep": derived_schema(
            "FootstepControllerConfig", FootstepParams, named=True, doc="The footstep planner (FootstepParams)."
        ),
    }


_REGISTERED: set[str] = set()


def _store(nodes: dict[str, type]) -> None:
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    for path, node in nodes.items():
        group, _, name = path.rpartition("/")
        store.store(group=f"schema/{group}" if group else "schema", name=name, node=node)


def register_schemas(controllers: bool = False) -> None:
    """Store the schemas in Hydra's ConfigStore (idempotent; before composing or ``hydra.main``).

    ``controllers``: also the baselines' ``controller`` schemas (derived from the planners'
    parameter classes, whose import is heavy; footsim-eval and the controller group need them)."""
    if "env" not in _REGISTERED:
        _store(
            {
                "backend/pymunk": PymunkBackendConfig,
                "backend/mujoco": MujocoBackendConfig,
                "backend/pybullet": PybulletBackendConfig,
                "robot": RobotConfig,
                "task": TaskConfig,
                "randomization": RandomizationConfig,
                "agent": AgentConfig,
                "train": TrainSection,
                "eval": EvalSection,
                "train_app": TrainAppConfig,
                "walktune_app": WalktuneAppConfig,
                **_env_derived(),
            }
        )
        _REGISTERED.add("env")
    if controllers and "controllers" not in _REGISTERED:
        _store(_controller_derived())
        _REGISTERED.add("controllers")


def schema_fields(schema: type) -> list[str]:
    """The keys a schema accepts."""
    return [f.name for f in dataclasses.fields(schema)]
