"""QuinticWalk: timing, footstep accuracy (FK of the IK output), continuity, orders, bad input."""

import math

import numpy as np
import pytest

from footsim.geometry import Pose2D, wrap_angle
from footsim.walk import (
    DoubleStep,
    Footstep,
    FootstepGeometry,
    LegGeometry,
    QuinticWalk,
    Side,
    StepLimits,
    WalkParams,
    WalkState,
)
from footsim.walk.ik import leg_fk, legs_ik, rpy_from_rotation

LIMITS = StepLimits(0.156, 0.103, 0.764)
LEG = LegGeometry()
PARAMS = WalkParams()
# Every Bit-Bots shaping parameter away from its neutral default at once.
SHAPED = WalkParams(
    foot_apex_pitch=0.1,
    foot_overshoot_ratio=0.1,
    foot_overshoot_phase=0.85,
    foot_z_pause=0.1,
    foot_put_down_phase=0.9,
    foot_put_down_z_offset=0.005,
    trunk_pause=0.1,
    first_step_trunk_phase=-0.5,
    trunk_x_offset=-0.02,  # the x coefficients move the trunk forward: this keeps big turns within reach
    trunk_x_offset_p_coef_forward=0.1,
    trunk_x_offset_p_coef_turn=0.02,
)


def make_engine(params: WalkParams = PARAMS, control_dt: float = 1 / 500, **kwargs) -> QuinticWalk:
    geometry = FootstepGeometry(LIMITS, foot_distance=params.foot_distance)
    return QuinticWalk(params, geometry, LEG, control_dt, **kwargs)


def random_double_steps(n, scale, seed):
    rng = np.random.default_rng(seed)
    return [DoubleStep.from_action(rng.uniform(-scale, scale, 6), LIMITS) for _ in range(n)]


def sole_relative_pose(q_support, support: Side, q_flying, flying: Side):
    """Flying sole pose in the support sole's frame, from FK of both legs: (x, y, z, r, p, y)."""
    ps, Rs = leg_fk(q_support[None], support.value, LEG)
    pf, Rf = leg_fk(q_flying[None], flying.value, LEG)
    rel_p = Rs[0].T @ (pf[0] - ps[0])
    rel_rpy = rpy_from_rotation(Rs[0].T @ Rf[0])
    return np.concatenate([rel_p, rel_rpy])


def legs(joints):
    return {Side.LEFT: joints[:6], Side.RIGHT: joints[6:]}


# --- timing ----------------------------------------------------------------------------------


@pytest.mark.parametrize("freq,dt", [(1.9633, 1 / 500), (1.7294, 1 / 240), (2.5, 1 / 1000), (1.0, 1 / 500)])
def test_double_step_lasts_one_period_of_whole_ticks(freq, dt):
    engine = make_engine(WalkParams(freq=freq), control_dt=dt)
    n = round(1 / (freq * dt))
    assert engine.ticks_per_double_step == n
    assert abs(engine.double_step_duration - 1 / freq) <= dt / 2 + 1e-12
    assert engine.freq == pytest.approx(1 / (n * dt))
    first = engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    assert len(first) == engine.start_ticks + n  # the start movement is prepended when IDLE
    for _ in range(3):
        traj = engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
        assert len(traj) == n
        assert traj.duration == pytest.approx(n * dt)
        np.testing.assert_allclose(np.diff(traj.t), dt)
        np.testing.assert_allclose(traj.phase, np.mod(np.arange(1, n + 1) * dt * engine.freq, 1.0), atol=1e-9)
        assert ((traj.phase >= 0) & (traj.phase < 1)).all()
        np.testing.assert_array_equal(traj.support, traj.phase < 0.5)
    assert engine.time == pytest.approx((engine.start_ticks + 4 * n) * dt)


def test_state_sequence_start_walk_stop():
    engine = make_engine()
    assert engine.state == WalkState.IDLE
    assert len(engine.stop()) == 0  # nothing to stop
    traj = engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    kinds = [WalkState(k) for k in dict.fromkeys(traj.state.tolist())]
    assert kinds == [WalkState.START_MOVEMENT, WalkState.START_STEP, WalkState.WALKING]
    assert engine.state == WalkState.WALKING
    # The start movement moves only the trunk: the feet stay put.
    start = traj.state == WalkState.START_MOVEMENT
    assert np.ptp(traj.left_foot[start], axis=0).max() < 1e-12 and np.ptp(traj.right_foot[start], axis=0).max() < 1e-12
    assert np.ptp(traj.trunk[start, 1]) > 0.005
    stop = engine.stop()
    assert len(stop) == engine.ticks_per_double_step
    assert [WalkState(k) for k in dict.fromkeys(stop.state.tolist())] == [WalkState.STOP_STEP, WalkState.STOP_MOVEMENT]
    assert engine.state == WalkState.IDLE


