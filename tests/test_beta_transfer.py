import json
import subprocess

import numpy as np
import pytest
import torch as th
from budgets import tiny_training
from stable_baselines3 import PPO

from footsim.env import FootstepEnv
from footsim.rl.beta import BetaActorCriticPolicy, BetaDistribution

TINY = tiny_training(128, "eval.after_train=false")


def test_log_prob_and_entropy_match_torch_beta_rescaled():
    low, high = np.array([-1.0, -2.0, 0.0]), np.array([1.0, 2.0, 0.5])
    dist = BetaDistribution(3, low, high)
    params = th.randn(5, 6)
    dist.proba_distribution(params)
    alpha = th.nn.functional.softplus(params[:, :3]) + 1
    beta = th.nn.functional.softplus(params[:, 3:]) + 1
    reference = th.distributions.TransformedDistribution(
        th.distributions.Beta(alpha, beta),
        th.distributions.AffineTransform(th.tensor(low, dtype=th.float32), th.tensor(high - low, dtype=th.float32)),
    )
    actions = reference.sample()
    np.testing.assert_allclose(dist.log_prob(actions), reference.log_prob(actions).sum(-1), rtol=1e-5, atol=1e-5)
    # entropy of a·X + b is H(X) + log|a|
    expected = (th.distributions.Beta(alpha, beta).entropy() + th.log(th.tensor(high - low))).sum(-1)
    np.testing.assert_allclose(dist.entropy(), expected, rtol=1e-5)
    assert th.all(alpha > 1) and th.all(beta > 1)


def test_samples_never_leave_the_bounds_and_mode_is_the_beta_mode():
    dist = BetaDistribution(6, -np.ones(6), np.ones(6))
    params = th.randn(2000, 12, generator=th.Generator().manual_seed(0)) * 5
    # near-uniform rows: α = 1 + 2⁻²³ beside β = 1, where float32's α + β − 2 is 0 (the mode is the
    # upper bound), and α = β = 1 exactly (uniform: the middle)
    params[0, :6] = -15.9
    params[0, 6:] = -40.0
    params[1, :] = -120.0
    dist.proba_distribution(params)
    samples = dist.sample()
    assert th.all(samples > -1) and th.all(samples < 1)
    a = dist.distribution.concentration1.numpy()
    b = dist.distribution.concentration0.numpy()
    assert np.all(a[0] > 1) and np.all(b[0] == 1) and np.all(a[1] == 1) and np.all(b[1] == 1)
    assert np.all(a[0] + b[0] - 2 == 0)  # the float32 edge: the textbook formula divides by zero there
    with np.errstate(invalid="ignore", divide="ignore"):
        expected = -1 + 2 * (a - 1) / (a + b - 2)  # numpy, float32, as the policy computes it
    expected[:2] = [[1.0] * 6, [0.0] * 6]  # by hand: the bound on α's side, and the middle
    np.testing.assert_allclose(dist.mode(), expected, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(dist.mode()[:2].numpy(), np.array([[1.0] * 6, [0.0] * 6], dtype=np.float32))


def test_the_mode_of_a_uniform_beta_is_the_middle_not_nan():
    """A head output so negative that softplus underflows gives α = β = 1 exactly (uniform): the mode
    formula's 0/0 must not reach the env as a NaN action (a training run's validation failed on it)."""
    dist = BetaDistribution(3, np.array([-1.0, 0.0, -0.5]), np.array([1.0, 2.0, 0.5]))
    params = th.tensor([[-120.0, -120.0, 0.0, -120.0, -120.0, -120.0]])  # α = (1, 1, 1.69), β = (1, 1, 1)
    alpha, beta = dist.concentrations(params)
    assert alpha[0, 0] == 1.0 and beta[0, 0] == 1.0  # the underflow itself, in float32
    mode = dist.mode_of(params)[0]
    assert th.all(th.isfinite(mode))
    np.testing.assert_allclose(mode[:2], [0.0, 1.0], atol=1e-6)  # the middle of [-1, 1] and [0, 2]
    assert mode[2] == pytest.approx(0.5)  # α > 1 = β: the mode is the upper bound, as before


def test_beta_policy_learns_saves_and_loads(tmp_path):
    env = FootstepEnv()
    model = PPO(BetaActorCriticPolicy, env, n_steps=64, batch_size=64, n_epochs=1, device="cpu", seed=0)
    model.learn(128)
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, deterministic=True)
    model.save(tmp_path / "beta.zip")
    loaded = PPO.load(tmp_path / "beta.zip", device="cpu")
    assert isinstance(loaded.policy, BetaActorCriticPolicy)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], action)
    assert np.all(np.abs(action) <= 1)


