"""Statistics over training seeds: the mean with a 95 % bootstrap interval and the interquartile mean.

A condition's metric is one value per training seed (e.g. each seed's success rate on 500 scenes).
The interval is scipy's percentile bootstrap of the mean over those values (``scipy.stats.bootstrap``,
``method="percentile"``, a fixed generator seed, so a table regenerates identically); the
interquartile mean is ``scipy.stats.trim_mean(values, 0.25)``, the mean of the middle half (with
5 seeds: the middle 3).  Undefined values (NaN: e.g. the success time of a seed that never
succeeded) are left out and counted apart.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

#: Bootstrap resamples and generator seed of every interval the results page shows.
N_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class SeedStats:
    """A metric over training seeds: ``n`` finite values (``n_undefined`` NaNs left out)."""

    n: int
    mean: float
    ci_low: float
    ci_high: float
    iqm: float
    n_undefined: int = 0

    def as_dict(self, prefix: str = "") -> dict:
        return {
            f"{prefix}n": self.n,
            f"{prefix}mean": self.mean,
            f"{prefix}ci_low": self.ci_low,
            f"{prefix}ci_high": self.ci_high,
            f"{prefix}iqm": self.iqm,
            f"{prefix}n_undefined": self.n_undefined,
        }


def _finite(values: Iterable[float | None]) -> tuple[np.ndarray, int]:
    raw = [math.nan if v is None else float(v) for v in values]
    data = np.array([v for v in raw if math.isfinite(v)], dtype=float)
    return data, len(raw) - len(data)


def bootstrap_interval(
    values: Iterable[float | None],
    confidence: float = 0.95,
    n_resamples: int = N_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """The percentile bootstrap interval of the mean of ``values``; ``(nan, nan)`` with fewer than
    two finite values (no spread to resample); ``(v, v)`` when they are all ``v``."""
    from scipy.stats import bootstrap

    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    data, _ = _finite(values)
    if len(data) < 2:
        return math.nan, math.nan
    if np.all(data == data[0]):
        return float(data[0]), float(data[0])
    result = bootstrap(
        (data,),
        np.mean,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def iqm(values: Iterable[float | None]) -> float:
    """The interquartile mean (``scipy.stats.trim_mean(values, 0.25)``) of the finite values; NaN if none."""
    from scipy.stats import trim_mean

    data, _ = _finite(values)
    return float(trim_mean(data, 0.25)) if len(data) else math.nan


def seed_stats(values: Iterable[float | None], confidence: float = 0.95) -> SeedStats:
    """Mean, bootstrap interval and IQM of a metric's per-seed values."""
    values = list(values)
    data, undefined = _finite(values)
    low, high = bootstrap_interval(data, confidence)
    return SeedStats(
        n=len(data),
        mean=float(data.mean()) if len(data) else math.nan,
        ci_low=low,
        ci_high=high,
        iqm=iqm(data),
        n_undefined=undefined,
    )
