"""One tracking camera (``backend.camera``) on MuJoCo, dm-control and PyBullet: the same world
point lands on the same pixel in each simulator's own rendering.

The camera looks at a point above the robot's base from a pose relative to the base's heading, so
the pixel of a point at a known offset from the base (a white ball, the robot at its reset pose
at the origin) measures where the base itself is framed: the same pixel on every backend, and the
pixel that an independent pinhole model of the camera (``TrackingCamera.project``) predicts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from footsim.backends.base import TrackingCamera
from footsim.env import FootstepEnv
from footsim.geometry import Pose2D
from footsim.scene import Obstacle, Scene

W, H = 320, 240
FAR_GOAL = Pose2D(4.0, 4.0, 0.0)  # out of view
BALL_R = 0.1
#: Ball positions in view of the default camera (in front-left of the robot, looking back at it).
BALLS = [(0.2, -1.2), (-1.2, 0.6), (-1.5, -1.5), (0.8, -0.3)]


def test_the_camera_model_by_hand():
    camera = TrackingCamera(distance=2.0, elevation=-30.0, azimuth=180.0, fov=60.0, height=0.3)
    base = Pose2D(1.0, 2.0, math.pi / 2)  # heading +y: the camera looks along -y (azimuth 180° + 90°)
    eye, target = camera.eye(base)
    np.testing.assert_allclose(target, [1.0, 2.0, 0.3])
    np.testing.assert_allclose(eye, [1.0, 2.0 + 2.0 * math.cos(math.radians(30)), 0.3 + 1.0], atol=1e-12)
    # the look-at point is the image centre; a point raised by d·tan(fov/2) perpendicular to the
    # view, at the look-at point's depth, is on the top edge
    up = np.array([0.0, -math.sin(math.radians(30)), math.cos(math.radians(30))])  # camera up (pointing away from it)
    points = np.array([target, target + 2.0 * math.tan(math.radians(30)) * up])
    np.testing.assert_allclose(camera.project(points, base, W, H), [[W / 2, H / 2], [W / 2, 0.0]], atol=1e-9)


@pytest.mark.parametrize("key, value", [("distance", 0.0), ("fov", 200.0), ("elevation", "high")])
def test_bad_camera_values_name_the_key(key, value):
    with pytest.raises(ValueError, match=f"backend.camera.{key}"):
        TrackingCamera.from_config({key: value})
    with pytest.raises(ValueError, match="unknown key"):
        TrackingCamera.from_config({"zoom": 2})


def _ball_pixels(backend: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ball: the centroid of its bright pixels (changed from the empty scene) in the
    backend's frame, the camera model's projection of its centre, and its projected radius [px]."""
    pytest.importorskip("dm_control" if backend == "dm_control" else backend)
    env = FootstepEnv(backend={"name": backend, "render_size": [W, H]}, render_mode="rgb_array")
    found, projected, radius = [], [], []
    try:
        env.reset(seed=0, options={"scene": Scene(goal=FAR_GOAL)})
        empty = env.backend.render(None)
        camera = env.backend.camera
        for x, y in BALLS:
            env.reset(seed=0, options={"scene": Scene(goal=FAR_GOAL, ball=Obstacle(x, y, BALL_R))})
            frame = env.backend.render(None)
            ball = (frame != empty).any(axis=2) & (frame.min(axis=2) > 140)  # white ball, lit
            rows, cols = np.nonzero(ball)
            assert len(rows) > 5, f"{backend}: ball at {(x, y)} not found"
            found.append((cols.mean(), rows.mean()))
            base = env.backend.planar_pose()
            projected.append(camera.project([[x, y, BALL_R]], base, W, H)[0])
            eye, _ = camera.eye(base)
            depth = float(np.linalg.norm(np.array([x, y, BALL_R]) - eye))
            radius.append(0.5 * H / math.tan(math.radians(camera.fov) / 2) * BALL_R / depth)
    finally:
        env.close()
    return np.array(found), np.array(projected), np.array(radius)


def test_a_world_point_lands_on_the_same_pixel_on_every_3d_backend():
    results = {name: _ball_pixels(name) for name in ("mujoco", "dm_control", "pybullet")}
    for name, (found, projected, radius) in results.items():
        # Tolerance: only the ball's lit cap passes the brightness test (MuJoCo lights it from
        # above), so its centroid sits up to about half the projected radius above the centre;
        # 0.6 radius + 1 px covers that and no framing difference larger than ~3 % of the frame.
        error = np.linalg.norm(found - projected, axis=1)
        assert (error < 0.6 * radius + 1.0).all(), f"{name}: {error.round(1)} px off (radius {radius.round(1)})"
    # the backends against one another (the same tolerance, twice: each may be off its way)
    names = list(results)
    for a in names:
        for b in names:
            gap = np.linalg.norm(results[a][0] - results[b][0], axis=1)
            assert (gap < 2 * (0.6 * results[a][2] + 1.0)).all(), f"{a} vs {b}: {gap.round(1)} px"
