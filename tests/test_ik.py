"""Analytic leg IK / FK in the shared joint convention."""

import numpy as np
import pytest

from footsim.walk.ik import (
    LEG_JOINT_NAMES,
    LegGeometry,
    leg_fk,
    leg_ik,
    leg_ik_rotation,
    legs_ik,
    rotation_from_rpy,
    rpy_from_rotation,
)

LEG = LegGeometry()
SIDES = ["left", "right"]


def _random_joint_sets(rng, n):
    """Joint angles in a walking-like range, knee bent (away from the straight singularity)."""
    return np.column_stack(
        [
            rng.uniform(-0.8, 0.8, n),  # hip yaw
            rng.uniform(-0.5, 0.5, n),  # hip roll
            rng.uniform(-1.2, 0.6, n),  # hip pitch
            rng.uniform(0.1, 2.2, n),  # knee
            rng.uniform(-1.0, 0.6, n),  # ankle pitch
            rng.uniform(-0.5, 0.5, n),  # ankle roll
        ]
    )


def test_joint_name_order():
    assert LEG_JOINT_NAMES[:3] == ("LHipYaw", "LHipRoll", "LHipPitch")
    assert (
        LEG_JOINT_NAMES[5] == "LAnkleRoll" and LEG_JOINT_NAMES[6] == "RHipYaw" and LEG_JOINT_NAMES[11] == "RAnkleRoll"
    )
    assert len(LEG_JOINT_NAMES) == 12


@pytest.mark.parametrize("side,sign", [("left", 1.0), ("right", -1.0)])
def test_fk_zero_pose_and_bent_knee_by_hand(side, sign):
    pos, rot = leg_fk(np.zeros((1, 6)), side, LEG)
    np.testing.assert_allclose(pos[0], [0.0, sign * 0.055, -(0.0414 + 0.169 + 0.170 + 0.0529)], atol=1e-12)
    np.testing.assert_allclose(rot[0], np.eye(3), atol=1e-12)
    # Knee at +90°: the shin and foot point backwards (+y rotation takes -z to -x).
    pos, rot = leg_fk(np.array([[0, 0, 0, np.pi / 2, 0, 0]]), side, LEG)
    np.testing.assert_allclose(pos[0], [-(0.170 + 0.0529), sign * 0.055, -(0.0414 + 0.169)], atol=1e-12)
    # Hip roll +0.3 swings the leg towards +y (left).
    pos, _ = leg_fk(np.array([[0, 0.3, 0, 0, 0, 0]]), side, LEG)
    assert pos[0, 1] == pytest.approx(sign * 0.055 + np.sin(0.3) * (0.169 + 0.170 + 0.0529))


def test_rpy_round_trip():
    rng = np.random.default_rng(0)
    rpy = np.column_stack([rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)])
    np.testing.assert_allclose(rpy_from_rotation(rotation_from_rpy(rpy)), rpy, atol=1e-12)


@pytest.mark.parametrize("side", SIDES)
def test_ik_of_fk_round_trip(side):
    rng = np.random.default_rng(1)
    q = _random_joint_sets(rng, 500)
    pos, rot = leg_fk(q, side, LEG)
    q_ik, reachable = leg_ik(pos, rpy_from_rotation(rot), side, LEG)
    assert reachable.all()
    np.testing.assert_allclose(q_ik, q, atol=1e-8)  # unique solution in this (knee > 0) range
    pos2, rot2 = leg_fk(q_ik, side, LEG)
    assert np.abs(pos2 - pos).max() < 1e-6
    assert np.abs(rot2 - rot).max() < 1e-6


@pytest.mark.parametrize("side", SIDES)
def test_fk_of_ik_round_trip_over_random_reachable_targets(side):
    rng = np.random.default_rng(2)
    n = 2000
    sign = 1.0 if side == "left" else -1.0
    pos = np.column_stack(
        [rng.uniform(-0.12, 0.12, n), sign * 0.055 + rng.uniform(-0.1, 0.1, n), rng.uniform(-0.41, -0.25, n)]
    )
    rpy = rng.uniform(-0.35, 0.35, size=(n, 3))
    q, reachable = leg_ik(pos, rpy, side, LEG)
    assert np.isfinite(q).all()
    assert reachable.mean() > 0.8  # most of this box is inside the workspace
    pos2, rot2 = leg_fk(q[reachable], side, LEG)
    assert np.abs(pos2 - pos[reachable]).max() < 1e-6
    assert np.abs(rot2 - rotation_from_rpy(rpy[reachable])).max() < 1e-6


def test_left_and_right_solutions_are_mirror_images():
    rng = np.random.default_rng(3)
    q = _random_joint_sets(rng, 100)
    pos, rot = leg_fk(q, "left", LEG)
    rpy = rpy_from_rotation(rot)
    mirrored_pos = pos * [1, -1, 1]
    mirrored_rpy = rpy * [-1, 1, -1]
    q_right, ok = leg_ik(mirrored_pos, mirrored_rpy, "right", LEG)
    assert ok.all()
    np.testing.assert_allclose(q_right, q * [-1, -1, 1, 1, 1, -1], atol=1e-8)