def test_stop_returns_to_the_standing_pose():
    engine = make_engine()
    standing = engine.standing_joint_targets()
    for ds in random_double_steps(3, 0.5, seed=5):
        engine.double_step(ds)
    stop = engine.stop()
    feet = stop.feet
    np.testing.assert_allclose(feet.left.relative(feet.right), [0.0, -engine.params.foot_distance, 0.0], atol=1e-12)
    np.testing.assert_allclose(stop.joint_targets[-1], standing, atol=1e-9)
    # ... and the standing pose stands: both soles flat on the ground, foot_distance apart.
    q = legs(standing)
    rel = sole_relative_pose(q[Side.LEFT], Side.LEFT, q[Side.RIGHT], Side.RIGHT)
    np.testing.assert_allclose(rel, [0, -engine.params.foot_distance, 0, 0, 0, 0], atol=1e-9)
    p_left, R_left = leg_fk(q[Side.LEFT][None], "left", LEG)
    trunk_in_sole = R_left[0].T @ -p_left[0]
    assert trunk_in_sole[2] == pytest.approx(engine.params.trunk_height, abs=1e-9)
    assert rpy_from_rotation(R_left[0].T)[1] == pytest.approx(engine.params.trunk_pitch, abs=1e-9)


def test_standing_pose_is_mirror_symmetric_without_lateral_offset():
    q = make_engine(WalkParams(trunk_y_offset=0.0)).standing_joint_targets()
    np.testing.assert_allclose(q[6:], q[:6] * [-1, -1, 1, 1, 1, -1], atol=1e-9)
    assert 0.5 < q[3] < 1.5  # a walk-ready crouch, not a straight leg


# --- footsteps land where the planar geometry says --------------------------------------------


@pytest.mark.parametrize("params", [PARAMS, SHAPED], ids=["default", "shaped"])
def test_put_down_pose_by_fk_equals_landing_for_every_footstep(params):
    engine = make_engine(params)
    geometry = engine.geometry
    extreme = DoubleStep(Footstep(0.3, -0.2, 1.0), Footstep(-0.3, 0.2, -1.0))
    orders = random_double_steps(20, 0.6, seed=11) + [
        extreme,
        DoubleStep(Footstep(0.15, 0.0, 0.7), Footstep(0.15, 0.0, 0.7)),
    ]
    feet = engine.feet
    for ds in orders:
        traj = engine.double_step(ds)
        n = engine.ticks_per_double_step
        # Last tick of each half step = the put-down instant (≤ dt/2 before it for odd n).
        first_end = len(traj) - n + int(math.floor(n / 2))
        for tick, (flying, step) in zip((first_end - 1, len(traj) - 1), ds.steps()):
            expected, executed, _ = geometry.landing(flying, step)
            q = legs(traj.joint_targets[tick])
            rel = sole_relative_pose(q[flying.other], flying.other, q[flying], flying)
            if not traj.reachable[tick]:
                # Only the deliberately extreme order may leave the leg's workspace; then the
                # IK says so (and its clamped pose cannot match).
                assert ds is extreme
                continue
            assert abs(rel[0] - expected.x) < 1e-3 and abs(rel[1] - expected.y) < 1e-3
            assert abs(rel[2]) < 1e-3
            assert abs(wrap_angle(rel[5] - expected.theta)) < math.radians(0.1)
            assert abs(rel[3]) < math.radians(0.1) and abs(rel[4]) < math.radians(0.1)
        # The planar bookkeeping agrees with FootstepGeometry.execute (shared with the 2D backend).
        _, after, executed_ds, _ = geometry.execute(feet, ds)
        assert traj.executed == executed_ds
        for side in Side:
            np.testing.assert_allclose(traj.feet.foot(side), after.foot(side), atol=1e-12)
        feet = traj.feet


def test_requests_beyond_the_limits_are_clipped():
    engine = make_engine()
    traj = engine.double_step(DoubleStep(Footstep(1.0, -1.0, -2.0), Footstep(-1.0, 1.0, 2.0)))
    first, second = traj.executed.first, traj.executed.second
    assert (first.x, first.y, first.theta) == (LIMITS.x, -LIMITS.y, -LIMITS.theta)
    assert (second.x, second.y, second.theta) == (-LIMITS.x, LIMITS.y, LIMITS.theta)
    rel = traj.feet.right.relative(traj.feet.left)  # left landed relative to the right foot
    assert rel.x == pytest.approx(-LIMITS.x) and rel.y == pytest.approx(engine.params.foot_distance + LIMITS.y)
    assert rel.theta == pytest.approx(LIMITS.theta)


