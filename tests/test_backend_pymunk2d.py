"""The 2D backend's closed-form geometry against pymunk's own queries (and the earlier numpy rays).

The hot path tests rectangle–circle overlaps and ray–circle hits in closed form; these tests
compare it with pymunk shape / segment queries on random and near-boundary scenes.
"""

import math

import numpy as np
import pymunk
import pytest

from footsim.backends.pymunk2d import Pymunk2DBackend, box_hits_circles
from footsim.config import build_robot, build_walk, load_preset
from footsim.geometry import Pose2D, mean_pose
from footsim.robots.spec import RobotSpec
from footsim.scene import Obstacle, Scene
from footsim.tasks import nav
from footsim.tasks.scenes import SceneSampler
from footsim.walk.footsteps import DoubleStep


def _pymunk_box_hits(x, y, theta, length, width, circles) -> bool:
    space = pymunk.Space()
    for cx, cy, r in circles:
        space.add(pymunk.Circle(space.static_body, r, (cx, cy)))
    body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    hl, hw = 0.5 * length, 0.5 * width
    shape = pymunk.Poly(body, [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)])
    space.add(body, shape)
    body.position = (x, y)
    body.angle = theta
    space.reindex_shapes_for_body(body)
    return any(hit.shape.body is space.static_body for hit in space.shape_query(shape))


def test_box_circle_overlap_matches_pymunk_shape_queries():
    rng = np.random.default_rng(0)
    near, hits = 0, 0
    for i in range(3000):
        length, width = rng.uniform(0.05, 0.3, 2)
        x, y, theta = *rng.uniform(-2, 2, 2), rng.uniform(-4, 4)
        r = rng.uniform(0.02, 0.4)
        if i % 2:  # centre at a chosen distance from the rectangle's boundary (corners and sides)
            u, v = rng.uniform(-1, 1, 2) * (0.5 * length, 0.5 * width)
            side = rng.integers(4)
            u = [0.5 * length, -0.5 * length, u, u][side]
            v = [v, v, 0.5 * width, -0.5 * width][side]
            phi = rng.uniform(-math.pi, math.pi)
            gap = r + rng.choice([-1, 1]) * rng.choice([1e-6, 1e-4, 1e-2, 0.1])
            u, v = u + gap * math.cos(phi), v + gap * math.sin(phi)
            near += 1
        else:
            u, v = rng.uniform(-0.6, 0.6, 2)
        c, s = math.cos(theta), math.sin(theta)
        circle = (x + c * u - s * v, y + s * u + c * v, r)
        others = [tuple(rng.uniform(-2, 2, 2)) + (rng.uniform(0.02, 0.3),) for _ in range(rng.integers(0, 3))]
        circles = others + [circle]
        expected = _pymunk_box_hits(x, y, theta, length, width, circles)
        assert box_hits_circles(x, y, theta, 0.5 * length, 0.5 * width, circles) == expected, (x, y, theta, circles)
        hits += expected
    assert 500 < hits < 2500 and near == 1500  # both answers well represented


def test_hand_computed_box_circle_cases():
    # 0.2 x 0.1 box at the origin turned by 90°: it reaches 0.1 along y and 0.05 along x
    assert box_hits_circles(0, 0, math.pi / 2, 0.1, 0.05, [(0.0, 0.15, 0.0501)])
    assert not box_hits_circles(0, 0, math.pi / 2, 0.1, 0.05, [(0.0, 0.15, 0.0499)])
    assert not box_hits_circles(0, 0, math.pi / 2, 0.1, 0.05, [(0.1, 0.0, 0.0499)])
    # corner (0.05, 0.1) at distance 0.05·√2 from (0.1, 0.15)
    assert box_hits_circles(0, 0, math.pi / 2, 0.1, 0.05, [(0.1, 0.15, 0.0708)])
    assert not box_hits_circles(0, 0, math.pi / 2, 0.1, 0.05, [(0.1, 0.15, 0.0706)])
    assert box_hits_circles(0, 0, 0, 0.1, 0.05, [(0.01, 0.01, 0.001)])  # centre inside the box
    assert not box_hits_circles(0, 0, 0, 0.1, 0.05, [])


