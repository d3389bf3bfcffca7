import math

import numpy as np
import pytest

from footsim.walk import DoubleStep, Footstep, FootstepGeometry, Side, StepLimits, WalkParams

LIMITS = StepLimits(0.156, 0.103, 0.764)
GEOM = FootstepGeometry(LIMITS, 0.154, 0.106, 0.1799)


def test_action_scaling_and_clipping():
    ds = DoubleStep.from_action([1, -0.5, 0.25, 2.0, -3.0, 0], LIMITS)
    np.testing.assert_allclose(ds.as_array(), [0.156, -0.0515, 0.191, 0.156, -0.103, 0.0])


@pytest.mark.parametrize(
    "bad", [[np.nan, 0, 0, 0, 0, 0], [0, 0, 0, np.inf, 0, 0], [np.inf, -np.inf, 0, 0, 0, 0], [0, 0, 0, 0, 0, -np.inf]]
)
def test_non_finite_action_raises(bad):
    with pytest.raises(ValueError, match="NaN or inf"):
        DoubleStep.from_action(bad, LIMITS)


def test_huge_finite_action_is_clipped_not_rejected():
    # the values overflow their sum (the fast finiteness check) but are finite: clipped
    ds = DoubleStep.from_action([1e308, 1e308, -1e308, 1e308, 1e308, 0.5], LIMITS)
    np.testing.assert_allclose(ds.as_array(), [0.156, 0.103, -0.764, 0.156, 0.103, 0.382])


def test_landing_is_resting_pose_plus_step():
    pose, done, interfered = GEOM.landing(Side.LEFT, Footstep(0.1, 0.05, 0.3))
    assert not interfered
    np.testing.assert_allclose(pose, (0.1, 0.1799 + 0.05, 0.3))
    pose, _, _ = GEOM.landing(Side.RIGHT, Footstep(-0.1, -0.02, -0.2))
    np.testing.assert_allclose(pose, (-0.1, -0.1799 - 0.02, -0.2))


def _corners(x, y, t, length=0.154, width=0.106):
    c, s = math.cos(t), math.sin(t)
    hl, hw = length / 2, width / 2
    return np.array(
        [(x + c * dx - s * dy, y + s * dx + c * dy) for dx, dy in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))]
    )


def _overlap_by_sampling(pose) -> bool:
    """Independent check: does any grid point of the support foot lie inside the flying foot?"""
    gx, gy = np.meshgrid(np.linspace(-0.077, 0.077, 60), np.linspace(-0.053, 0.053, 40))
    x, y, t = pose
    c, s = math.cos(t), math.sin(t)
    lx = c * (gx - x) + s * (gy - y)
    ly = -s * (gx - x) + c * (gy - y)
    return bool(np.any((np.abs(lx) <= 0.077) & (np.abs(ly) <= 0.053)))


def test_inward_step_is_backed_off_until_the_feet_clear():
    pose, done, interfered = GEOM.landing(Side.LEFT, Footstep(0.0, -0.103, 0.0))
    assert interfered
    # parallel feet: the centres end at least one foot width plus the gap apart
    assert pose.y == pytest.approx(0.106 + 0.01, abs=1e-3)
    assert not _overlap_by_sampling(pose)
    assert done.y == pytest.approx(pose.y - 0.1799)


def test_no_landing_overlaps_the_support_foot():
    rng = np.random.default_rng(1)
    for _ in range(300):
        side = Side.LEFT if rng.random() < 0.5 else Side.RIGHT
        pose, _, _ = GEOM.landing(side, Footstep(*(rng.uniform(-1, 1, 3) * LIMITS.as_array())))
        assert not _overlap_by_sampling(pose)


def test_forward_steps_are_relative_to_the_support_foot():
    feet = GEOM.initial_feet()
    ds = DoubleStep.from_action([1, 0, 0, 1, 0, 0], LIMITS)
    _, after, executed, n = GEOM.execute(feet, ds)
    assert n == 0
    # right foot lands 0.156 ahead of the left, then the left 0.156 ahead of the right
    np.testing.assert_allclose(after.right, (0.156, -0.1799 / 2, 0), atol=1e-12)
    np.testing.assert_allclose(after.left, (0.312, 0.1799 / 2, 0), atol=1e-12)
    np.testing.assert_allclose(after.nav_pose, (0.234, 0.0, 0.0), atol=1e-12)
    # in steady state a double step advances 2 x
    _, again, _, _ = GEOM.execute(after, ds)
    np.testing.assert_allclose(again.nav_pose.x - after.nav_pose.x, 0.312, atol=1e-12)


def test_double_step_duration_is_one_over_freq():
    assert WalkParams().double_step_duration == pytest.approx(1 / 1.9633)


def test_too_small_foot_distance_is_rejected():
    with pytest.raises(ValueError, match="foot_distance"):
        FootstepGeometry(LIMITS, 0.154, 0.106, 0.05)