# --- continuity --------------------------------------------------------------------------------


def _finite_differences(poses, dt):
    p = poses.copy()
    p[:, 3:] = np.unwrap(p[:, 3:], axis=0)
    vel = np.diff(p, axis=0) / dt
    acc = np.diff(vel, axis=0) / dt
    return p, vel, acc


@pytest.mark.parametrize("params", [PARAMS, SHAPED], ids=["default", "shaped"])
def test_feet_and_trunk_are_c2_across_half_step_boundaries(params):
    engine = make_engine(params)
    trajs = [engine.double_step(ds) for ds in random_double_steps(20, 0.5, seed=21)] + [engine.stop()]
    dt = engine.control_dt
    states = np.concatenate([t.state for t in trajs])
    support = np.concatenate([t.support for t in trajs])
    # Ticks where a new half step (new support frame, rebuilt splines) begins.
    boundaries = np.flatnonzero((np.diff(support.astype(int)) != 0) | (np.diff(states) != 0)) + 1
    assert len(boundaries) >= 40
    for name in ("left_foot", "right_foot", "trunk"):
        poses = np.concatenate([getattr(t, name) for t in trajs])
        p, vel, acc = _finite_differences(poses, dt)
        for series in (p, vel, acc):
            jumps = np.abs(np.diff(series, axis=0))
            for b in boundaries:
                if b < 8 or b > len(jumps) - 8:
                    continue
                here = jumps[b - 2 : b + 1].max(axis=0)  # the differences that straddle the boundary
                around = np.maximum(jumps[b - 8 : b - 3].max(axis=0), jumps[b + 2 : b + 7].max(axis=0))
                # A discontinuity shows as one difference far above its neighbours.
                assert np.all(here <= 3.0 * around + 1e-9), (name, b, here, around)
        assert np.isfinite(poses).all()


def test_trunk_yaw_is_the_mean_of_the_feet():
    engine = make_engine()
    for ds in random_double_steps(5, 0.8, seed=8):
        traj = engine.double_step(ds)
        half = 0.5 * np.angle(np.exp(1j * (traj.right_foot[:, 5] - traj.left_foot[:, 5])))
        expected = np.angle(np.exp(1j * (traj.left_foot[:, 5] + half)))
        np.testing.assert_allclose(np.angle(np.exp(1j * (traj.trunk[:, 5] - expected))), 0.0, atol=1e-9)


def test_support_frame_trunk_is_the_odometry_trunk_seen_from_the_support_sole():
    """The 3D driver reads roll and pitch from ``trunk_in_support``: they (and z) must equal the
    odometry-frame trunk's, and x, y, yaw must be the trunk seen from the support sole."""
    engine = make_engine()
    for ds in random_double_steps(4, 0.8, seed=3):
        traj = engine.double_step(ds)
        local, world = traj.trunk_in_support, traj.trunk
        np.testing.assert_array_equal(local[:, 2:5], world[:, 2:5])
        # A half step's last tick (phase 0.5 or 1) is the put-down instant: both soles are down and
        # ``support`` already names the next one, so those ticks are left out here.
        inside = ~np.isclose(np.mod(traj.phase, 0.5), 0.0)
        sole = np.where(traj.support[:, None], traj.left_foot, traj.right_foot)[inside]  # odometry frame
        local, world = local[inside], world[inside]
        c, s = np.cos(sole[:, 5]), np.sin(sole[:, 5])
        np.testing.assert_allclose(sole[:, 0] + c * local[:, 0] - s * local[:, 1], world[:, 0], atol=1e-12)
        np.testing.assert_allclose(sole[:, 1] + s * local[:, 0] + c * local[:, 1], world[:, 1], atol=1e-12)
        np.testing.assert_allclose(np.angle(np.exp(1j * (sole[:, 5] + local[:, 5] - world[:, 5]))), 0.0, atol=1e-12)
        assert inside.sum() >= len(traj) - 3