@pytest.mark.parametrize(("radius", "upper_body_hits"), [(0.09, True), (0.08, False)])
def test_upper_body_check_reaches_the_forearms(radius, upper_body_hits):
    # an obstacle ahead of the standing robot, its edge 0.16 m (0.17 m) ahead of the feet's mean: the
    # upper body's box reaches 0.045 + 0.119 = 0.164 m ahead, the feet 0.077 m and the torso 0.075 m
    scene = Scene(Pose2D(2.0, 0.0, 0.0), obstacles=(Obstacle(0.25, 0.0, radius),))
    limits = _make_backend().robot.step_limits
    in_place = DoubleStep.from_action(np.zeros(6), limits)
    for collision_model, expected in (("footprint", False), ("upper_body", upper_body_hits)):
        backend = _make_backend(collision_model=collision_model)
        backend.reset(scene, np.random.default_rng(0))
        assert backend.execute(in_place).collided is expected, collision_model
        # the ball in the obstacle's place stays below the arms: neither check touches it
        backend.reset(Scene(Pose2D(2.0, 0.0, 0.0), ball=Obstacle(0.25, 0.0, radius)), np.random.default_rng(0))
        assert backend.execute(in_place).collided is False, collision_model
    flat = RobotSpec("flat", limits)  # a planar spec without the upper body's figures
    with pytest.raises(ValueError, match="collision_model=upper_body: robot 'flat' has no upper_body_footprint"):
        Pymunk2DBackend(flat, build_walk(load_preset("walk", "pymunk")), collision_model="upper_body")


def _make_backend(**options) -> Pymunk2DBackend:
    return Pymunk2DBackend(
        build_robot(load_preset("robot", "wolfgang")), build_walk(load_preset("walk", "pymunk")), **options
    )


def _pymunk_double_step_collides(backend: Pymunk2DBackend, before, after_first, after_second) -> bool:
    """The six pymunk shape queries of a double step (the backend's original narrow phase)."""
    space = backend.space
    foot, trunk, *upper = sorted((s for s in space.shapes if isinstance(s, pymunk.Poly)), key=lambda s: s.area)

    def hits(shape, pose):
        shape.body.position = (pose.x, pose.y)
        shape.body.angle = pose.theta
        space.reindex_shapes_for_body(shape.body)
        return any(h.shape.body is space.static_body for h in space.shape_query(shape))

    checks = [
        (foot, mean_pose(before.right, after_first.right)),
        (foot, after_first.right),
        (trunk, after_first.nav_pose),
        (foot, mean_pose(after_first.left, after_second.left)),
        (foot, after_second.left),
        (trunk, after_second.nav_pose),
    ]
    checks += [(shape, pose) for shape in upper for pose in (after_first.nav_pose, after_second.nav_pose)]
    return any(hits(shape, pose) for shape, pose in checks)


@pytest.mark.parametrize("collision_model", ["footprint", "upper_body"])
def test_backend_collisions_match_pymunk_shape_queries(collision_model):
    backend = _make_backend(collision_model=collision_model)
    rng = np.random.default_rng(1)
    sampler = SceneSampler(obstacles=True, obstacle_offset_sigma=0.4, obstacle_radius_max=0.4)
    outcomes = []
    for episode in range(150):
        backend.reset(sampler.sample(rng), np.random.default_rng(episode))
        if episode % 3 == 0:
            backend.apply_randomization(
                {"footstep_noise_x": 0.02, "footstep_noise_y": 0.02, "footstep_noise_theta": 0.1}
            )
        for _ in range(30):
            before = backend.feet
            result = backend.execute(DoubleStep.from_action(rng.uniform(-1, 1, 6), backend.robot.step_limits))
            after_first = type(before)(before.left, backend.history[-2][1])
            assert backend.history[-1][1] == result.feet.left
            expected = _pymunk_double_step_collides(backend, before, after_first, result.feet)
            assert result.collided == expected
            outcomes.append(expected)
            if expected:
                break
    assert 30 < sum(outcomes) < len(outcomes) - 300


def _numpy_rays(pose, obstacles, n_rays, max_range):
    """The earlier vectorised implementation (all rays × all circles), kept as a reference."""
    k = np.arange(n_rays) * (2.0 * math.pi / n_rays)
    base = np.stack([np.cos(k), np.sin(k)])
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    rel = np.array(
        [
            [
                c * (o.x - pose.x) + s * (o.y - pose.y),
                -s * (o.x - pose.x) + c * (o.y - pose.y),
                (o.x - pose.x) ** 2 + (o.y - pose.y) ** 2 - o.r * o.r,
            ]
            for o in obstacles
        ]
    )
    proj = rel[:, :2] @ base
    disc = proj * proj - rel[:, 2:3]
    inside = rel[:, 2:3] <= 0.0
    t = proj - np.sqrt(np.maximum(disc, 0.0))
    t = np.where(inside, 0.0, np.where((disc >= 0.0) & (t >= 0.0), t, max_range))
    return np.minimum(t.min(axis=0), max_range)


