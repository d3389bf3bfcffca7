import json
import math

import numpy as np
import pymunk
import pytest

from footsim.config import load_preset
from footsim.geometry import Pose2D, wrap_angles
from footsim.scene import Obstacle, Scene
from footsim.tasks import nav
from footsim.tasks.nav import NavTaskConfig
from footsim.tasks.noise import NoiseModel
from footsim.tasks.scenes import SceneSampler, load_scenes, sample_scenes, save_scenes


def test_reward_terms_match_hand_computation():
    scene = Scene(goal=Pose2D(1.0, 0.0, math.pi / 2))
    a = np.array([0.5, 0, 0, 0, 0, 0.0])
    prev = np.array([0.0, 0, 0, 0, 0, 1.0])
    terms = nav.reward_terms(Pose2D(0, 0, 0), scene, a, prev)
    assert terms["distance"] == pytest.approx(math.exp(-0.5))  # d = 1
    assert terms["angle"] == pytest.approx(math.exp(-5) * math.exp(-math.pi / 2))  # α = 90°
    assert terms["orientation"] == pytest.approx(1.0)  # β = 0
    assert terms["obstacle"] == 1.0  # no obstacles
    assert terms["continuity"] == pytest.approx((math.exp(-1.5) + math.exp(-3) + 4) / 6)


def test_orientation_clause_and_obstacle_term_exclude_ball():
    # 0.08 m from the goal, facing away: orientation is 1 by the d < 0.1 clause
    scene = Scene(Pose2D(0.08, 0, 0), obstacles=(Obstacle(0.0, 1.0, 0.5),), ball=Obstacle(0.0, -0.2, 0.1))
    terms = nav.reward_terms(Pose2D(0, 0, math.pi), scene, np.zeros(6), np.zeros(6))
    assert terms["orientation"] == 1.0
    # d_obs = 1.0 - 0.5 = 0.5 to the obstacle; the closer ball (0.1 m away) is ignored
    assert terms["obstacle"] == pytest.approx(math.exp(-0.0015 * 4.0))
    # a larger epsilon (a config param) asks for more clearance: exp(-0.006 / 0.5²)
    config = NavTaskConfig(obstacles=True, reward={"obstacle": {"weight": 1.0, "params": {"epsilon": 0.006}}})
    wider = nav.reward_terms(Pose2D(0, 0, math.pi), scene, np.zeros(6), np.zeros(6), config=config)
    assert wider == pytest.approx({"obstacle": math.exp(-0.006 * 4.0)})
    negative = NavTaskConfig(obstacles=True, reward={"obstacle": {"weight": 1.0, "params": {"epsilon": -0.1}}})
    with pytest.raises(ValueError, match=r"task\.reward\.obstacle\.params\.epsilon must be >= 0, got -0\.1"):
        nav.reward_terms(Pose2D(0, 0, math.pi), scene, np.zeros(6), np.zeros(6), config=negative)
    # measured from a 0.2 m circle around the robot: d_obs = 0.5 - 0.2 = 0.3, exp(-0.0015 / 0.3²)
    outline = NavTaskConfig(obstacles=True, reward={"obstacle": {"weight": 1.0, "params": {"radius": 0.2}}})
    from_circle = nav.reward_terms(Pose2D(0, 0, math.pi), scene, np.zeros(6), np.zeros(6), config=outline)
    assert from_circle == pytest.approx({"obstacle": math.exp(-0.0015 / 0.09)})
    # an obstacle inside that circle: the term's floor, exp(-0.0015 / (1e-6)²) = 0
    touching = Scene(Pose2D(0.08, 0, 0), obstacles=(Obstacle(0.0, 0.6, 0.45),))
    assert nav.reward_terms(Pose2D(0, 0, 0), touching, np.zeros(6), np.zeros(6), config=outline) == {"obstacle": 0.0}
    for bad in (-0.1, math.nan):
        wrong = NavTaskConfig(obstacles=True, reward={"obstacle": {"weight": 1.0, "params": {"radius": bad}}})
        with pytest.raises(ValueError, match=r"task\.reward\.obstacle\.params\.radius must be a number >= 0"):
            nav.reward_terms(Pose2D(0, 0, math.pi), scene, np.zeros(6), np.zeros(6), config=wrong)
    far = nav.reward_terms(Pose2D(0, 0, math.pi), Scene(Pose2D(2, 0, 0)), np.zeros(6), np.zeros(6))
    assert far["orientation"] == pytest.approx(math.exp(-math.pi))


