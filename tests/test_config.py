"""Typed configs, one composer: every preset composes against its schema, through Hydra."""

import gymnasium as gym
import pytest
import yaml
from hydra import initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

import footsim  # noqa: F401  (registers the env)
from footsim import config as fconf
from footsim import schema
from footsim.env import FootstepEnv

GROUP_SCHEMAS = {
    "robot": schema.RobotConfig,
    "task": schema.TaskConfig,
    "randomization": schema.RandomizationConfig,
    "agent": schema.AgentConfig,
}


def _raw(group: str, name: str) -> dict:
    """A preset file read by a YAML parser, not by Hydra."""
    return yaml.safe_load((fconf.conf_dir() / group / f"{name}.yaml").read_text())


@pytest.mark.parametrize("group", ["backend", "robot", "walk", "task", "noise", "randomization", "agent", "controller"])
def test_every_preset_composes_against_a_schema(group):
    for name in fconf.available(group):
        node = fconf.compose(None, [f"+{group}={name}"])[group]
        object_type = OmegaConf.get_type(node)
        assert object_type.__module__ == schema.__name__, (group, name, object_type)
        if group in GROUP_SCHEMAS:
            assert object_type is GROUP_SCHEMAS[group]
        defaults = _raw(group, name).get("defaults", [])
        assert defaults[-1] == "_self_" and len(defaults) == 2, (group, name, defaults)  # a schema or one base preset


def test_dm_control_inherits_the_mujoco_values():
    mujoco, dm_control = fconf.load_preset("backend", "mujoco"), fconf.load_preset("backend", "dm_control")
    own = {k: v for k, v in _raw("backend", "dm_control").items() if k != "defaults"}
    assert own == {"name": "dm_control", "max_render_size": 1024}
    assert dm_control == {**mujoco, **own}
    assert {k: v for k, v in _raw("backend", "mujoco").items() if k != "defaults"} == mujoco


@pytest.mark.parametrize(
    "backend, walk", [("pymunk", "default"), ("mujoco", "bitbots_sim"), ("pybullet", "bitbots_sim")]
)
def test_the_walk_default_is_the_backends(backend, walk):
    expected = {k: v for k, v in _raw("walk", walk).items() if k != "defaults"}
    assert fconf.env_config(backend)["walk"] == expected
    assert fconf.load_preset("walk", backend=backend) == expected