@pytest.mark.parametrize("n_rays", [1, 3, 36, 37, 360])
def test_rays_match_the_all_pairs_computation(n_rays):
    rng = np.random.default_rng(n_rays)
    sampler = SceneSampler(obstacles=True)
    for i in range(300):
        scene = sampler.sample(rng)
        pose = Pose2D(*rng.normal(0, 1.0, 2), rng.uniform(-math.pi, math.pi))
        max_range = [5.0, 1.0, 0.3][i % 3]
        ours = nav.ray_distances(pose, scene.all_obstacles, n_rays, max_range)
        expected = _numpy_rays(pose, scene.all_obstacles, n_rays, max_range)
        np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-12)


def test_grazing_rays_match_pymunk_segment_queries():
    """Circles placed so that a ray passes just inside or just outside them (± 1 µm)."""
    rng = np.random.default_rng(5)
    n, max_range = 36, 5.0
    grazed = 0
    for _ in range(400):
        pose = Pose2D(*rng.uniform(-1, 1, 2), rng.uniform(-math.pi, math.pi))
        circles = []
        for _ in range(rng.integers(1, 5)):
            k = rng.integers(n)
            heading = pose.theta + k * 2 * math.pi / n
            along, r = rng.uniform(0.3, 4.5), rng.uniform(0.05, 0.4)
            offset = r + rng.choice([-1e-6, 1e-6, -1e-3, 0.05])  # centre's distance from the ray
            side = rng.choice([-1, 1])
            cx = pose.x + along * math.cos(heading) - side * offset * math.sin(heading)
            cy = pose.y + along * math.sin(heading) + side * offset * math.cos(heading)
            circles.append(Obstacle(cx, cy, r))
        if any(math.hypot(o.x - pose.x, o.y - pose.y) <= o.r for o in circles):
            continue
        ours = nav.ray_distances(pose, tuple(circles), n, max_range)
        space = pymunk.Space()
        for o in circles:
            space.add(pymunk.Circle(space.static_body, o.r, (o.x, o.y)))
        for k in range(n):
            a = pose.theta + k * 2 * math.pi / n
            end = (pose.x + max_range * math.cos(a), pose.y + max_range * math.sin(a))
            hit = space.segment_query_first((pose.x, pose.y), end, 0, pymunk.ShapeFilter())
            expected = max_range if hit is None else hit.alpha * max_range
            assert ours[k] == pytest.approx(expected, abs=1e-6), (pose, k, circles)
            grazed += hit is not None
    assert grazed > 300


def test_ray_special_cases():
    pose = Pose2D(0.0, 0.0, 0.3)
    assert np.all(nav.ray_distances(pose, (Obstacle(0.05, 0.0, 0.1), Obstacle(2, 0, 0.1)), 36, 5.0) == 0.0)
    assert np.all(nav.ray_distances(pose, (), 36, 5.0) == 5.0)
    assert np.all(nav.ray_distances(pose, (Obstacle(6.0, 0.0, 0.5),), 36, 5.0) == 5.0)  # beyond range
    # a circle straight behind (bearing ±180°, the index wrap-around): ray 18 hits at 1.8 m
    behind = Obstacle(-2 * math.cos(0.3), -2 * math.sin(0.3), 0.2)
    d = nav.ray_distances(pose, (behind,), 36, 5.0)
    assert d[18] == pytest.approx(1.8) and np.count_nonzero(d < 5.0) == 1
    # the observation maps rays through tanh(d / ray_scale)
    cfg = nav.NavTaskConfig(obstacles=True, ray_scale=2.0)
    obs = nav.observation(pose, Scene(Pose2D(1, 0, 0), (behind,)), ([0.0] * 6, [0.0] * 6), cfg)
    assert obs[17 + 18] == pytest.approx(math.tanh(0.9), abs=1e-6) and obs[17] == pytest.approx(
        math.tanh(2.5), abs=1e-6
    )