def _weights(preset: str) -> dict[str, float]:
    return {name: entry["weight"] for name, entry in load_preset("task", preset)["reward"].items()}


def test_weight_sets_sum_to_one_and_terms_in_unit_interval():
    assert _weights("nav") == {
        "distance": 0.3,
        "angle": 0.3,
        "orientation": 0.2,
        "obstacle": 0.0,
        "continuity": 0.2,
        "stability": 0.0,
        "contact": 0.0,
    }  # thesis 5.5, and the 3D options off
    assert sum(_weights("nav").values()) == pytest.approx(1)
    assert sum(_weights("nav_obstacles").values()) == pytest.approx(1)
    rng = np.random.default_rng(0)
    sampler = SceneSampler(obstacles=True)
    for _ in range(200):
        scene = sampler.sample(rng)
        pose = Pose2D(*rng.normal(size=2), rng.uniform(-3, 3))
        terms = nav.reward_terms(pose, scene, rng.uniform(-1, 1, 6), rng.uniform(-1, 1, 6))
        assert all(0.0 <= v <= 1.0 for v in terms.values())


def test_observation_layout_and_range():
    cfg = NavTaskConfig(obstacles=True)
    scene = Scene(Pose2D(1.0, 1.0, 0.0), obstacles=(Obstacle(0.0, -1.0, 0.2),), ball=Obstacle(3, 3, 0.1))
    prev = (np.full(6, 0.5), np.full(6, -0.25))
    obs = nav.observation(Pose2D(0, 0, 0), scene, prev, cfg)
    assert obs.shape == (53,) and obs.dtype == np.float32
    assert obs[0] == pytest.approx(math.tanh(math.sqrt(2)))
    assert obs[1:3] == pytest.approx([0.0, 1.0])  # α = 0
    assert obs[3:5] == pytest.approx([math.sin(math.pi / 4), math.cos(math.pi / 4)], abs=1e-6)  # β = 45°
    assert np.all(obs[5:11] == 0.5) and np.all(obs[11:17] == -0.25)
    rays = obs[17:]
    assert rays[27] == pytest.approx(math.tanh(0.8), abs=1e-6)  # ray 27 points at -90°: hits at 0.8 m
    assert rays[0] == pytest.approx(math.tanh(5.0), abs=1e-6)  # nothing ahead: max range
    assert np.all((obs >= -1) & (obs <= 1))
    assert nav.observation(Pose2D(), scene, prev, NavTaskConfig()).shape == (17,)


def test_rays_agree_with_pymunk_segment_queries():
    rng = np.random.default_rng(3)
    sampler = SceneSampler(obstacles=True)
    for _ in range(30):
        scene = sampler.sample(rng)
        pose = Pose2D(*rng.normal(0, 0.5, 2), rng.uniform(-3, 3))
        ours = nav.ray_distances(pose, scene.all_obstacles, 36, 5.0)
        space = pymunk.Space()
        for o in scene.all_obstacles:
            space.add(pymunk.Circle(space.static_body, o.r, (o.x, o.y)))
        inside = any(math.hypot(o.x - pose.x, o.y - pose.y) < o.r for o in scene.all_obstacles)
        if inside:
            continue
        for k in range(36):
            a = pose.theta + math.radians(10 * k)
            end = (pose.x + 5 * math.cos(a), pose.y + 5 * math.sin(a))
            hit = space.segment_query_first((pose.x, pose.y), end, 0, pymunk.ShapeFilter())
            expected = 5.0 if hit is None else hit.alpha * 5.0
            assert ours[k] == pytest.approx(expected, abs=1e-6)


def test_scene_sampler_statistics():
    scenes = sample_scenes(SceneSampler(obstacles=False), 4000, seed=1)
    goals = np.array([s.goal for s in scenes])
    assert goals[:, 0].std() == pytest.approx(1.0, abs=0.05)
    assert goals[:, 1].std() == pytest.approx(1.0, abs=0.05)
    assert abs(goals[:, :2].mean()) < 0.05
    # θ ~ N(0, 1.5) wrapped to (-π, π]: compare with an independently drawn wrapped normal
    reference = wrap_angles(np.random.default_rng(7).normal(0, 1.5, 200000))
    assert goals[:, 2].std() == pytest.approx(reference.std(), abs=0.05)
    assert np.all(np.abs(goals[:, 2]) <= math.pi)


