"""The compiled 2D kernels (``footsim.tasks.rays``, ``footsim.backends.pymunk2d.collision``,
``footsim.walk.kernels``) against the pure-Python code they replaced.

The ``_reference_*`` functions below are that code, kept here as the reference implementation
(``footsim/tasks/nav.py`` and ``footsim/backends/pymunk2d.py`` before numba).  The contract is
agreement to 1e-12 and identical discrete outcomes (hit / miss, inside, collided); the kernels
do the same float operations in the same order, so most comparisons are in fact exact.
"""

import math

import numpy as np
import pytest

from footsim.backends.pymunk2d import Pymunk2DBackend, box_hits_circles, collision
from footsim.config import build_robot, build_walk, load_preset
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D, mean_pose
from footsim.scene import Obstacle, Scene, circle_array
from footsim.tasks import nav, rays
from footsim.tasks.nav import NavTaskConfig
from footsim.tasks.scenes import SceneSampler
from footsim.walk.footsteps import DoubleStep, FeetState, Footstep, FootstepGeometry, Side, StepLimits

ATOL = 1e-12


# -- the pure-Python reference implementations -------------------------------------------------
def _reference_ray_scan(pose, circles, n_rays, max_range, out):
    """Write each ray's distance to the first circle hit into ``out`` (``n_rays`` × ``max_range``);
    returns the indices of the rays that hit, ``None`` when the origin is inside a circle."""
    n = n_rays
    hit = []
    if not circles:
        return hit
    k_ = np.arange(n) * (2.0 * math.pi / n)
    cos_k, sin_k = np.cos(k_).tolist(), np.sin(k_).tolist()
    px, py, theta = pose
    c, s = math.cos(theta), math.sin(theta)
    per_rad = n / (2.0 * math.pi)
    far = max_range + 1e-6 * (1.0 + max_range)
    for ox, oy, r in circles:
        dx, dy = ox - px, oy - py
        d2 = dx * dx + dy * dy
        cc = d2 - r * r
        if cc <= 0.0:
            return None
        dist = math.sqrt(d2)
        if dist - r > far:
            continue
        rx, ry = c * dx + s * dy, c * dy - s * dx
        bearing = math.atan2(ry, rx) * per_rad
        q = r / dist
        half = math.asin(q if q < 1.0 else 1.0) * per_rad + 1e-3
        lo, hi = math.ceil(bearing - half), math.floor(bearing + half)
        if hi - lo >= n:
            lo, hi = 0, n - 1
        for k in range(lo, hi + 1) if lo >= 0 and hi < n else [k % n for k in range(lo, hi + 1)]:
            proj = rx * cos_k[k] + ry * sin_k[k]
            disc = proj * proj - cc
            if disc >= 0.0:
                t = proj - math.sqrt(disc)
                if 0.0 <= t < out[k]:
                    out[k] = t
                    hit.append(k)
    return hit


def _reference_rays(pose, circles, n_rays, max_range):
    out = [max_range] * n_rays
    hit = _reference_ray_scan(pose, circles, n_rays, max_range, out)
    return [0.0] * n_rays if hit is None else out


def _reference_nearest(pose, circles):
    best = math.inf
    for ox, oy, r in circles:
        d = math.hypot(ox - pose[0], oy - pose[1]) - r
        if d < best:
            best = d
    return best


def _reference_box_hits(x, y, theta, half_length, half_width, circles):
    c, s = math.cos(theta), math.sin(theta)
    for cx, cy, r in circles:
        dx, dy = cx - x, cy - y
        u = abs(c * dx + s * dy) - half_length
        if u > r:
            continue
        v = abs(c * dy - s * dx) - half_width
        if v > r:
            continue
        u = u if u > 0.0 else 0.0
        v = v if v > 0.0 else 0.0
        if u * u + v * v <= r * r:
            return True
    return False