def test_unrolled_overlap_band_matches_the_axis_loop():
    from footsim.walk.footsteps import _overlap_band_y, _overlap_band_y_reference

    rng = np.random.default_rng(7)
    special = [0.0, math.pi / 2, -math.pi / 2, math.pi, 1e-13, 0.764, -0.764]
    for i in range(20000):
        theta = rng.uniform(-3.5, 3.5) if i % 4 else special[i % len(special)]
        x, hl, hw = rng.uniform(-0.4, 0.4), rng.uniform(0.05, 0.1), rng.uniform(0.03, 0.07)
        assert _overlap_band_y(x, theta, hl, hw) == _overlap_band_y_reference(x, theta, hl, hw)


def test_scene_uniform_draw_is_numpys_uniform():
    from footsim.tasks.scenes import uniform

    a, b = np.random.default_rng(11), np.random.default_rng(11)
    for i in range(3000):
        low, high = [(0.1, 0.3), (-2.0, 5.0), (1e-4, 1e-3)][i % 3]
        assert uniform(a, low, high) == b.uniform(low, high)
        if i % 5 == 0:  # interleaved with other draws, as in the sampler
            np.testing.assert_array_equal(a.normal(0.0, 0.5, size=2), b.normal(0.0, 0.5, size=2))


def test_deferred_generator_is_the_seeded_generator():
    from footsim.env import DeferredGenerator

    lazy, eager = DeferredGenerator(1234), np.random.default_rng(1234)
    assert not lazy.created  # nothing created until first use
    np.testing.assert_array_equal(lazy.normal(0.0, 1.0, 3), eager.normal(0.0, 1.0, 3))
    assert lazy.random() == eager.random() and lazy.uniform(-1, 2) == eager.uniform(-1, 2)


def test_deferred_generator_and_env_survive_copy_and_pickle():
    import copy
    import pickle

    from footsim.env import DeferredGenerator, FootstepEnv

    for used in (False, True):
        for clone in (copy.deepcopy, lambda g: pickle.loads(pickle.dumps(g))):
            lazy, eager = DeferredGenerator(99), np.random.default_rng(99)
            if used:
                lazy.normal(), eager.normal()
            assert clone(lazy).random() == eager.random()
    env = FootstepEnv(obstacles=True, noise="localization")
    env.reset(seed=3)
    twin = copy.deepcopy(env)
    a = np.full(6, 0.3)
    np.testing.assert_array_equal(env.step(a)[0], twin.step(a)[0])  # same noise draws from the copies


def test_nav_distance_collision_model_is_the_thesis_centre_distance_check():
    """collision_model=nav_distance: a collision iff the navigation pose after either put-down
    is closer than collision_distance to a circle's edge (pymunk's point query as the reference),
    regardless of the feet; the footprint model on the same steps disagrees somewhere."""
    backend = _make_backend(collision_model="nav_distance", collision_distance=0.1)
    footprint = _make_backend()
    rng = np.random.default_rng(3)
    sampler = SceneSampler(obstacles=True, obstacle_offset_sigma=0.4, obstacle_radius_max=0.4)
    outcomes, disagreements = [], 0
    for episode in range(100):
        scene = sampler.sample(rng)
        backend.reset(scene, np.random.default_rng(episode))
        footprint.reset(scene, np.random.default_rng(episode))
        space = pymunk.Space()
        for o in scene.all_obstacles:
            space.add(pymunk.Circle(space.static_body, o.r, (o.x, o.y)))
        for _ in range(30):
            action = rng.uniform(-1, 1, 6)
            left_before = backend.feet.left
            result = backend.execute(DoubleStep.from_action(action, backend.robot.step_limits))
            other = footprint.execute(DoubleStep.from_action(action, backend.robot.step_limits))
            half_nav = mean_pose(left_before, backend.history[-2][1])  # the left stands, the right has landed
            hits = [space.point_query_nearest((p.x, p.y), 0.1, pymunk.ShapeFilter()) for p in (half_nav, result.pose)]
            expected = any(hit is not None and hit.distance < 0.1 for hit in hits)
            assert result.collided == expected
            disagreements += result.collided != other.collided
            outcomes.append(expected)
            if expected or other.collided:
                break
    assert 20 < sum(outcomes) < len(outcomes) - 200
    assert disagreements > 0


def test_collision_model_rejects_unknown_values():
    with pytest.raises(ValueError, match="collision_model"):
        _make_backend(collision_model="sphere")
    with pytest.raises(ValueError, match="collision_distance"):
        _make_backend(collision_model="nav_distance", collision_distance=-0.1)
