"""Quintic spline primitives: end conditions, C2 knots, vectorised evaluation."""

import numpy as np
import pytest

from footsim.walk.spline import PiecewiseQuintic, QuinticSegment, knots_state, quintic_coefficients, sample_positions


def test_rest_to_rest_segment_is_the_textbook_minimum_jerk_polynomial():
    # (0,0,0) -> (1,0,0) over T = 1 is p(t) = 10 t^3 - 15 t^4 + 6 t^5.
    c = quintic_coefficients(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(c, [0, 0, 0, 10, -15, 6], atol=1e-12)
    seg = QuinticSegment.from_boundary((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 1.0)
    pos, vel, acc = seg.evaluate(np.array([0.5]))
    assert pos[0] == pytest.approx(0.5)
    assert vel[0] == pytest.approx(1.875)  # 30/4 - 60/8 + 30/16
    assert acc[0] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("duration", [0.01, 0.25, 1.0, 3.7])
def test_segment_end_conditions_are_exact(duration):
    rng = np.random.default_rng(int(duration * 100))
    for _ in range(20):
        start, end = rng.normal(size=3), rng.normal(size=3)
        seg = QuinticSegment.from_boundary(start, end, duration)
        pos, vel, acc = seg.evaluate(np.array([0.0, duration]))
        np.testing.assert_allclose([pos[0], vel[0], acc[0]], start, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose([pos[1], vel[1], acc[1]], end, rtol=1e-7, atol=1e-7)


def test_segment_rejects_non_positive_duration():
    with pytest.raises(ValueError):
        quintic_coefficients(0, 0, 0, 1, 0, 0, 0.0)


def _random_channels(rng, n_channels=5):
    channels = []
    for _ in range(n_channels):
        times = np.cumsum(rng.uniform(0.05, 0.4, size=rng.integers(2, 6)))
        channels.append([(t, *rng.normal(size=3)) for t in times])
    return channels


def test_piecewise_hits_every_knot_and_is_c2_there():
    rng = np.random.default_rng(3)
    channels = _random_channels(rng)
    spline = PiecewiseQuintic(channels)
    eps = 1e-10  # tiny: jerk × 2 eps must stay below the tolerance
    for c, knots in enumerate(channels):
        for t, p, v, a in knots:
            np.testing.assert_allclose(spline.state(t)[c], [p, v, a], rtol=1e-7, atol=1e-7)
        for t, *_ in knots[1:-1]:  # both neighbouring segments agree at inner knots
            before, after = spline.state(t - eps)[c], spline.state(t + eps)[c]
            np.testing.assert_allclose(before, after, atol=1e-5)


def test_vectorised_positions_match_scalar_states_and_per_channel_times():
    rng = np.random.default_rng(4)
    channels = _random_channels(rng, 4)
    spline = PiecewiseQuintic(channels)
    t = np.linspace(-0.1, 2.5, 57)
    pos, vel, acc = spline.evaluate(t)
    np.testing.assert_allclose(spline.positions(t), pos)
    for i in (0, 17, 56):
        np.testing.assert_allclose(np.stack([pos[:, i], vel[:, i], acc[:, i]], axis=1), spline.state(t[i]), atol=1e-9)
        for c, knots in enumerate(channels):
            np.testing.assert_allclose(knots_state(knots, t[i]), spline.state(t[i])[c], rtol=1e-9, atol=1e-9)
    per_channel = rng.uniform(0, 1.5, size=(4, 9))
    expected = np.stack([spline.positions(per_channel[c])[c] for c in range(4)])
    np.testing.assert_allclose(spline.positions(per_channel), expected)


def test_knots_default_velocity_and_acceleration_to_zero():
    spline = PiecewiseQuintic([[(0.0, 1.0), (2.0, 3.0)]])
    np.testing.assert_allclose(spline.state(0.0)[0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(spline.state(2.0)[0], [3, 0, 0], atol=1e-12)
    assert spline.state(1.0)[0, 0] == pytest.approx(2.0)


@pytest.mark.parametrize(
    "channels",
    [
        [[(0.0, 0.0), (0.0, 1.0)]],  # repeated time
        [[(0.0, 0.0), (1.0, 1.0), (0.5, 2.0)]],  # decreasing
        [[(0.0, 0.0)]],  # one knot
        [[(0.0, float("nan")), (1.0, 1.0)]],
        [[(0.0, 0.0), (float("inf"), 1.0)]],
        [],
    ],
)
def test_invalid_knots_raise(channels):
    with pytest.raises(ValueError):
        PiecewiseQuintic(channels)
    with pytest.raises(ValueError):
        sample_positions(channels, np.zeros((max(len(channels), 1), 3)))


def test_compiled_positions_equal_the_numpy_evaluation_bit_for_bit():
    """``positions`` (one compiled call) against ``evaluate`` (numpy segment search + Horner) on
    ragged channels: shared and per-channel times, exactly at knots, and extrapolated beyond both
    ends."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        channels = []
        for _ in range(int(rng.integers(1, 8))):
            times = np.cumsum(rng.uniform(0.01, 0.3, int(rng.integers(2, 7))))
            channels.append([(t, *rng.normal(0, 1, int(rng.integers(1, 4)))) for t in times])
        spline = PiecewiseQuintic(channels)
        knot_times = np.concatenate([[k[0] for k in c] for c in channels])
        shared = np.concatenate([rng.uniform(-0.5, 2.5, 40), knot_times])
        np.testing.assert_array_equal(spline.positions(shared), spline.evaluate(shared)[0])
        per_channel = rng.uniform(-0.5, 2.5, (len(channels), 30))
        per_channel[:, 0] = [c[-1][0] for c in channels]  # each channel's last knot
        expected = np.stack([spline.evaluate(row)[0][i] for i, row in enumerate(per_channel)])
        np.testing.assert_array_equal(spline.positions(per_channel), expected)
        # the walk engine's path: tables and sampling in one call, no spline object
        np.testing.assert_array_equal(sample_positions(channels, per_channel), expected)