def _reference_double_step_collides(backend, circles, before, after_first, after_second):
    """The backend's broad phase and six box tests, as they were in Python."""
    foot_half = (0.5 * backend.robot.foot_length, 0.5 * backend.robot.foot_width)
    trunk_half = tuple(0.5 * v for v in backend.robot.torso_footprint)
    reach = max(math.hypot(*foot_half), math.hypot(*trunk_half)) * (1.0 + 1e-9) + 1e-9
    start_right, (mid_left, right), end_left = before[1], after_first, after_second[0]
    xs = (start_right[0], right[0], mid_left[0], end_left[0])
    ys = (start_right[1], right[1], mid_left[1], end_left[1])
    lo_x, hi_x, lo_y, hi_y = min(xs) - reach, max(xs) + reach, min(ys) - reach, max(ys) + reach
    near = [(x, y, r) for x, y, r in circles if x + r >= lo_x and x - r <= hi_x and y + r >= lo_y and y - r <= hi_y]
    if not near:
        return False

    def swing(start, end, trunk):
        mid = mean_pose(start, end)
        return (
            _reference_box_hits(*mid, *foot_half, near)
            or _reference_box_hits(*end, *foot_half, near)
            or _reference_box_hits(*trunk, *trunk_half, near)
        )

    return swing(start_right, right, mean_pose(mid_left, right)) or swing(
        mid_left, end_left, mean_pose(end_left, right)
    )


def _reference_observation(believed, scene, previous_actions, config, tilt=(0.0, 0.0, 0.0), hint=(0.0, 1.0)):
    d, alpha, beta = nav.goal_features(believed, scene.goal)
    values = [math.tanh(d / config.distance_scale), math.sin(alpha), math.cos(alpha), math.sin(beta), math.cos(beta)]
    values += list(previous_actions[0]) + list(previous_actions[1])
    if config.obstacles:
        n, max_range, scale = int(config.n_rays), config.ray_range, config.ray_scale
        rays = [max_range] * n
        hit = _reference_ray_scan(believed, scene.circles, n, max_range, rays)
        if hit is None:
            values += [0.0] * n
        else:
            start = len(values)
            values += [float(np.tanh(max_range / scale))] * n
            for k in hit:
                values[start + k] = math.tanh(rays[k] / scale)
    if config.observe_imu:
        values += [math.tanh(v / config.imu_scale) for v in tilt]
    if config.path_hint:
        values += [hint[0], hint[1]]
    return np.array(values, dtype=np.float32)


def _reference_land(geometry, left, x, y, theta):
    """``FootstepGeometry`` placement as it was in Python: clip, then back the lateral offset off
    to the edge of the overlap band (the unrolled band is checked against the axis loop in
    ``tests/test_backend_pymunk2d.py``; the axis loop is used here)."""
    from footsim.walk.footsteps import _overlap_band_y_reference

    lim = geometry.limits
    x, y, theta = min(max(x, -lim.x), lim.x), min(max(y, -lim.y), lim.y), min(max(theta, -lim.theta), lim.theta)
    rest_y = geometry.foot_distance if left else -geometry.foot_distance
    half_l, half_w = (
        0.5 * (geometry.foot_length + geometry.min_foot_gap),
        0.5 * (geometry.foot_width + geometry.min_foot_gap),
    )
    band = _overlap_band_y_reference(x, theta, half_l, half_w)
    interfered = band is not None and band[0] < rest_y + y < band[1]
    if interfered:
        y = (band[1] if left else band[0]) - rest_y
    return x, y, theta, interfered


def _reference_execute(geometry, feet, double_step, perturb=None):
    first, second = double_step
    x, y, theta, hit_first = _reference_land(geometry, False, *first)
    right = feet.left.compose(Pose2D(x, y - geometry.foot_distance, theta))
    right = perturb(right) if perturb else right
    done_first = Footstep(x, y, theta)
    x, y, theta, hit_second = _reference_land(geometry, True, *second)
    left = right.compose(Pose2D(x, y + geometry.foot_distance, theta))
    left = perturb(left) if perturb else left
    return (
        FeetState(feet.left, right),
        FeetState(left, right),
        DoubleStep(done_first, Footstep(x, y, theta)),
        int(hit_first) + int(hit_second),
    )


def _reference_obstacle_term(pose, scene):
    d_obs = _reference_nearest(pose, scene.obstacle_circles)
    return 1.0 if d_obs == math.inf else math.exp(-0.0015 * (1.0 / max(d_obs, 1e-6)) ** 2)