def test_out_of_reach_is_flagged_clamped_and_never_nan():
    targets = np.array([[0.0, 0.055, -0.6], [0.5, 0.055, -0.2], [0.0, 0.055, -0.0414 - 0.0529]])
    q, reachable = leg_ik(targets, np.zeros((3, 3)), "left", LEG)
    assert not reachable.any()
    assert np.isfinite(q).all()
    assert q[0, 3] == pytest.approx(0.0)  # too far: straight knee, pointing at the target
    pos, _ = leg_fk(q[:1], "left", LEG)
    np.testing.assert_allclose(pos[0], [0.0, 0.055, -LEG.straight_leg_length], atol=1e-9)


def test_joint_limits_clip_and_flag():
    q_true = np.array([[0.0, 0.0, -0.6, 1.2, -0.6, 0.0]])
    pos, rot = leg_fk(q_true, "left", LEG)
    limits = np.array([[-1, 1], [-1, 1], [-1, 1], [-0.2, 1.0], [-1, 1], [-1, 1]], dtype=float)
    q, reachable = leg_ik(pos, rpy_from_rotation(rot), "left", LEG, limits=limits)
    assert not reachable[0]
    assert q[0, 3] == pytest.approx(1.0)
    q, reachable = leg_ik(pos, rpy_from_rotation(rot), "left", LEG, limits=np.tile([-3.0, 3.0], (6, 1)))
    assert reachable[0]
    np.testing.assert_allclose(q, q_true, atol=1e-9)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_targets_raise(bad):
    with pytest.raises(ValueError):
        leg_ik(np.array([[0.0, 0.055, bad]]), np.zeros((1, 3)), "left", LEG)
    with pytest.raises(ValueError):
        leg_ik(np.array([[0.0, 0.055, -0.35]]), np.array([[0.0, bad, 0.0]]), "left", LEG)


def test_unknown_side_raises():
    with pytest.raises(ValueError):
        leg_ik(np.zeros((1, 3)), np.zeros((1, 3)), "middle", LEG)


@pytest.mark.parametrize("tilted_soles", [False, True])
def test_compiled_both_legs_ik_reproduces_fk_in_any_trunk_frame(tilted_soles):
    """legs_ik takes world-frame trunk and sole poses; FK of its answer (in the trunk frame) must
    give back the soles, and it must agree with the numpy per-leg solver."""
    rng = np.random.default_rng(11)
    n = 64
    q_true = {side: _random_joint_sets(rng, n) for side in SIDES}
    trunk = np.vstack(
        [
            rng.uniform(-1, 1, (2, n)),
            rng.uniform(0.3, 0.5, (1, n)),
            rng.uniform(-0.3, 0.3, (2, n)),
            rng.uniform(-np.pi, np.pi, (1, n)),
        ]
    )
    Rt = rotation_from_rpy(trunk[3:].T)  # (n, 3, 3)
    world = {}
    for side in SIDES:
        pos, rot = leg_fk(q_true[side], side, LEG)  # in the trunk frame
        pos_w = trunk[:3].T + np.einsum("nij,nj->ni", Rt, pos)
        rpy_w = rpy_from_rotation(Rt @ rot)
        if not tilted_soles:  # the walk's soles: exactly flat in the world (some become unreachable)
            rpy_w[:, :2] = 0.0
        world[side] = np.vstack([pos_w.T, rpy_w.T])
    q, reachable = legs_ik(trunk, world["left"], world["right"], LEG)
    assert q.shape == (n, 12) and reachable.sum() >= (n if tilted_soles else n // 2)
    both = np.ones(n, dtype=bool)
    for k, side in enumerate(SIDES):
        sole = world[side]
        p_local = np.einsum("nji,nj->ni", Rt, sole[:3].T - trunk[:3].T)
        R_local = np.transpose(Rt, (0, 2, 1)) @ rotation_from_rpy(sole[3:].T)
        q_numpy, reachable_numpy = leg_ik_rotation(p_local, R_local, side, LEG)
        np.testing.assert_allclose(q[:, 6 * k : 6 * k + 6], q_numpy, atol=1e-12)
        both &= reachable_numpy
        pos, rot = leg_fk(q[reachable, 6 * k : 6 * k + 6], side, LEG)
        np.testing.assert_allclose(pos, p_local[reachable], atol=1e-9)
        np.testing.assert_allclose(rot, R_local[reachable], atol=1e-9)
    np.testing.assert_array_equal(reachable, both)
    # limits: knees capped below their angle are clipped and flagged, the rest untouched
    limits = np.tile([-4.0, 4.0], (12, 1))
    limits[3] = [0.0, 1.0]  # left knee
    clipped, within = legs_ik(trunk, world["left"], world["right"], LEG, limits)
    over = q[:, 3] > 1.0 + 1e-9
    assert over.any() and (~over).any()
    np.testing.assert_array_equal(within, reachable & ~over)
    np.testing.assert_allclose(clipped[:, 3], np.minimum(q[:, 3], 1.0))
    np.testing.assert_array_equal(np.delete(clipped, 3, axis=1), np.delete(q, 3, axis=1))
