"""The summaries over seeds (dospcot.metrics, SeedSummary) against cases worked by hand, not against
the functions themselves: every interval of the published tables comes from here."""

import math

import numpy as np
import pytest

from dospcot.statistics import SeedSummary, bootstrap_ci, iqm


def test_the_percentile_interval_of_a_tiny_sample_is_the_one_worked_on_paper():
    # A resample of [0, 0, 0, 1] holds the 1 k times, k ~ Binomial(4, 1/4), so its mean is k / 4 with
    # P(k = 0) = 81/256 (0.32), P(k >= 3) = 13/256 (0.051) and P(k = 4) = 1/256 (0.004). The 2.5%
    # quantile of the means is therefore 0, and the 97.5% quantile 0.75 (more than 2.5% of the
    # resamples reach 0.75, fewer than 2.5% reach 1). With 10,000 resamples the empirical shares sit
    # many standard errors away from 0.025, so any seed gives exactly this.
    for seed in (0, 1, 7):
        assert bootstrap_ci(np.array([0.0, 0.0, 0.0, 1.0]), seed=seed) == (0.0, 0.75)
    # [0, 1]: resample means 0, 0.5 and 1 with probabilities 1/4, 1/2, 1/4: the interval is [0, 1].
    assert bootstrap_ci(np.array([0.0, 1.0])) == (0.0, 1.0)


def test_degenerate_samples_have_the_value_itself_or_nothing_as_interval():
    assert bootstrap_ci(np.array([1.0, 1.0, 1.0])) == (1.0, 1.0)
    assert bootstrap_ci(np.array([2.5])) == (2.5, 2.5)
    assert all(math.isnan(bound) for bound in bootstrap_ci(np.array([])))


def test_a_seed_summary_drops_missing_values_and_prints_mean_and_interval():
    summary = SeedSummary.of([0.0, math.nan, 0.0, 0.0, 1.0])
    assert (summary.mean, summary.low, summary.high, summary.n) == (0.25, 0.0, 0.75, 4)
    assert str(summary) == "0.250 [0.000, 0.750]"
    assert str(SeedSummary.of([20.0, 22.0, 21.0, 23.0])).startswith("21.5 [")  # one decimal above 10
    assert str(SeedSummary.of([math.nan])) == "n/a"


def test_the_interquartile_mean_drops_a_quarter_at_each_end():
    # 8 values: drop the 2 lowest and the 2 highest, so the outlier 100 does not count.
    assert iqm(np.array([7.0, 1.0, 100.0, 3.0, 2.0, 5.0, 4.0, 6.0])) == pytest.approx(4.5)
    # 7 values: floor(7 / 4) = 1 at each end: the mean of 2..6.
    assert iqm(np.arange(1.0, 8.0)) == pytest.approx(4.0)
    # Fewer than 4 values: nothing is dropped.
    assert iqm(np.array([1.0, 2.0, 6.0])) == pytest.approx(3.0)
