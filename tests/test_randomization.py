import math

import numpy as np
import pytest

from footsim import config as fconf
from footsim.env import FootstepEnv
from footsim.randomization import Randomizer, TermSpec, parse_terms


def test_distributions_have_the_configured_statistics():
    rng = np.random.default_rng(0)
    uni = TermSpec.from_mapping("foot_friction", {"dist": "uniform", "low": 0.5, "high": 1.5}, "r")
    log = TermSpec.from_mapping("floor_friction", {"dist": "loguniform", "low": 0.5, "high": 2.0}, "r")
    nor = TermSpec.from_mapping("torso_com_offset_x", {"dist": "normal", "mean": 0.01, "std": 0.005}, "r")
    u = np.array([uni.sample(rng) for _ in range(20000)])
    logs = np.array([log.sample(rng) for _ in range(20000)])
    n = np.array([nor.sample(rng) for _ in range(20000)])
    assert u.min() >= 0.5 and u.max() <= 1.5 and u.mean() == pytest.approx(1.0, abs=0.01)
    assert np.log(logs).mean() == pytest.approx(0.5 * (math.log(0.5) + math.log(2.0)), abs=0.01)
    assert n.mean() == pytest.approx(0.01, abs=2e-4) and n.std() == pytest.approx(0.005, rel=0.03)


@pytest.mark.parametrize(
    "cfg,msg",
    [
        ({"dist": "uniform", "low": 2, "high": 1}, "low"),
        ({"dist": "gamma", "low": 0, "high": 1}, "dist must be one of"),
        ({"dist": "normal", "mean": 0}, "missing \\['std'\\]"),
        ({"dist": "uniform", "low": 0, "high": 1, "when": "sometimes"}, "when must be"),
    ],
)
def test_bad_term_configs_name_the_key(cfg, msg):
    with pytest.raises(ValueError, match=msg):
        TermSpec.from_mapping("foot_friction", cfg, "randomization.terms_3d")


def test_unknown_term_and_unsupported_term_fail_naming_term_and_backend():
    with pytest.raises(ValueError, match="gravity_scale: unknown randomization term"):
        parse_terms({"terms_3d": {"gravity_scale": {"dist": "constant", "value": 1}}}, "terms_3d")
    with pytest.raises(
        ValueError, match="backend 'pymunk' cannot apply randomization term\\(s\\) \\['foot_friction'\\]"
    ):
        FootstepEnv(randomization={"terms_2d": {"foot_friction": {"dist": "constant", "value": 1.0}}})
    with pytest.raises(ValueError, match="cannot apply"):
        Randomizer(
            parse_terms({"terms_2d": {"push_force": {"dist": "constant", "value": 1}}}, "terms_2d"),
            "pymunk",
            frozenset({"footstep_noise_x"}),
        )


def test_footstep_noise_moves_the_landings_with_the_drawn_sigma():
    sigma = 0.02
    env = FootstepEnv(randomization={"terms_2d": {"footstep_noise_x": {"dist": "constant", "value": sigma}}})
    clean = FootstepEnv()
    errors = []
    for seed in range(40):
        obs, info = env.reset(seed=seed)
        clean.reset(seed=seed)
        assert info["randomization"] == {"footstep_noise_x": sigma}
        for _ in range(5):
            a = np.array([0.5, 0, 0, 0.5, 0, 0])
            _, _, t1, _, i1 = env.step(a)
            _, _, t2, _, i2 = clean.step(a)
        # heading and lateral position stay exact: only x is perturbed
        errors.append(i1["pose"][0] - i2["pose"][0])
        assert i1["pose"][2] == pytest.approx(i2["pose"][2], abs=1e-12)
    errors = np.array(errors)
    # 10 footsteps, nav pose = mean of the feet: the final x error has σ = sigma * sqrt(sum of weights²)
    assert 0.5 * sigma < errors.std() < 3 * sigma
    assert abs(errors.mean()) < errors.std()


def test_walk_freq_scale_changes_the_double_step_time_and_values_are_reproducible():
    cfg = {"terms_2d": {"walk_freq_scale": {"dist": "uniform", "low": 0.5, "high": 2.0}}}
    a, b = FootstepEnv(randomization=cfg), FootstepEnv(randomization=cfg)
    _, ia = a.reset(seed=3)
    _, ib = b.reset(seed=3)
    assert ia["randomization"] == ib["randomization"]
    scale = ia["randomization"]["walk_freq_scale"]
    _, _, _, _, info = a.step(np.zeros(6))
    assert info["time_s"] == pytest.approx(1 / (1.9633 * scale))
    _, ic = a.reset(seed=4)
    assert ic["randomization"] != ia["randomization"]


def test_per_step_terms_are_redrawn_every_step():
    cfg = {"terms_2d": {"footstep_noise_y": {"dist": "uniform", "low": 0.0, "high": 0.01, "when": "step"}}}
    env = FootstepEnv(randomization=cfg)
    env.reset(seed=0)
    seen = {env.step(np.zeros(6))[4]["randomization"]["footstep_noise_y"] for _ in range(5)}
    assert len(seen) == 5


def test_presets_load_and_none_reports_nothing():
    env = FootstepEnv(randomization="default")
    _, info = env.reset(seed=0)
    assert set(info["randomization"]) == {
        "footstep_noise_x",
        "footstep_noise_y",
        "footstep_noise_theta",
        "walk_freq_scale",
    }
    _, info = FootstepEnv(randomization="none").reset(seed=0)
    assert "randomization" not in info
    FootstepEnv(randomization="strong").reset(seed=0)


def test_the_rolling_preset_is_default_plus_the_rolling_friction():
    default, rolling = (fconf.load_preset("randomization", n) for n in ("default", "rolling"))
    assert rolling["terms_2d"] == default["terms_2d"]
    extra = {k: v for k, v in rolling["terms_3d"].items() if k not in default["terms_3d"]}
    assert {k: v for k, v in rolling["terms_3d"].items() if k in default["terms_3d"]} == default["terms_3d"]
    assert extra == {"rolling_friction_scale": {"dist": "loguniform", "low": 0.05, "high": 1.0}}