def test_keyword_api_merges_mappings_over_presets():
    env = gym.make("footsim/FootstepNav-v1", task={"name": "nav_obstacles", "max_steps": 200}, noise={"sigma_x": 0.1})
    try:
        config = env.unwrapped.task.config
        assert config.max_steps == 200 and config.obstacles and env.observation_space.shape == (53,)
        assert env.unwrapped.config["noise"] == {**fconf.load_preset("noise", "none"), "sigma_x": 0.1}
    finally:
        env.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (
            {"backend": {"name": "mujoco", "servo_kp": 2.0}},
            r"backend mujoco: unknown key\(s\) \['servo_kp'\]; valid: \[.*'servo_kp_scale'",
        ),
        ({"task": {"scenes": {"n_obstacle": 2}}}, r"task\.scenes: unknown key\(s\) \['n_obstacle'\]"),
        ({"walk": {"frequency": 1.0}}, r"walk: unknown key\(s\) \['frequency'\]; valid: \[.*'freq'"),
        ({"task": "nav_hard"}, r"unknown task preset 'nav_hard'; available: nav, nav_obstacles"),
        ({"backend": "bullet"}, r"unknown backend 'bullet'; valid backends: pymunk, mujoco, dm_control, pybullet"),
    ],
)
def test_a_wrong_key_fails_at_start_naming_it(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FootstepEnv(**kwargs)


@pytest.mark.parametrize(
    "config_name, override, key",
    [("env", "task.max_steps=many", "task.max_steps"), ("config", "train.n_envs=eight", "train.n_envs")],
)
def test_a_command_line_value_of_the_wrong_type_names_the_key(config_name, override, key):
    with pytest.raises(ConfigCompositionException) as err:
        fconf.compose(config_name, [override])
    assert key in str(err.value) + str(err.value.__cause__)


def test_composing_inside_a_running_hydra_app_keeps_its_state(tmp_path):
    (tmp_path / "app.yaml").write_text("x: 1\n")
    with initialize_config_dir(str(tmp_path), version_base="1.3"):
        running = GlobalHydra.instance().hydra
        env = FootstepEnv(backend="pymunk", task="nav_obstacles")
        env.close()
        assert GlobalHydra.instance().hydra is running  # the app's Hydra is back
    assert not GlobalHydra.instance().is_initialized()  # and nothing is left behind outside an app


def test_a_run_config_in_the_old_keys_evaluates_unchanged():
    old = OmegaConf.create(
        {
            "backend": {
                **fconf.load_preset("backend", "pymunk"),
                "collision_ends_episode": True,
                "fall_threshold": 0.6,
            },
            "task": {
                **{k: v for k, v in fconf.load_preset("task", "nav").items() if k != "reward"},
                "reward_weights": {"continuity": 0.2, "distance": 0.3, "angle": 0.3, "orientation": 0.2},
                "stability_scale": 0.3,
            },
        }
    )
    new = fconf.upgrade_run_config(old)
    assert "fall_threshold" not in new.backend and "collision_ends_episode" not in new.backend
    assert new.task.fall_threshold == 0.6 and new.task.collision_ends_episode is None  # true = the 2D rule
    weights = {name: entry["weight"] for name, entry in new.task.reward.items()}
    assert weights == {
        "distance": 0.3,
        "angle": 0.3,
        "orientation": 0.2,
        "obstacle": 0.0,
        "continuity": 0.2,
        "stability": 0.0,
        "contact": 0.0,
    }
    assert new.task.reward.stability.params.scale == 0.3
    assert fconf.upgrade_run_config(new) is new  # today's keys: unchanged


@pytest.mark.parametrize(
    "config_name, group, root",
    [
        ("config", "experiment", schema.TrainAppConfig),
        ("config", "launcher", schema.TrainAppConfig),
        ("config", "hpo", schema.TrainAppConfig),
        ("walktune", "hpo", schema.WalktuneAppConfig),
    ],
)
def test_every_global_preset_composes_against_its_apps_root_schema(config_name, group, root):
    walk_tuning = config_name == "walktune"  # the hpo/walk* presets are footsim-walktune's, the others footsim-train's
    names = [n for n in fconf.available(group) if group != "hpo" or n.startswith("walk") == walk_tuning]
    assert names
    for name in names:
        cfg = fconf.compose(config_name, [f"+{group}={name}"])
        assert OmegaConf.get_type(cfg) is root, (group, name)
        written = {k for k in _raw(group, name) if k not in ("defaults", "hydra")}
        assert written <= set(schema.schema_fields(root)), (group, name, written)


def test_a_global_preset_writing_an_unknown_key_fails_naming_it(tmp_path):
    (tmp_path / "experiment").mkdir()
    (tmp_path / "experiment" / "typo.yaml").write_text("# @package _global_\ntrain:\n  total_timestep: 5\n")
    with pytest.raises(ConfigCompositionException) as err:
        fconf.compose("config", [f"hydra.searchpath=[file://{tmp_path}]", "+experiment=typo"])
    assert "total_timestep" in str(err.value) + str(err.value.__cause__)
    (tmp_path / "experiment" / "typo.yaml").write_text("# @package _global_\nsede: 3\n")
    with pytest.raises(ConfigCompositionException) as err:
        fconf.compose("config", [f"hydra.searchpath=[file://{tmp_path}]", "+experiment=typo"])
    assert "sede" in str(err.value) + str(err.value.__cause__)


def test_linear_learning_rate_schedule_decays_to_zero_over_the_run():
    """SB3 calls the schedule with the share of the run still to go (1 → 0); hand values."""
    from footsim.rl.common import learning_rate_schedule

    agent = OmegaConf.create({"learning_rate": 4.0e-4, "lr_schedule": "linear"})
    schedule = learning_rate_schedule(agent)
    assert [schedule(p) for p in (1.0, 0.25, 0.0)] == pytest.approx([4.0e-4, 1.0e-4, 0.0])
    assert learning_rate_schedule(OmegaConf.create({"learning_rate": 4.0e-4, "lr_schedule": "constant"})) == 4.0e-4
    # a run saved before the key existed trains at its constant rate
    assert learning_rate_schedule(OmegaConf.create({"learning_rate": 4.0e-4})) == 4.0e-4