# -- scenes that stress the edge cases ---------------------------------------------------------
def _grazing_circles(rng, pose, n, count):
    """Circles whose edge passes at a chosen tiny distance inside or outside a ray."""
    circles = []
    for _ in range(count):
        k = int(rng.integers(n))
        heading = pose[2] + k * 2 * math.pi / n
        along, r = rng.uniform(0.05, 5.5), rng.uniform(0.01, 0.5)
        offset = r + rng.choice([-1e-12, 1e-12, -1e-9, 1e-9, -1e-6, 1e-6, 0.0, 0.3 * r])
        side = rng.choice([-1.0, 1.0])
        circles.append(
            (
                pose[0] + along * math.cos(heading) - side * offset * math.sin(heading),
                pose[1] + along * math.sin(heading) + side * offset * math.cos(heading),
                r,
            )
        )
    return circles


def _random_case(rng, i, n):
    """A pose and circles: sampled scenes, grazing circles, circles around the pose (inside, on the
    edge, huge, behind, at the range limit)."""
    pose = (float(rng.normal(0, 1.0)), float(rng.normal(0, 1.0)), float(rng.uniform(-math.pi, math.pi)))
    kind = i % 4
    if kind == 0:
        circles = list(SceneSampler(obstacles=True).sample(rng).circles)
    elif kind == 1:
        circles = _grazing_circles(rng, pose, n, int(rng.integers(1, 6)))
    elif kind == 2:
        circles = [
            tuple(rng.normal(0, 2.0, 2) + pose[:2]) + (float(rng.uniform(0.01, 3.0)),)
            for _ in range(int(rng.integers(0, 8)))
        ]
    else:  # special positions relative to the pose
        r = float(rng.uniform(0.05, 1.0))
        phi = float(rng.uniform(-math.pi, math.pi))
        dist = float(rng.choice([r, r * (1 + 1e-12), r * (1 - 1e-12), 5.0 + r, 5.0 + r + 1e-7, 5.0 + r + 1e-5, 3 * r]))
        circles = [(pose[0] + dist * math.cos(phi), pose[1] + dist * math.sin(phi), r)]
        circles += _grazing_circles(rng, pose, n, int(rng.integers(0, 3)))
    return pose, [tuple(float(v) for v in c) for c in circles]


# -- rays ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("n_rays", [1, 3, 36, 37, 360])
def test_ray_scan_matches_the_python_reference(n_rays):
    rng = np.random.default_rng(100 + n_rays)
    directions = rays.ray_directions(n_rays)
    out = np.empty(n_rays)
    counts = {"hit": 0, "inside": 0, "exact": 0}
    cases = 2000 if n_rays <= 37 else 400
    for i in range(cases):
        pose, circles = _random_case(rng, i, n_rays)
        max_range = [5.0, 1.0, 0.3, 5.0][i % 4]
        expected = _reference_rays(pose, circles, n_rays, max_range)
        rays.scan_rays(*pose, circle_array(circles), directions, max_range, out)
        np.testing.assert_allclose(out, expected, rtol=0, atol=ATOL, err_msg=f"{pose} {circles}")
        # the same rays hit (a hit is strictly closer than max_range)
        assert [v < max_range for v in out] == [v < max_range for v in expected], (pose, circles)
        counts["hit"] += sum(v < max_range for v in expected) > 0
        counts["inside"] += all(v == 0.0 for v in expected)
        counts["exact"] += out.tolist() == expected
    assert counts["hit"] > cases // 3 and counts["inside"] > 20  # both well represented
    assert counts["exact"] == cases  # same operations in the same order: bit for bit here


def test_ray_special_cases_and_wrapper():
    directions = rays.ray_directions(36)
    out = np.empty(36)
    rays.scan_rays(0.0, 0.0, 0.3, circle_array([]), directions, 5.0, out)
    assert np.all(out == 5.0)
    rays.scan_rays(0.0, 0.0, 0.3, circle_array([(0.1, 0.0, 0.1)]), directions, 5.0, out)
    assert np.all(out == 0.0)  # the origin on a circle's edge counts as inside
    pose = Pose2D(0.2, -0.1, 2.0)
    obstacles = (Obstacle(1.0, 0.5, 0.3), Obstacle(-1.0, -2.0, 0.2))
    expected = _reference_rays(pose, [(o.x, o.y, o.r) for o in obstacles], 36, 5.0)
    assert nav.ray_distances(pose, obstacles, 36, 5.0).tolist() == expected
    assert nav.ray_distances(Pose2D(0, 0, 0), obstacles, 36, 5.0).tolist() == _reference_rays(
        (0.0, 0.0, 0.0), [(o.x, o.y, o.r) for o in obstacles], 36, 5.0
    )  # integer pose components


