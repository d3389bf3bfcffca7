import math

import numpy as np
import pytest

from footsim.geometry import Pose2D, mean_pose, wrap_angle, wrap_angles


@pytest.mark.parametrize(
    "angle,expected",
    [
        (0.0, 0.0),
        (math.pi, math.pi),
        (-math.pi, math.pi),
        (3 * math.pi, math.pi),
        (2 * math.pi + 0.1, 0.1),
        (-0.1, -0.1),
    ],
)
def test_wrap_angle_range(angle, expected):
    assert wrap_angle(angle) == pytest.approx(expected)
    assert wrap_angles(np.array([angle]))[0] == pytest.approx(expected)


def _matrix(p: Pose2D) -> np.ndarray:
    c, s = math.cos(p.theta), math.sin(p.theta)
    return np.array([[c, -s, p.x], [s, c, p.y], [0, 0, 1]])


def _from_matrix(m: np.ndarray) -> Pose2D:
    return Pose2D(m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0]))


def test_compose_inverse_relative_match_homogeneous_matrices():
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = Pose2D.of(*rng.normal(size=2), rng.uniform(-4, 4))
        b = Pose2D.of(*rng.normal(size=2), rng.uniform(-4, 4))
        np.testing.assert_allclose(a.compose(b), _from_matrix(_matrix(a) @ _matrix(b)), atol=1e-12)
        np.testing.assert_allclose(a.inverse(), _from_matrix(np.linalg.inv(_matrix(a))), atol=1e-12)
        np.testing.assert_allclose(a.relative(b), _from_matrix(np.linalg.inv(_matrix(a)) @ _matrix(b)), atol=1e-12)
        np.testing.assert_allclose(a.compose(a.relative(b)), b, atol=1e-12)


def test_mean_pose_bisects_headings_across_the_wrap():
    m = mean_pose(Pose2D(0, 0, math.pi - 0.1), Pose2D(2, 2, -math.pi + 0.1))
    assert (m.x, m.y) == (1, 1)
    assert abs(wrap_angle(m.theta - math.pi)) < 1e-12
