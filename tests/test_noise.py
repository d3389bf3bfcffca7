"""Observation noise: thesis Gaussian, per-episode bias, delay; presets and validation."""

import math

import numpy as np
import pytest

from footsim.config import build_noise, load_preset
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D, wrap_angles
from footsim.tasks.noise import NoiseModel


def _walk(n, seed=0):
    rng = np.random.default_rng(seed)
    return [Pose2D(*rng.uniform(-2, 2, size=2), float(rng.uniform(-3, 3))) for _ in range(n)]


def test_bias_is_constant_within_an_episode():
    noise = NoiseModel(bias_sigma_x=0.1, bias_sigma_y=0.2, bias_sigma_theta=0.3)
    rng = np.random.default_rng(1)
    noise.reset(rng)
    offsets = np.array([p.relative(noise.believe(p, rng)) for p in _walk(50)])
    assert np.allclose(offsets, offsets[0], atol=1e-12)  # the same robot-frame offset every step
    assert np.allclose(offsets[0], noise.bias, atol=1e-12) and np.linalg.norm(offsets[0]) > 0


def test_bias_is_resampled_per_episode_with_the_configured_sigma():
    sigmas = (0.1, 0.2, 0.3)
    noise = NoiseModel(bias_sigma_x=sigmas[0], bias_sigma_y=sigmas[1], bias_sigma_theta=sigmas[2])
    rng = np.random.default_rng(2)
    true = Pose2D(1.0, -0.5, 2.0)
    biases = []
    for _ in range(5000):
        noise.reset(rng)
        biases.append(true.relative(noise.believe(true, rng)))
    biases = np.array(biases)
    assert len(np.unique(biases[:, 0])) == len(biases)  # a new bias every episode
    assert biases.mean(axis=0) == pytest.approx([0, 0, 0], abs=0.02)
    assert biases.std(axis=0) == pytest.approx(sigmas, rel=0.05)


def test_bias_plus_gaussian_keeps_both_spreads():
    noise = NoiseModel(0.05, 0.03, 0.07, bias_sigma_x=0.2)
    rng = np.random.default_rng(3)
    true = Pose2D(0.3, 0.2, -1.0)
    noise.reset(rng)
    within = np.array([true.relative(noise.believe(true, rng)) for _ in range(5000)])
    assert within.std(axis=0) == pytest.approx([0.05, 0.03, 0.07], rel=0.05)  # per-step spread only
    assert within[:, 0].mean() == pytest.approx(noise.bias.x, abs=0.005)


@pytest.mark.parametrize("k", [1, 3])
def test_delay_returns_exactly_the_pose_from_k_steps_earlier(k):
    poses = _walk(20)
    noise = NoiseModel(delay_steps=k)
    noise.reset(np.random.default_rng(0))
    out = [noise.believe(p, None) for p in poses]
    for t, got in enumerate(out):
        assert got == poses[max(t - k, 0)]  # before k steps: the episode's first pose
    # a new episode forgets the previous one
    noise.reset(np.random.default_rng(0))
    assert noise.believe(Pose2D(9.0, 9.0, 0.0), None) == Pose2D(9.0, 9.0, 0.0)


def test_delay_delays_the_noisy_belief_and_keeps_the_noise_stream():
    poses = _walk(15, seed=4)
    plain, delayed = NoiseModel(0.05, 0.03, 0.07), NoiseModel(0.05, 0.03, 0.07, delay_steps=2)
    rng_a, rng_b = np.random.default_rng(7), np.random.default_rng(7)
    plain.reset(rng_a)
    delayed.reset(rng_b)
    a = [plain.believe(p, rng_a) for p in poses]
    b = [delayed.believe(p, rng_b) for p in poses]
    assert b[2:] == a[:-2] and b[0] == b[1] == b[2] == a[0]