def test_the_mean_action_is_the_beta_mean_and_is_saved_with_the_model(tmp_path):
    env = FootstepEnv()
    low, high = env.action_space.low, env.action_space.high
    model = PPO(
        BetaActorCriticPolicy,
        env,
        n_steps=64,
        batch_size=64,
        n_epochs=1,
        device="cpu",
        seed=0,
        policy_kwargs={"deterministic_action": "mean"},
    )
    model.learn(64)
    obs, _ = env.reset(seed=1)
    with th.no_grad():  # alpha and beta of the head, by hand: softplus + 1 of its two halves
        latent = model.policy.mlp_extractor.forward_actor(th.as_tensor(obs[None], dtype=th.float32))
        a, b = th.chunk(model.policy.action_net(latent)[0], 2)
        alpha, beta = th.nn.functional.softplus(a) + 1, th.nn.functional.softplus(b) + 1
    mean = low + (high - low) * (alpha / (alpha + beta)).numpy()
    mode = low + (high - low) * ((alpha - 1) / (alpha + beta - 2)).numpy()
    np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], mean, rtol=1e-5, atol=1e-6)
    model.save(tmp_path / "mean.zip")
    loaded = PPO.load(tmp_path / "mean.zip", device="cpu")
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], mean, rtol=1e-5, atol=1e-6)
    loaded.policy.action_dist.deterministic_action = "mode"
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], mode, rtol=1e-5, atol=1e-6)
    # the mean lies between the mode and the middle of the box
    middle = (low + high) / 2
    assert np.all(np.abs(mean - middle) <= np.abs(mode - middle) + 1e-6)


def _train(tmp_path, name, *overrides):
    run_dir = tmp_path / name
    proc = subprocess.run(
        ["footsim-train", *TINY, *overrides, f"hydra.run.dir={run_dir}"], capture_output=True, text=True, timeout=300
    )
    return run_dir, proc


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
@pytest.mark.parametrize("agent", ["ppo", "ppo_beta"])
def test_init_from_copies_weights_and_records_the_parent(tmp_path, agent, tiny_runs):
    parent = tiny_runs(agent, f"agent={agent}")
    # weights copied exactly into a fresh model
    from footsim.rl.transfer import init_from_run

    cls = BetaActorCriticPolicy if agent == "ppo_beta" else "MlpPolicy"
    from omegaconf import OmegaConf

    from footsim.config import load_preset
    from footsim.rl.common import policy_kwargs

    agent_cfg = OmegaConf.create(load_preset("agent", agent))
    fresh = PPO(cls, FootstepEnv(), policy_kwargs=policy_kwargs(agent_cfg), device="cpu", seed=3)
    record = init_from_run(fresh, parent)
    saved = PPO.load(parent / "model.zip", device="cpu")
    for (k, v), (k2, v2) in zip(fresh.policy.state_dict().items(), saved.policy.state_dict().items()):
        assert k == k2 and th.equal(v, v2)
    assert record["parent_backend"] == "pymunk"

    child, proc = _train(tmp_path, "child", f"agent={agent}", f"init_from={parent}")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads((child / "parent.json").read_text())["init_from"] == str(parent)


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_init_from_with_mismatched_spaces_or_distribution_fails_clearly(tmp_path, tiny_runs):
    parent = tiny_runs("ppo", "agent=ppo")
    obstacle_parent = tiny_runs("ppo_obstacles", "task=nav_obstacles")
    _, proc = _train(tmp_path, "child", "task=nav", f"init_from={obstacle_parent}")
    assert proc.returncode != 0 and "observation spaces differ" in proc.stderr
    _, proc = _train(tmp_path, "child2", "agent=ppo_beta", f"init_from={parent}")
    assert proc.returncode != 0 and "agent=ppo or agent=ppo_beta" in proc.stderr


