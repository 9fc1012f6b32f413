"""Summaries of a metric over seeds: the mean, a 95% percentile bootstrap interval and the
interquartile mean, as the sweep reports and study tables print them (docs/design.md, "Statistics").
SciPy loads with this module only: a training run never imports it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats


def bootstrap_ci(
    values: np.ndarray, confidence: float = 0.95, n_resamples: int = 10_000, seed: int = 0
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``values``: ``scipy.stats.bootstrap`` with the
    percentile method, ``n_resamples`` resamples of the values drawn with replacement, from a generator
    seeded by ``seed`` (so a table rebuilds to the same digits). One value is its own interval (SciPy
    needs two); no value gives NaN. Why percentile and not SciPy's default BCa: docs/design.md,
    "Statistics"."""
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return float("nan"), float("nan")
    if values.size == 1:
        return float(values[0]), float(values[0])
    result = stats.bootstrap(
        (values,),
        np.mean,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean after dropping ``floor(n / 4)`` values at each end
    (``scipy.stats.trim_mean`` at 0.25, as rliable computes it)."""
    return float(stats.trim_mean(np.asarray(values, dtype=np.float64), 0.25))


@dataclass(frozen=True)
class SeedSummary:
    """A metric over seeds: mean, 95% bootstrap interval, IQM and the number of finite values."""

    mean: float
    low: float
    high: float
    iqm: float
    n: int

    @classmethod
    def of(cls, values: Sequence[float], iqm_min_n: int = 1) -> SeedSummary:
        """Summarise the finite ``values``; the IQM is NaN below ``iqm_min_n`` of them."""
        finite = np.array([v for v in values if math.isfinite(v)], dtype=np.float64)
        if finite.size == 0:
            return cls(math.nan, math.nan, math.nan, math.nan, 0)
        low, high = bootstrap_ci(finite)
        iqm_value = iqm(finite) if finite.size >= iqm_min_n else math.nan
        return cls(float(finite.mean()), low, high, iqm_value, int(finite.size))

    def __str__(self) -> str:
        if self.n == 0 or math.isnan(self.mean):
            return "n/a"
        digits = 1 if abs(self.mean) >= 10 else 3
        return f"{self.mean:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"