# -- observation, reward, env -------------------------------------------------------------------
@pytest.mark.parametrize(
    "config",
    [
        NavTaskConfig(obstacles=True),
        NavTaskConfig(obstacles=True, n_rays=37, ray_range=2.0, ray_scale=2.0),
        NavTaskConfig(obstacles=True, observe_imu=True, path_hint=True),
        NavTaskConfig(obstacles=False, observe_imu=True),
        NavTaskConfig(),
    ],
    ids=["rays", "37rays", "rays_imu_hint", "imu", "plain"],
)
def test_observation_matches_the_python_reference(config):
    rng = np.random.default_rng(7)
    sampler = SceneSampler(obstacles=True)
    for i in range(500):
        scene = sampler.sample(rng)
        if i % 5 == 0:  # also grazing circles as obstacles
            pose0 = (0.0, 0.0, 0.0)
            scene = Scene(scene.goal, tuple(Obstacle(*c) for c in _grazing_circles(rng, pose0, 36, 4)), scene.ball)
        pose = Pose2D(*rng.normal(0, 0.8, 2), rng.uniform(-math.pi, math.pi))
        prev = (rng.uniform(-1, 1, 6).tolist(), rng.uniform(-1, 1, 6))
        tilt, hint = tuple(rng.normal(0, 0.2, 3)), (0.6, 0.8)
        expected = _reference_observation(pose, scene, prev, config, tilt, hint)
        for arrays in (None, nav.scene_arrays(scene)):
            obs = nav.observation(pose, scene, prev, config, None, tilt, hint, arrays)
            assert obs.dtype == np.float32 and obs.shape == expected.shape
            np.testing.assert_array_equal(obs, expected)


def test_obstacle_reward_matches_the_python_reference():
    rng = np.random.default_rng(11)
    sampler = SceneSampler(obstacles=True)
    a = [0.0] * 6
    for i in range(3000):
        scene = sampler.sample(rng)
        if i % 10 == 0:
            scene = Scene(scene.goal, (), scene.ball)  # the ball alone: no obstacle term
        pose = Pose2D(*rng.normal(0, 1.0, 2), 0.0)
        expected = _reference_obstacle_term(pose, scene)
        for arrays in (None, nav.scene_arrays(scene)):
            got = nav.reward_terms(pose, scene, a, a, arrays=arrays)["obstacle"]
            assert got == pytest.approx(expected, rel=0, abs=ATOL)
            assert got == expected  # the kernel picks the circle, math.hypot gives the distance
    obstacles = (Obstacle(1.0, 0.0, 0.25), Obstacle(0.0, 3.0, 0.5))
    assert nav.nearest_obstacle_distance(Pose2D(), obstacles) == 0.75
    assert nav.nearest_obstacle_distance(Pose2D(), ()) == math.inf


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(obstacles=True),
        dict(obstacles=True, noise="localization", randomization="strong"),
        dict(task={"name": "nav_obstacles", "n_rays": 37, "observe_imu": True}),
    ],
    ids=["obstacles", "noise_randomization", "37rays_imu"],
)
def test_env_steps_match_the_python_reference(kwargs):
    """Every step's observation (from the believed pose) and obstacle reward term (from the true
    pose) against the reference code, and the collision outcome against the reference check."""
    env = FootstepEnv(**kwargs)
    rng = np.random.default_rng(3)
    obs, _ = env.reset(seed=5)
    collisions = 0
    for _ in range(1500):
        before = env.backend.feet
        obs, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 6))
        prev, believed = env.task.previous_actions, Pose2D(*info["pose_estimate"])
        np.testing.assert_array_equal(
            obs, _reference_observation(believed, env.scene, prev, env.task.config, env.task.tilt)
        )
        assert info["reward_terms"]["obstacle"] == _reference_obstacle_term(env.task.pose, env.scene)
        after_first = type(before)(before.left, env.backend.history[-2][1])
        expected = _reference_double_step_collides(
            env.backend, env.scene.circles, before, after_first, env.backend.feet
        )
        assert info["collided"] == expected
        collisions += expected
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    assert collisions > 10