def test_obstacle_free_parent_seeds_an_obstacle_run_with_zero_ray_weights(tmp_path):
    from footsim.rl.transfer import init_from_run

    parent_env, child_env = FootstepEnv(), FootstepEnv(obstacles=True)
    parent = PPO("MlpPolicy", parent_env, device="cpu", seed=0)
    parent.save(tmp_path / "model.zip")
    (tmp_path / "config.yaml").write_text("backend: {name: pymunk}\ntask: {name: nav}\n")
    child = PPO("MlpPolicy", child_env, device="cpu", seed=1)
    record = init_from_run(child, tmp_path)
    assert record["observation_expanded"] == "17 -> 53"
    # the child acts exactly like the parent whatever the rays say
    obs, _ = child_env.reset(seed=0)
    rays_changed = obs.copy()
    rays_changed[17:] = 0.1
    expected = parent.predict(obs[:17], deterministic=True)[0]
    np.testing.assert_allclose(child.predict(obs, deterministic=True)[0], expected, atol=1e-6)
    np.testing.assert_allclose(child.predict(rays_changed, deterministic=True)[0], expected, atol=1e-6)


def test_normalization_statistics_widen_with_the_observation(tmp_path):
    """A parent that normalizes its 17-D observation seeds a 53-D child that normalizes too: the
    parent's statistics cover the first 17 inputs, the rays get mean 0 / variance 1, and the child's
    normalized observation and action equal the parent's."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from footsim.rl.transfer import init_from_run

    parent_venv = VecNormalize(DummyVecEnv([FootstepEnv]), norm_obs=True, norm_reward=False)
    parent = PPO("MlpPolicy", parent_venv, n_steps=64, batch_size=64, n_epochs=1, device="cpu", seed=0)
    parent.learn(64)  # the running statistics move away from (0, 1)
    parent.save(tmp_path / "model.zip")
    parent_venv.save(tmp_path / "vecnormalize.pkl")
    (tmp_path / "config.yaml").write_text("backend: {name: pymunk}\ntask: {name: nav}\n")
    child_venv = VecNormalize(DummyVecEnv([lambda: FootstepEnv(obstacles=True)]), norm_obs=True, norm_reward=False)
    child = PPO("MlpPolicy", child_venv, device="cpu", seed=1)
    record = init_from_run(child, tmp_path)
    assert record["copied_obs_normalization"] and record["observation_expanded"] == "17 -> 53"

    rms = child_venv.obs_rms
    np.testing.assert_array_equal(rms.mean[:17], parent_venv.obs_rms.mean)
    np.testing.assert_array_equal(rms.var[:17], parent_venv.obs_rms.var)
    assert np.all(rms.mean[17:] == 0.0) and np.all(rms.var[17:] == 1.0)
    assert not np.allclose(parent_venv.obs_rms.var, 1.0)  # the first block really was rescaled
    obs, _ = FootstepEnv(obstacles=True).reset(seed=0)
    child_venv.training = parent_venv.training = False
    norm_child, norm_parent = child_venv.normalize_obs(obs), parent_venv.normalize_obs(obs[:17])
    np.testing.assert_allclose(norm_child[:17], norm_parent, rtol=1e-6)
    expected = parent.predict(norm_parent, deterministic=True)[0]
    np.testing.assert_allclose(child.predict(norm_child, deterministic=True)[0], expected, atol=1e-6)


def test_obstacle_parent_seeds_a_path_hint_run_but_not_an_incompatible_layout(tmp_path):
    """Prefix rule: 53-D (goal+rays) seeds 55-D (goal+rays+hint) with zero hint weights; a parent
    with the IMU block (56-D) cannot seed a larger goal+rays+hint run (59-D), whose blocks differ."""
    from footsim.rl.transfer import init_from_run

    obstacle_task = {"name": "nav_obstacles", "obstacles": True, "n_rays": 36}
    parent_env = FootstepEnv(obstacles=True)
    parent = PPO("MlpPolicy", parent_env, device="cpu", seed=0)
    parent.save(tmp_path / "model.zip")
    (tmp_path / "config.yaml").write_text(
        "backend: {name: pymunk}\ntask: {name: nav_obstacles, obstacles: true, n_rays: 36}\n"
    )
    hint_task = dict(obstacle_task, path_hint=True)
    child_env = FootstepEnv(task=hint_task)
    child = PPO("MlpPolicy", child_env, device="cpu", seed=1)
    record = init_from_run(child, tmp_path, hint_task)
    assert record["observation_expanded"] == "53 -> 55"
    obs, _ = child_env.reset(seed=0)
    hint_changed = obs.copy()
    hint_changed[53:] = (0.7, -0.7)
    expected = parent.predict(obs[:53], deterministic=True)[0]
    np.testing.assert_allclose(child.predict(obs, deterministic=True)[0], expected, atol=1e-6)
    np.testing.assert_allclose(child.predict(hint_changed, deterministic=True)[0], expected, atol=1e-6)

    imu_dir = tmp_path / "imu"
    imu_dir.mkdir()
    imu_parent = PPO("MlpPolicy", FootstepEnv(task=dict(obstacle_task, observe_imu=True)), device="cpu", seed=0)
    imu_parent.save(imu_dir / "model.zip")
    (imu_dir / "config.yaml").write_text(
        "backend: {name: pymunk}\ntask: {name: nav_obstacles, obstacles: true, n_rays: 36, observe_imu: true}\n"
    )
    wide_task = dict(obstacle_task, path_hint=True, n_rays=40)  # 59-D: larger, but rays differ
    wide = PPO("MlpPolicy", FootstepEnv(task=wide_task), device="cpu", seed=1)
    with pytest.raises(ValueError, match="goal_and_actions\\+rays\\+imu"):
        init_from_run(wide, imu_dir, wide_task)


def test_reset_log_std_reopens_exploration_after_a_warm_start_and_refuses_beta():
    from footsim.rl.transfer import reset_log_std

    model = PPO("MlpPolicy", FootstepEnv(), policy_kwargs={"log_std_init": -2.0}, device="cpu", seed=0)
    obs, _ = FootstepEnv().reset(seed=0)
    mean_before = model.predict(obs, deterministic=True)[0]
    reset_log_std(model, -0.5)
    # every action dimension's std is e^-0.5, the mean is untouched
    dist = model.policy.get_distribution(model.policy.obs_to_tensor(obs)[0])
    np.testing.assert_allclose(dist.distribution.stddev.detach().numpy(), np.exp(-0.5), rtol=1e-6)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], mean_before)
    beta = PPO(BetaActorCriticPolicy, FootstepEnv(), device="cpu", seed=0)
    with pytest.raises(ValueError, match="agent=ppo"):
        reset_log_std(beta, -0.5)


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_runs")
def test_footsim_eval_takes_the_beta_action_and_refuses_it_for_a_gaussian_policy(tmp_path, tiny_runs):
    from footsim.rl.common import LoadedPolicy

    beta_run = tiny_runs("ppo_beta", "agent=ppo_beta")
    obs = np.linspace(-1, 1, 17).astype(np.float32)
    trained, mean = LoadedPolicy(beta_run), LoadedPolicy(beta_run, beta_action="mean")
    # an independent route: SB3's predict on the observation normalized by hand, the head switched to its mean
    model = PPO.load(beta_run / "model.zip", device="cpu")
    model.policy.action_dist.deterministic_action = "mean"
    seen = obs
    if trained.obs_rms is not None:
        rms = trained.obs_rms
        seen = np.clip((obs - rms.mean) / np.sqrt(rms.var + trained.epsilon), -trained.clip_obs, trained.clip_obs)
    np.testing.assert_allclose(mean(obs), model.predict(seen, deterministic=True)[0], rtol=1e-5, atol=1e-6)
    assert not np.allclose(trained(obs), mean(obs))  # trained with the mode
    with pytest.raises(ValueError, match="is not a Beta policy"):
        LoadedPolicy(tiny_runs("ppo", "agent=ppo"), beta_action="mean")
    out = tmp_path / "eval"
    proc = subprocess.run(
        ["footsim-eval", f"run={beta_run}", "n_scenes=3", "plot=false", "beta_action=mean", f"hydra.run.dir={out}"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Beta mean" in json.loads((out / "summary.json").read_text())["label"]


def test_obstacle_parent_seeds_a_history_run_that_acts_as_the_parent(tmp_path):
    """53-D (goal+rays) seeds goal+rays+history (135-D with 2 earlier observations): the history
    inputs start at zero weight, so whatever they hold the child acts as the parent."""
    from footsim.rl.transfer import init_from_run

    parent = PPO(BetaActorCriticPolicy, FootstepEnv(obstacles=True), device="cpu", seed=0)
    parent.save(tmp_path / "model.zip")
    (tmp_path / "config.yaml").write_text(
        "backend: {name: pymunk}\ntask: {name: nav_obstacles, obstacles: true, n_rays: 36}\n"
    )
    history_task = {"name": "nav_obstacles", "obstacles": True, "n_rays": 36, "observe_history": 2}
    child_env = FootstepEnv(task=history_task)
    child = PPO(BetaActorCriticPolicy, child_env, device="cpu", seed=1)
    record = init_from_run(child, tmp_path, history_task)
    assert record["observation_expanded"] == "53 -> 135"
    obs, _ = child_env.reset(seed=0)
    history_changed = obs.copy()
    history_changed[53:] = np.linspace(-1, 1, 82)
    expected = parent.predict(obs[:53], deterministic=True)[0]
    np.testing.assert_allclose(child.predict(obs, deterministic=True)[0], expected, atol=1e-6)
    np.testing.assert_allclose(child.predict(history_changed, deterministic=True)[0], expected, atol=1e-6)


def test_a_parent_and_child_that_disagree_on_observation_normalization_are_refused(tmp_path):
    """Weights trained on normalized inputs would read raw ones (or the reverse): named, not copied."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from footsim.rl.transfer import init_from_run

    parent_venv = VecNormalize(DummyVecEnv([FootstepEnv]), norm_obs=True, norm_reward=False)
    parent = PPO("MlpPolicy", parent_venv, device="cpu", seed=0)
    parent.save(tmp_path / "model.zip")
    parent_venv.save(tmp_path / "vecnormalize.pkl")
    (tmp_path / "config.yaml").write_text("backend: {name: pymunk}\ntask: {name: nav}\n")
    child = PPO("MlpPolicy", FootstepEnv(), device="cpu", seed=1)
    before = [p.detach().clone() for p in child.policy.parameters()]
    with pytest.raises(ValueError, match="agent.normalize_obs=true"):
        init_from_run(child, tmp_path)
    assert all(th.equal(a, b) for a, b in zip(before, child.policy.parameters(), strict=True))  # nothing copied