def test_flying_foot_lifts_to_foot_rise_and_support_foot_stays_down():
    params = WalkParams()
    engine = make_engine(params)
    engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    traj = engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    left_support = traj.support
    assert traj.right_foot[left_support, 2].max() == pytest.approx(params.foot_rise, abs=2e-4)
    assert np.abs(traj.left_foot[left_support, 2]).max() < 1e-12  # the last tick is a put-down instant
    assert traj.left_foot[~left_support, 2].max() == pytest.approx(params.foot_rise, abs=2e-4)
    # x holds through double support, then moves.
    n_double = int(params.double_support_ratio * engine.half_period / engine.control_dt)
    assert n_double >= 1
    assert np.ptp(traj.right_foot[:n_double, 0]) < 1e-9
    assert np.ptp(traj.right_foot[: len(traj) // 2, 0]) > 0.09


def test_joint_targets_are_sane_and_never_nan():
    engine = make_engine()
    trajs = [engine.double_step(ds) for ds in random_double_steps(20, 1.0, seed=31)] + [engine.stop()]
    q = np.concatenate([t.joint_targets for t in trajs])
    reachable = np.concatenate([t.reachable for t in trajs])
    assert np.isfinite(q).all()
    assert np.abs(q).max() < 2.0
    knees = q[:, [3, 9]]
    assert knees.min() >= 0.0 and knees.max() < 2.8
    assert reachable.mean() > 0.9  # even full-range random steps are mostly reachable
    moderate = make_engine()
    trajs = [moderate.double_step(ds) for ds in random_double_steps(10, 0.5, seed=32)]
    assert all(t.reachable.all() for t in trajs)


def test_joint_targets_solved_a_half_step_at_a_time_are_the_batch_ik():
    """``WalkTrajectory.solve`` (the 3D driver's, a half step at a time) gives the bits of the
    batch IK of all ticks (``legs_ik``), and solves no further than the half step it needs."""
    limits = np.tile([-1.2, 1.2], (12, 1))
    engine = make_engine(joint_limits=limits)
    for ds in random_double_steps(4, 0.8, seed=33):
        traj = engine.double_step(ds)
        local = traj.local_poses
        expected, reachable = legs_ik(local[2], local[0], local[1], LEG, limits)
        first_half = traj.half_step_ends[-2]
        joints, ok, solved = traj.solve(first_half - 3)
        assert solved == first_half
        assert np.array_equal(joints[:solved], expected[:solved]) and np.array_equal(ok[:solved], reachable[:solved])
        assert np.array_equal(traj.joint_targets, expected) and np.array_equal(traj.reachable, reachable)


def test_joint_limits_are_applied_and_reported():
    engine = make_engine(joint_limits=np.tile([-0.3, 0.3], (12, 1)))
    traj = engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    assert np.abs(traj.joint_targets).max() <= 0.3 + 1e-12
    assert not traj.reachable.any()  # the crouch needs > 0.3 rad at the knee
    with pytest.raises(ValueError):
        make_engine(joint_limits=np.zeros((6, 2)))


# --- velocity orders ---------------------------------------------------------------------------


def test_velocity_orders_give_v_over_two_freq_per_step():
    engine = make_engine()
    f = engine.freq
    assert f == pytest.approx(1 / 0.510)  # 255 ticks at 500 Hz
    ds = engine.footsteps_from_velocity(0.2, 0.0, 0.0)
    assert ds.first == ds.second == Footstep(0.2 / (2 * f), 0.0, 0.0)
    assert ds.first.x == pytest.approx(0.051)
    # Lateral and turning steps only on the outward foot; the other foot returns to rest.
    ds = engine.footsteps_from_velocity(0.0, 0.05, 0.3)
    assert ds.first == Footstep(0.0, 0.0, 0.0)
    assert ds.second == Footstep(0.0, pytest.approx(0.05 / (2 * f)), pytest.approx(0.3 / (2 * f)))
    ds = engine.footsteps_from_velocity(-0.1, -0.05, -0.3)
    assert ds.second == Footstep(pytest.approx(-0.1 / (2 * f)), 0.0, 0.0)
    assert ds.first == Footstep(
        pytest.approx(-0.1 / (2 * f)), pytest.approx(-0.05 / (2 * f)), pytest.approx(-0.3 / (2 * f))
    )


def test_velocity_orders_respect_limits_and_multipliers():
    engine = make_engine(WalkParams(x_speed_multiplier=0.5, y_speed_multiplier=2.0))
    f = engine.freq
    ds = engine.footsteps_from_velocity(0.2, 0.05, 0.0)
    assert ds.first.x == pytest.approx(0.5 * 0.2 / (2 * f))
    assert ds.second.y == pytest.approx(2.0 * 0.05 / (2 * f))
    ds = engine.footsteps_from_velocity(5.0, -5.0, 50.0)
    assert ds.first == Footstep(LIMITS.x, -LIMITS.y, 0.0)
    assert ds.second == Footstep(LIMITS.x, 0.0, LIMITS.theta)


def test_velocity_double_step_walks_at_the_commanded_forward_speed():
    engine = make_engine()
    engine.velocity_double_step(0.15, 0.0, 0.0)
    start = engine.feet.nav_pose
    for _ in range(4):
        traj = engine.velocity_double_step(0.15, 0.0, 0.0)
    assert traj.executed == engine.footsteps_from_velocity(0.15, 0.0, 0.0)
    travelled = engine.feet.nav_pose.x - start.x
    assert travelled / (4 * engine.double_step_duration) == pytest.approx(0.15, rel=1e-9)


# --- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_orders_raise_and_leave_the_engine_untouched(bad):
    engine = make_engine()
    engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    time_before, feet_before = engine.time, engine.feet
    with pytest.raises(ValueError):
        engine.double_step(DoubleStep(Footstep(bad, 0.0, 0.0), Footstep()))
    with pytest.raises(ValueError):
        engine.double_step(DoubleStep(Footstep(), Footstep(0.0, 0.0, bad)))
    for order in ((bad, 0.0, 0.0), (0.0, bad, 0.0), (0.0, 0.0, bad)):
        with pytest.raises(ValueError):
            engine.velocity_double_step(*order)
        with pytest.raises(ValueError):
            engine.footsteps_from_velocity(*order)
    assert engine.time == time_before and engine.feet == feet_before


@pytest.mark.parametrize(
    "field,value",
    [
        ("freq", 0.0),
        ("freq", -1.0),
        ("double_support_ratio", 1.0),
        ("double_support_ratio", -0.1),
        ("foot_rise", -0.01),
        ("trunk_height", math.nan),
    ],
)
def test_invalid_walk_params_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        WalkParams(**{field: value})


def test_engine_rejects_inconsistent_configuration():
    with pytest.raises(ValueError, match="foot_distance"):
        QuinticWalk(WalkParams(foot_distance=0.2), FootstepGeometry(LIMITS, foot_distance=0.18))
    with pytest.raises(ValueError, match="foot_apex_phase"):
        make_engine(WalkParams(foot_apex_phase=0.8, foot_put_down_phase=0.7))
    with pytest.raises(ValueError, match="control_dt"):
        make_engine(control_dt=0.0)


def test_walk_config_matches_walk_params():
    from footsim.config import load_preset

    assert WalkParams.from_mapping(load_preset("walk", "default")) == WalkParams()


def test_reset_places_the_feet_around_a_pose():
    engine = make_engine()
    engine.double_step(DoubleStep(Footstep(0.05), Footstep(0.05)))
    engine.reset(Pose2D(1.0, 2.0, 0.5))
    assert engine.state == WalkState.IDLE and engine.time == 0.0
    nav = engine.feet.nav_pose
    assert (nav.x, nav.y, nav.theta) == pytest.approx((1.0, 2.0, 0.5))
    traj = engine.double_step(DoubleStep(Footstep(), Footstep()))
    assert traj.trunk[0, 5] == pytest.approx(0.5)


def test_walkplot_cli_writes_a_png(tmp_path):
    from footsim.tools.walkplot import main

    out = tmp_path / "walk.png"
    main([f"out={out}", "steps=0.05,0,0.2,0.05,0.03,0.2", "n=1", "stop=false"])
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(SystemExit):
        main(["steps=0,0,0,0,0,0"])  # out= is required
    with pytest.raises(SystemExit):
        main([f"out={out}", "steps=nan,0,0,0,0,0"])


def test_swing_path_goes_around_the_support_foot():
    """A turned foot stepping inward after an inward, turned step: both put-down poses are clear
    of the other foot, but the straight (x, y, yaw) path between them sweeps the turning plate
    over the support foot.  The engine detours outward so no tick of the swing overlaps."""
    engine = make_engine()
    geometry = engine.geometry
    touching = FootstepGeometry(
        geometry.limits, geometry.foot_length, geometry.foot_width, geometry.foot_distance, min_foot_gap=0.0
    )
    overlaps = 0
    for action in ([-0.93, 0.79, 0.32, 0.8, -0.77, 0.97], [0.07, 0.32, -0.24, 0.47, 0.32, 0.68]):
        trajectory = engine.double_step(DoubleStep.from_action(action, LIMITS))
        for left, right in zip(trajectory.left_foot, trajectory.right_foot):
            rel = Pose2D(*left[[0, 1, 5]]).relative(Pose2D(*right[[0, 1, 5]]))
            overlaps += touching.feet_interfere(rel.x, rel.y, rel.theta)
    assert overlaps == 0