def test_env_observes_the_delayed_pose():
    env = FootstepEnv(noise={"delay_steps": 2})
    _, info = env.reset(seed=0)
    truth = [info["pose"]]
    estimates = [info["pose_estimate"]]
    rng = np.random.default_rng(0)
    for _ in range(6):
        _, _, term, trunc, info = env.step(rng.uniform(-1, 1, 6))
        truth.append(info["pose"])
        estimates.append(info["pose_estimate"])
        if term or trunc:
            break
    assert len(truth) > 3
    for t in range(len(truth)):
        np.testing.assert_array_equal(estimates[t], truth[max(t - 2, 0)])


def test_env_bias_per_episode_and_reproducible():
    def episode_offsets(env, seed):
        _, info = env.reset(seed=seed)
        offsets = [Pose2D(*info["pose"]).relative(Pose2D(*info["pose_estimate"]))]
        for _ in range(4):
            _, _, term, trunc, info = env.step(np.zeros(6))
            offsets.append(Pose2D(*info["pose"]).relative(Pose2D(*info["pose_estimate"])))
            if term or trunc:
                break
        return np.array(offsets)

    cfg = {"bias_sigma_x": 0.1, "bias_sigma_y": 0.1, "bias_sigma_theta": 0.1}
    env = FootstepEnv(noise=cfg)
    first = episode_offsets(env, seed=1)
    second = episode_offsets(env, seed=2)
    assert np.allclose(first, first[0]) and np.allclose(second, second[0])
    assert not np.allclose(first[0], second[0])
    again = episode_offsets(FootstepEnv(noise=cfg), seed=1)
    np.testing.assert_array_equal(first, again)


def test_presets():
    thesis = load_preset("noise", "localization")
    assert (thesis["sigma_x"], thesis["sigma_y"], thesis["sigma_theta"]) == (0.05, 0.03, 0.07)
    assert thesis["delay_steps"] == 0 and thesis["bias_sigma_x"] == thesis["bias_sigma_theta"] == 0
    biased = build_noise(load_preset("noise", "localization_biased"))
    assert biased.biased and biased.gaussian and biased.delay_steps == 0
    delayed = build_noise(load_preset("noise", "localization_delayed"))
    assert delayed.delay_steps >= 1 and not delayed.biased and delayed.sigma_x == 0.05
    assert not build_noise(load_preset("noise", "none")).active
    fused = build_noise(load_preset("noise", "localization_odometry"))
    assert (fused.sigma_x, fused.sigma_y, fused.sigma_theta) == (0.05, 0.03, 0.07) and fused.odometry_weight == 0.6
    assert all(build_noise(load_preset("noise", n)).odometry_weight == 0 for n in ("localization", "none"))
    for name in ("localization_biased", "localization_delayed", "localization_odometry"):
        FootstepEnv(noise=name).reset(seed=0)


@pytest.mark.parametrize(("weight", "heading"), [(0.6, 0.0), (0.8, 0.0), (0.6, math.pi / 2)])
def test_odometry_fusion_shrinks_the_spread_as_a_first_order_filter(weight, heading):
    """With exact odometry the estimate's error follows e_t = w e_(t-1) + (1 - w) n_t, whose stationary
    spread is σ √((1 - w) / (1 + w)) (hand-derived).  The robot walks straight ahead, so at heading 0 the
    robot-frame noise is the world-frame error and at π/2 its x and y swap (odometry added in the
    world frame instead of the robot's would drift 4 cm a step off there)."""
    sigmas = (0.05, 0.03, 0.07)
    noise = NoiseModel(sigma_x=sigmas[0], sigma_y=sigmas[1], sigma_theta=sigmas[2], odometry_weight=weight)
    rng = np.random.default_rng(5)
    noise.reset(rng)
    step = Pose2D(0.04, 0.0, 0.0)
    true, errors = Pose2D(0.0, 0.0, heading), []
    noise.believe(true, rng)  # the first step has no odometry: the measurement itself
    for _ in range(40000):
        true = true.compose(step)
        believed = noise.believe(true, rng, odometry=step)
        errors.append((believed.x - true.x, believed.y - true.y, wrap_angles(believed.theta - true.theta)))
    spread = np.array(errors[100:]).std(axis=0)
    world = sigmas if heading == 0.0 else (sigmas[1], sigmas[0], sigmas[2])
    # x and y carry a little of the heading error through the 4 cm odometry: 2 % leeway besides 3 % sampling
    np.testing.assert_allclose(spread, np.array(world) * math.sqrt((1 - weight) / (1 + weight)), rtol=0.05)
    silent = NoiseModel(odometry_weight=weight)  # no noise: nothing to fuse, the true pose
    silent.reset(rng)
    assert silent.believe(true, rng, odometry=Pose2D(1.0, 0.0, 0.0)) == true


