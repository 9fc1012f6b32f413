"""Label-efficiency curves: an arm's success, as a share of the oracle's, against the labels its runs
used, read off at several budgets; from it, the labels the arm needs to reach 90% of the oracle (with
a bootstrap interval over seeds) and the area under the curve on a log axis of labels.

The seeds are paired: a seed's runs at every budget of an arm and the oracle's run of that seed are
resampled together, so the interval carries the seeds' spread in the oracle's success as well.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass

import numpy as np

RESAMPLES = 10_000
"""Bootstrap resamples of the seeds (the count ``dospcot.statistics.SeedSummary`` draws)."""
SHARE = 0.9
"""The share of the oracle's success an arm must reach."""


@dataclass(frozen=True)
class Curve:
    """One arm on one task, over the seeds run at every one of its budgets and by the oracle.

    :param budgets: (B,) the label budgets the columns were run at, ascending.
    :param labels: (S, B) the labels each seed's run used at each budget (counted from its files).
    :param success: (S, B) each run's success.
    :param oracle: (S,) the oracle's success on each seed.
    :param pairs: (S,) what pairs each row with another arm's (its seed, and its map on a task of several),
        empty where the rows need no pairing.
    """

    budgets: np.ndarray
    labels: np.ndarray
    success: np.ndarray
    oracle: np.ndarray
    pairs: tuple[Hashable, ...] = ()

    def shares(self) -> np.ndarray:
        """(S, B) each run's success as a share of the oracle's mean success."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.success / self.oracle.mean()

    def share(self) -> tuple[np.ndarray, np.ndarray]:
        """(B,) the mean labels used at each budget, sorted, and the mean success there as a share of
        the oracle's mean success."""
        x, y = _mean_share(self.labels[None], self.success[None], self.oracle[None])
        return x[0], y[0]

    def labels_to_reach(self) -> float:
        """The labels at which the mean curve first reaches :data:`SHARE` of the oracle, interpolated
        linearly between budgets; inf where no budget reaches it."""
        x, y = self.share()
        return float(first_reach(x[None], y[None])[0])

    def labels_interval(self, seed: int = 0) -> tuple[float, float]:
        """The 95% percentile bootstrap interval of :meth:`labels_to_reach` over the seeds (inf where
        over 2.5% of the resamples never reach it)."""
        draws = np.random.default_rng(seed).integers(0, len(self.oracle), (RESAMPLES, len(self.oracle)))
        x, y = _mean_share(self.labels[draws], self.success[draws], self.oracle[draws])
        # Order statistics, not interpolation: a resample that never reaches the share is inf.
        low, high = np.percentile(first_reach(x, y), [2.5, 97.5], method="inverted_cdf")
        return float(low), float(high)

    def ends(self) -> tuple[float, float]:
        """The most labels any of the curve's runs used, and the fewest its budgets used on average: the
        range :func:`labels_text` reads a value against."""
        return float(np.max(self.labels)), float(self.labels.mean(axis=0).min())

    def reach_text(self) -> str:
        """:meth:`labels_to_reach` as a table cell (:func:`labels_text`)."""
        return labels_text(self.labels_to_reach(), *self.ends())

    def area(self) -> float:
        """The area under the share curve over log labels, from the arm's smallest budget to its
        largest, divided by that width: the oracle's curve (share 1 everywhere) scores 1. NaN with one
        budget."""
        return float(_areas(self, np.arange(len(self.oracle))[None])[0])


def labels_ratio(mine: Curve, theirs: Curve, seed: int = 0) -> tuple[float, float, float]:
    """The labels ``mine`` needs to reach :data:`SHARE` of the oracle over the labels ``theirs`` needs, on
    the pairs both ran, with its 95% percentile bootstrap interval (the pairs resampled together): 0
    where only ``mine`` reaches it, inf where only ``theirs`` does, and 1 where neither does (no budget
    tells them apart). NaN throughout where they share no pair."""
    return _paired(mine, theirs, lambda a, b, draws: _ratio(_reach(a, draws), _reach(b, draws)), seed)


def area_difference(mine: Curve, theirs: Curve, seed: int = 0) -> tuple[float, float, float]:
    """The area under ``mine`` minus the area under ``theirs`` (:meth:`Curve.area`, each over its own
    budgets), on the pairs both ran, with its 95% percentile bootstrap interval (the pairs resampled
    together). NaN throughout where they share no pair or a curve has one budget."""
    return _paired(mine, theirs, lambda a, b, draws: _areas(a, draws) - _areas(b, draws), seed)


