"""footsim.results.stats against values computed by hand (and by exact enumeration)."""

from __future__ import annotations

import math

import pytest

from footsim.results.stats import bootstrap_interval, iqm, seed_stats


def test_iqm_is_the_mean_of_the_middle_half():
    # sorted 0.1 0.2 | 0.3 0.5 0.6 0.7 | 0.9 1.0: two cut from each end, mean of the middle four
    assert iqm([0.2, 0.9, 0.5, 0.7, 0.1, 1.0, 0.3, 0.6]) == pytest.approx((0.3 + 0.5 + 0.6 + 0.7) / 4)
    # five seeds: int(0.25 * 5) = 1 cut from each end, the middle three
    assert iqm([0.98, 0.2, 1.0, 0.99, 0.97]) == pytest.approx((0.97 + 0.98 + 0.99) / 3)
    assert iqm([0.5, None, math.nan, 0.7]) == pytest.approx(0.6)  # undefined values left out
    assert math.isnan(iqm([None]))


def test_bootstrap_interval_of_one_failed_seed_in_five():
    """Values 0, 1, 1, 1, 1: a resample's mean is k/5 with k ~ Binomial(5, 0.8).  P(k <= 1) = 0.00672
    and P(k <= 2) = 0.05792 bracket 0.025, so the 2.5 % quantile is 2/5; P(k <= 4) = 0.67232 < 0.975,
    so the 97.5 % quantile is 5/5."""
    assert bootstrap_interval([0, 1, 1, 1, 1]) == (0.4, 1.0)


def test_bootstrap_interval_of_two_values_covers_both():
    # resample means 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4: the 2.5 % and 97.5 % quantiles are 0 and 1
    assert bootstrap_interval([0.0, 1.0]) == (0.0, 1.0)


def test_degenerate_inputs():
    assert bootstrap_interval([0.7, 0.7, 0.7]) == (0.7, 0.7)
    low, high = bootstrap_interval([0.7])
    assert math.isnan(low) and math.isnan(high)
    with pytest.raises(ValueError, match="confidence must be in"):
        bootstrap_interval([0.0, 1.0], confidence=95)


def test_seed_stats_counts_undefined_values_apart():
    stats = seed_stats([2.0, None, 4.0, math.nan, 3.0])
    assert (stats.n, stats.n_undefined) == (3, 2)
    assert stats.mean == pytest.approx(3.0) and stats.iqm == pytest.approx(3.0)  # trim_mean cuts none of 3
    assert 2.0 <= stats.ci_low < 3.0 < stats.ci_high <= 4.0
    assert seed_stats([1.0, 1.0]).as_dict("success_") == {
        "success_n": 2,
        "success_mean": 1.0,
        "success_ci_low": 1.0,
        "success_ci_high": 1.0,
        "success_iqm": 1.0,
        "success_n_undefined": 0,
    }