# -- collisions ----------------------------------------------------------------------------------
def test_box_kernel_matches_the_python_reference():
    rng = np.random.default_rng(2)
    hits = 0
    for i in range(5000):
        hl, hw = rng.uniform(0.02, 0.15, 2)
        x, y, theta = *rng.uniform(-1, 1, 2), rng.uniform(-4, 4)
        r = rng.uniform(0.01, 0.4)
        # a circle at a chosen distance from a point of the rectangle's boundary (corners and sides)
        u, v = rng.uniform(-1, 1, 2) * (hl, hw)
        side = int(rng.integers(4))
        u = [hl, -hl, u, u][side]
        v = [v, v, hw, -hw][side]
        # along the side's outward normal (that boundary point is then the closest one) or anywhere
        phi = [0.0, math.pi, 0.5 * math.pi, -0.5 * math.pi][side] if i % 2 else rng.uniform(-math.pi, math.pi)
        gap = r + rng.choice([-1, 1]) * rng.choice([0.0, 1e-12, 1e-9, 1e-4, 0.1])
        u, v = u + gap * math.cos(phi), v + gap * math.sin(phi)
        c, s = math.cos(theta), math.sin(theta)
        circles = [(x + c * u - s * v, y + s * u + c * v, r)]
        circles += [tuple(rng.uniform(-1.5, 1.5, 2)) + (rng.uniform(0.02, 0.3),) for _ in range(i % 3)]
        expected = _reference_box_hits(x, y, theta, hl, hw, circles)
        assert collision.box_hits_circles(x, y, theta, hl, hw, circle_array(circles)) == expected
        assert box_hits_circles(x, y, theta, hl, hw, circles) == expected
        hits += expected
    assert 1000 < hits < 4500  # both answers well represented


def test_double_step_collisions_match_the_python_reference():
    backend = Pymunk2DBackend(
        build_robot(load_preset("robot", "wolfgang")),
        build_walk(load_preset("walk", "pymunk")),
    )
    rng = np.random.default_rng(4)
    sampler = SceneSampler(obstacles=True, obstacle_offset_sigma=0.3, obstacle_radius_max=0.4)
    outcomes = []
    for episode in range(200):
        backend.reset(sampler.sample(rng), np.random.default_rng(episode))
        sigma = 0.02 * (episode % 2)  # (noise settings persist across resets)
        backend.apply_randomization(
            {"footstep_noise_x": sigma, "footstep_noise_y": sigma, "footstep_noise_theta": 10 * sigma}
        )
        for _ in range(25):
            before = backend.feet
            double_step = DoubleStep.from_action(rng.uniform(-1, 1, 6), backend.robot.step_limits)
            result = backend.execute(double_step)
            after_first = type(before)(before.left, backend.history[-2][1])
            expected = _reference_double_step_collides(backend, backend.scene.circles, before, after_first, result.feet)
            assert result.collided == expected
            outcomes.append(expected)
            assert result.pose == mean_pose(*result.feet)  # (bit for bit)
            if episode % 2 == 0:  # no execution noise: the compiled whole double step (execute_double_step)
                placed = backend.geometry.execute(before, double_step)  # separate placement kernel
                assert (after_first, result.feet, result.executed, result.info["foot_interference"]) == placed
    assert 200 < sum(outcomes) < len(outcomes) - 200  # both outcomes well represented