def _odometry_seen(env, n_steps, seed):
    """(true poses, odometry) the env hands its noise model over ``n_steps`` random steps from a reset."""
    seen = []
    believe = env.noise.believe

    def spy(pose, rng, odometry=None):
        seen.append((pose, odometry))
        return believe(pose, rng, odometry)

    env.noise.believe = spy
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(n_steps):
        env.step(rng.uniform(-0.5, 0.5, size=6))
    env.noise.believe = believe
    return [p for p, _ in seen], [o for _, o in seen]


def test_env_passes_the_walks_odometry_to_the_noise_model():
    """In plain 2D the feet land as planned, so the odometry the env hands the noise model is the true
    displacement of the navigation pose (robot frame); the first step of each episode has none.  With
    footstep-landing randomization the feet land elsewhere, and the odometry stays the planned one."""
    env = FootstepEnv(noise="localization_odometry")
    for seed in (4, 5):  # a second episode starts without odometry again
        poses, odometry = _odometry_seen(env, 6, seed)
        assert odometry[:2] == [None, None]  # at reset and after the first step: no odometry yet
        for before, after, odo in zip(poses[1:], poses[2:], odometry[2:]):
            np.testing.assert_allclose(odo, before.relative(after), atol=1e-9)

    randomized = FootstepEnv(noise="localization_odometry", randomization="default")
    poses, odometry = _odometry_seen(randomized, 6, 4)
    truth = [before.relative(after) for before, after in zip(poses[1:], poses[2:])]
    assert all(o is not None for o in odometry[2:])
    assert (
        max(np.abs(np.subtract(o, t)).max() for o, t in zip(odometry[2:], truth)) > 1e-3
    )  # blind to the landing noise
    assert max(np.abs(np.subtract(o, t)).max() for o, t in zip(odometry[2:], truth)) < 0.1  # but the same steps


def test_switching_bias_on_does_not_change_the_scenes():
    a = FootstepEnv(noise="localization")
    b = FootstepEnv(noise="localization_biased")
    a.reset(seed=3)
    b.reset(seed=3)
    assert a.scene == b.scene


@pytest.mark.parametrize(
    "cfg,message",
    [
        ({"delay_steps": -1}, "noise.delay_steps must be an integer >= 0"),
        ({"delay_steps": 1.5}, "noise.delay_steps must be an integer >= 0"),
        ({"delay_steps": True}, "noise.delay_steps must be an integer >= 0"),
        ({"delay_steps": "2"}, "noise.delay_steps must be an integer >= 0"),
        ({"bias_sigma_x": -0.1}, "noise.bias_sigma_x must be a number >= 0"),
        ({"bias_sigma_theta": math.inf}, "noise.bias_sigma_theta"),
        ({"bias_sigma_y": "a"}, "noise.bias_sigma_y"),
        ({"bias": 0.1}, r"noise: unknown key\(s\) \['bias'\]"),
        ({"odometry_weight": 1.0}, r"noise.odometry_weight must be a number in \[0, 1\)"),
        ({"odometry_weight": -0.1}, r"noise.odometry_weight must be a number in \[0, 1\)"),
        ({"odometry_weight": True}, r"noise.odometry_weight must be a"),
    ],
)
def test_invalid_values_name_the_key(cfg, message):
    with pytest.raises(ValueError, match=message):
        FootstepEnv(noise=cfg)
    with pytest.raises(ValueError, match=message):
        build_noise(cfg)