def test_obstacle_scenes_respect_the_thesis_rules():
    sampler = SceneSampler(obstacles=True)
    scenes = sample_scenes(sampler, 500, seed=2)
    radii = np.array([o.r for s in scenes for o in s.obstacles])
    assert radii.min() >= 0.1 and radii.max() <= 0.3 and radii.mean() == pytest.approx(0.2, abs=0.01)
    near_robot = []
    for s in scenes:
        assert len(s.obstacles) == 6
        for o in s.obstacles:
            assert math.hypot(o.x, o.y) >= o.r + sampler.robot_radius
            assert math.hypot(o.x - s.goal.x, o.y - s.goal.y) >= o.r + sampler.robot_radius
        near_robot += [math.hypot(o.x, o.y) for o in s.obstacles[:3]]
        ahead = s.goal.relative(Pose2D(s.ball.x, s.ball.y, 0))
        assert (ahead.x, ahead.y) == pytest.approx((0.2, 0.0))
        assert s.ball.r == 0.075
    assert np.median(near_robot) < 1.0  # the first three cluster around the robot


def test_scene_file_round_trip_and_format(tmp_path):
    scenes = sample_scenes(SceneSampler(obstacles=True), 5, seed=4)
    path = tmp_path / "s.json"
    save_scenes(path, scenes)
    raw = json.loads(path.read_text())
    assert set(raw["scenes"][0]) == {"goal", "obstacles", "ball"}
    assert len(raw["scenes"][0]["obstacles"][0]) == 3
    assert load_scenes(path) == scenes


def test_scene_file_gets_the_umask_permissions_and_a_failed_write_keeps_the_old_file(tmp_path):
    import os
    import stat

    from footsim.utils import atomic_save

    path = tmp_path / "s.json"
    old_umask = os.umask(0o027)
    try:
        save_scenes(path, sample_scenes(SceneSampler(), 2, seed=1))
    finally:
        os.umask(old_umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o640  # 0o666 & ~0o027, not mkstemp's 0o600
    before = path.read_bytes()

    def crash(tmp):
        with open(tmp, "w") as fh:
            fh.write("half a fi")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_save(crash, path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["s.json"]  # no temporary file left behind


def test_scene_from_plain_tuples_equals_the_typed_scene_and_bad_ones_are_named():
    typed = Scene(Pose2D.of(1.0, 2.0, 0.5), (Obstacle(0.5, 0.0, 0.1),), Obstacle(1.0, 1.0, 0.075))
    assert Scene(goal=(1, 2, 0.5), obstacles=[(0.5, 0, 0.1)], ball=[1, 1, 0.075]) == typed
    with pytest.raises(ValueError, match=r"Scene.obstacles\[1\]"):
        Scene(goal=(1, 2, 0), obstacles=[(0.5, 0, 0.1), (0.5, 0)])
    with pytest.raises(ValueError, match="Scene.goal"):
        Scene(goal=(1, 2))


@pytest.mark.parametrize(
    "bad,msg",
    [
        ({"goal": [0, 0]}, "scene 1: 'goal'"),
        ({"goal": [0, 0, "x"]}, "scene 1: 'goal'"),
        ({"goal": [0, 0, 0], "obstacles": [[0, 0, -1]]}, "scene 1: obstacle 0: radius"),
        ({"obstacles": []}, "scene 1: missing key 'goal'"),
    ],
)
def test_malformed_scene_file_names_the_scene(tmp_path, bad, msg):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"scenes": [{"goal": [1, 1, 0], "obstacles": [], "ball": None}, bad]}))
    with pytest.raises(ValueError, match=msg):
        load_scenes(path)


def test_noise_statistics_in_robot_frame():
    noise = NoiseModel(0.05, 0.03, 0.07)
    rng = np.random.default_rng(0)
    true = Pose2D(1.0, 2.0, math.pi / 2)
    samples = np.array([true.relative(noise.believe(true, rng)) for _ in range(20000)])
    assert samples.std(axis=0) == pytest.approx([0.05, 0.03, 0.07], rel=0.05)
    with pytest.raises(ValueError, match="noise.sigma_y"):
        NoiseModel(0.05, -0.1, 0.0)


def test_invalid_sampler_values_name_the_key():
    with pytest.raises(ValueError, match="task.scenes.obstacle_radius_min"):
        SceneSampler(obstacle_radius_min=-0.1)
    with pytest.raises(ValueError, match="task.scenes.goal_sigma_xy"):
        SceneSampler(goal_sigma_xy=0)
