"""The three how-tos of docs/ARCHITECTURE.md, done as a user would: from code outside footsim,
without editing a footsim file.  If one of these breaks, the guide is wrong."""

from __future__ import annotations

import dataclasses
import math
import sys
import types

import gymnasium as gym
import numpy as np
import pytest
from hydra.core.config_store import ConfigStore

import footsim  # noqa: F401  (registers the env)
from footsim.backends.base import BACKENDS, Backend, StepResult, register_backend
from footsim.geometry import Pose2D
from footsim.robots.registry import ROBOTS, get_robot, register_robot
from footsim.scene import Scene
from footsim.walk.footsteps import DoubleStep, FootstepGeometry

ENV = "footsim/FootstepNav-v1"


# -- 1. add a backend ---------------------------------------------------------------------------


class IdealBackend(Backend):
    """Feet land exactly where the footstep geometry puts them; nothing collides, nothing falls."""

    name = "ideal"
    kind = "2d"

    def __init__(self, robot, walk, step_time: float = 0.5):
        self.geometry = FootstepGeometry(robot.step_limits, robot.foot_length, robot.foot_width, walk.foot_distance)
        self.step_time = step_time

    def reset(self, scene: Scene, rng: np.random.Generator) -> Pose2D:
        self.feet = self.geometry.initial_feet()
        return self.feet.nav_pose

    def execute(self, double_step: DoubleStep) -> StepResult:
        _, self.feet, executed, _ = self.geometry.execute(self.feet, double_step)
        return StepResult(pose=self.feet.nav_pose, duration_s=self.step_time, feet=self.feet, executed=executed)


@dataclasses.dataclass
class IdealBackendConfig:
    name: str = "ideal"
    step_time: float = 0.5


@pytest.fixture
def ideal_backend():
    """The how-to's registration, in a module of the user's (here: a throwaway module)."""
    module = types.ModuleType("my_backends")
    module.IdealBackend = IdealBackend  # type: ignore[attr-defined]
    sys.modules["my_backends"] = module
    register_backend("ideal", "my_backends:IdealBackend")
    store = ConfigStore.instance()
    store.store(group="backend", name="ideal", node=IdealBackendConfig)
    store.store(group="walk", name="ideal", node={"defaults": ["default", "_self_"]})
    yield
    BACKENDS.pop("ideal")
    sys.modules.pop("my_backends")
    store.repo["backend"].pop("ideal.yaml")
    store.repo["walk"].pop("ideal.yaml")


def test_how_to_add_a_backend(ideal_backend):
    env = gym.make(ENV, backend="ideal")
    obs, _ = env.reset(seed=0, options={"scene": Scene(goal=(1.0, 0.0, 0.0))})
    # a full forward double step (Wolfgang's x limit 0.156 m, each step from the support foot): the
    # right foot lands at x = 0.156, the left at 0.312; the navigation pose is their mean
    obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0, 0, 1.0, 0, 0], dtype=np.float32))
    assert info["pose"][0] == pytest.approx(0.234)
    assert info["time_s"] == pytest.approx(0.5)
    assert np.tanh(1.0 - 0.234) == pytest.approx(obs[0], abs=1e-6)  # tanh(distance to the goal)
    env.close()
    assert gym.make(ENV, backend={"name": "ideal", "step_time": 0.25}).unwrapped.backend.step_time == 0.25
    with pytest.raises(ValueError, match="step_tme"):
        gym.make(ENV, backend={"name": "ideal", "step_tme": 0.25})


# -- 2. add a robot -----------------------------------------------------------------------------


def wolfgang_with_battery():
    """Wolfgang-OP with 1 kg more in the torso (a battery pack), COM and inertia kept."""
    robot = get_robot("wolfgang")
    links = tuple(
        dataclasses.replace(link, inertial=dataclasses.replace(link.inertial, mass=link.inertial.mass + 1.0))
        if link.name == robot.base_link
        else link
        for link in robot.links
    )
    return dataclasses.replace(robot, name="wolfgang_battery", links=links)


@pytest.fixture
def heavier_robot():
    register_robot("wolfgang_battery", wolfgang_with_battery)
    yield
    ROBOTS.pop("wolfgang_battery")


def test_how_to_add_a_robot(heavier_robot):
    assert get_robot("wolfgang_battery").total_mass == pytest.approx(get_robot("wolfgang").total_mass + 1.0)
    env = gym.make(ENV, robot={"name": "wolfgang_battery"})
    assert env.unwrapped.robot.name == "wolfgang_battery"
    env.reset(seed=0)
    env.step(np.zeros(6, dtype=np.float32))
    env.close()


def test_the_added_robot_is_built_by_the_mujoco_model():
    pytest.importorskip("mujoco")
    from footsim.robots.mjcf import build_mjcf

    base, heavy = (build_mjcf(robot).model for robot in (get_robot("wolfgang"), wolfgang_with_battery()))
    assert heavy.body_subtreemass[0] == pytest.approx(base.body_subtreemass[0] + 1.0)


# -- 3. add a reward term and a termination term ------------------------------------------------


def heading_error(step, scale: float = 1.0) -> float:
    """exp(-|robot heading − goal heading| / scale): reward facing the goal's direction anywhere."""
    return math.exp(-abs(step.alpha) / scale)


def far_away(step, radius: float = 3.0) -> bool:
    """End the episode once the robot is farther than ``radius`` from the goal."""
    return step.distance > radius


@pytest.fixture
def user_terms():
    module = types.ModuleType("my_terms")
    module.heading_error = heading_error  # type: ignore[attr-defined]
    module.far_away = far_away  # type: ignore[attr-defined]
    sys.modules["my_terms"] = module
    yield
    sys.modules.pop("my_terms")


def test_how_to_add_a_reward_and_a_termination_term(user_terms):
    task = {
        "name": "nav",
        "reward": {"heading": {"weight": 1.0, "func": "my_terms:heading_error", "params": {"scale": 0.5}}},
        "terminations": {"far": {"func": "my_terms:far_away", "params": {"radius": 1.2}}},
    }
    env = gym.make(ENV, task=task)
    env.reset(seed=0, options={"scene": Scene(goal=(1.0, 0.0, math.pi / 2))})
    _, reward, terminated, _, info = env.step(np.zeros(6, dtype=np.float32))
    # standing still at the origin: heading error = π/2, the built-in terms keep their weights
    assert info["reward_terms"]["heading"] == pytest.approx(math.exp(-(math.pi / 2) / 0.5))
    assert not terminated
    # walking backwards, the episode ends with the first step that takes the robot past 1.2 m
    for _ in range(5):
        _, _, terminated, _, info = env.step(np.array([-1.0, 0, 0, -1.0, 0, 0], dtype=np.float32))
        x, y, _ = info["pose"]
        assert terminated == (math.hypot(x - 1.0, y) > 1.2)
        if terminated:
            break
    assert info["outcome"] == "far" and x < -0.2
    env.close()