# -- footstep placement --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "geometry",
    [
        FootstepGeometry(StepLimits()),
        FootstepGeometry(
            StepLimits(0.2, 0.15, 1.2), foot_length=0.2, foot_width=0.12, foot_distance=0.26, min_foot_gap=0.0
        ),
    ],
    ids=["wolfgang_like", "other"],
)
def test_placement_matches_the_python_reference(geometry):
    """``landing`` and ``execute`` (with and without a perturbation between the two footsteps)
    against the Python placement, over the limits and well beyond, inward steps included."""
    rng = np.random.default_rng(9)
    limits = np.array([geometry.limits.x, geometry.limits.y, geometry.limits.theta])
    interfered = 0
    for i in range(4000):
        steps = rng.uniform(-1.3, 1.3, (2, 3)) * limits
        if i % 3 == 0:  # inward steps that make the feet interfere
            steps[0, 1], steps[1, 1] = abs(steps[0, 1]), -abs(steps[1, 1])
        double_step = DoubleStep(Footstep(*steps[0].tolist()), Footstep(*steps[1].tolist()))
        for side, step in ((Side.RIGHT, double_step.first), (Side.LEFT, double_step.second)):
            pose, done, hit = geometry.landing(side, step)
            x, y, theta, expected_hit = _reference_land(geometry, side is Side.LEFT, *step)
            rest_y = geometry.foot_distance if side is Side.LEFT else -geometry.foot_distance
            assert (pose, done, hit) == (Pose2D(x, rest_y + y, theta), Footstep(x, y, theta), expected_hit)
            interfered += hit
        start = Pose2D(*rng.normal(0, 1, 2), rng.uniform(-math.pi, math.pi))
        feet = geometry.initial_feet(start)
        assert geometry.execute(feet, double_step) == _reference_execute(geometry, feet, double_step)
        offset = Pose2D(*rng.normal(0, 0.01, 3))
        shift = lambda pose, offset=offset: pose.compose(offset)  # noqa: E731  (a deterministic perturbation)
        assert geometry.execute(feet, double_step, shift) == _reference_execute(geometry, feet, double_step, shift)
    assert interfered > 500


# -- swing-path overlap bands (footsim.walk.engine._overlap_bands) --------------------------------
def _reference_overlap_bands(x, theta, half_l, half_w):
    """The walk engine's numpy version of the bands before the compiled loop (per sample: the y
    interval where a foot at (x, y, theta) overlaps one at the origin; NaN where none does)."""
    c, s = np.cos(theta), np.sin(theta)
    lo = np.full(x.shape, -np.inf)
    hi = np.full(x.shape, np.inf)
    separated = np.zeros(x.shape, dtype=bool)
    for nx, ny in ((np.ones_like(c), np.zeros_like(c)), (np.zeros_like(c), np.ones_like(c)), (c, s), (-s, c)):
        reach = (
            half_l * np.abs(nx)
            + half_w * np.abs(ny)
            + half_l * np.abs(nx * c + ny * s)
            + half_w * np.abs(-nx * s + ny * c)
        )
        flat = np.abs(ny) < 1e-12
        separated |= flat & (np.abs(nx * x) > reach)
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = (-reach - nx * x) / ny, (reach - nx * x) / ny
        lo = np.where(flat, lo, np.maximum(lo, np.minimum(a, b)))
        hi = np.where(flat, hi, np.minimum(hi, np.maximum(a, b)))
    separated |= lo > hi
    return np.where(separated, np.nan, lo), np.where(separated, np.nan, hi)


def test_swing_path_bands_match_the_numpy_reference():
    """Bit for bit, NaN where separated, over random samples, headings where one box axis is flat
    (0, ±π/2, π) and offsets at and beyond the reach."""
    from footsim.walk.engine import _overlap_bands

    rng = np.random.default_rng(3)
    half_l, half_w = 0.5 * (0.2 + 0.01), 0.5 * (0.11 + 0.01)
    special = np.array([0.0, math.pi / 2, -math.pi / 2, math.pi, 1e-13, math.pi / 2 + 1e-13])
    separated = 0
    for i in range(300):
        n = int(rng.integers(1, 40))
        x = rng.uniform(-0.5, 0.5, n)
        theta = rng.choice(special, n) if i % 3 == 0 else rng.uniform(-math.pi, math.pi, n)
        lo, hi = _overlap_bands(x, theta, half_l, half_w)
        ref_lo, ref_hi = _reference_overlap_bands(x, theta, half_l, half_w)
        np.testing.assert_array_equal(lo, ref_lo)
        np.testing.assert_array_equal(hi, ref_hi)
        separated += int(np.isnan(lo).sum())
    assert separated > 100  # both branches exercised