def _paired(
    mine: Curve, theirs: Curve, statistic: Callable[[Curve, Curve, np.ndarray], np.ndarray], seed: int
) -> tuple[float, float, float]:
    """``statistic`` of two curves on the pairs both ran, (R,) from each resample (R, S) of those pairs'
    rows: its value on every pair once, and its 95% percentile bootstrap interval."""
    both = [p for p in mine.pairs if p in set(theirs.pairs)]
    if not both:
        return math.nan, math.nan, math.nan
    a, b = (_rows(curve, both) for curve in (mine, theirs))
    draws = np.random.default_rng(seed).integers(0, len(both), (RESAMPLES, len(both)))
    point = statistic(a, b, np.arange(len(both))[None])
    low, high = np.percentile(statistic(a, b, draws), [2.5, 97.5], method="inverted_cdf")
    return float(point[0]), float(low), float(high)


def _areas(curve: Curve, draws: np.ndarray) -> np.ndarray:
    """(R,) :meth:`Curve.area` of each resample (R, S) of the curve's rows."""
    x, y = _mean_share(curve.labels[draws], curve.success[draws], curve.oracle[draws])
    if x.shape[1] < 2:
        return np.full(len(x), math.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_x = np.log(x)
        width = log_x[:, -1] - log_x[:, 0]
        area = np.sum((y[:, 1:] + y[:, :-1]) / 2 * np.diff(log_x, axis=1), axis=1) / width
    # No labels at the smallest budget, or one budget's worth of labels at every budget: no log width.
    return np.where((x[:, 0] > 0) & (width > 0), area, math.nan)


def _rows(curve: Curve, pairs: list[Hashable]) -> Curve:
    """``curve`` on ``pairs`` alone, in their order."""
    index = [curve.pairs.index(p) for p in pairs]
    return Curve(curve.budgets, curve.labels[index], curve.success[index], curve.oracle[index], tuple(pairs))


def _reach(curve: Curve, draws: np.ndarray) -> np.ndarray:
    """(R,) the labels to reach :data:`SHARE` on each resample (R, S) of the curve's rows."""
    return first_reach(*_mean_share(curve.labels[draws], curve.success[draws], curve.oracle[draws]))


def _ratio(mine: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """``mine / theirs``, which is 0 and inf where one is inf; 1 where both are."""
    with np.errstate(invalid="ignore"):
        return np.where(np.isinf(mine) & np.isinf(theirs), 1.0, mine / theirs)


def _mean_share(labels: np.ndarray, success: np.ndarray, oracle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per resample (R, S, B) of runs and (R, S) of oracle runs: (R, B) the mean labels at each budget,
    sorted, and the mean success there over the oracle's mean (NaN where the oracle never succeeds)."""
    x, y = labels.mean(axis=1), success.mean(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        y = y / oracle.mean(axis=1)[:, None]
    order = np.argsort(x, axis=1)
    return np.take_along_axis(x, order, axis=1), np.take_along_axis(y, order, axis=1)


def first_reach(x: np.ndarray, y: np.ndarray, target: float = SHARE) -> np.ndarray:
    """(R,) for each row of (R, B) curves (x ascending), the x where y first reaches ``target``,
    interpolated linearly from the point before; inf where it never does."""
    reached = y >= target
    first = reached.argmax(axis=1)
    rows = np.arange(len(x))
    before = np.maximum(first - 1, 0)
    x0, y0, x1, y1 = x[rows, before], y[rows, before], x[rows, first], y[rows, first]
    with np.errstate(invalid="ignore", divide="ignore"):
        between = x0 + (target - y0) * (x1 - x0) / (y1 - y0)
    at = np.where(first == 0, x1, between)
    return np.where(reached.any(axis=1), at, np.inf)


def labels_text(value: float, largest: float, smallest: float = 0.0) -> str:
    """``value`` labels as a table cell: "> <largest>" where it is never reached, "<= <smallest>" where
    the smallest budget already reaches it (the curve cannot say how much less would)."""
    if math.isinf(value):
        return f"> {largest:,.0f}"
    return f"<= {smallest:,.0f}" if value <= smallest else f"{value:,.0f}"
