"""Reward classes: the distinct reward values seen in labels, per run.

Classes are numbered in order of first appearance, so a class keeps its index (and the classifier
output unit that stands for it) when a new reward value shows up later in training.
"""

from __future__ import annotations

import numpy as np


class _ClassValues:
    """A reward value per class: ``values`` (B, K) for B runs, or (K,) for one run; NaN where a run has
    no such class."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.values = np.full(shape, np.nan)
        """The value of each class, NaN where the run has no such class yet."""

    @property
    def mask(self) -> np.ndarray:
        """bool, the classes each run has (the shape of ``values``)."""
        return ~np.isnan(self.values)

    def decode(self, classes: np.ndarray) -> np.ndarray:
        """Reward value of each class index, (B, N) from (B, N) or (N,) from (N,); NaN for -1."""
        values = np.take_along_axis(self.values, np.clip(classes, 0, None), axis=-1)
        return np.where(classes >= 0, values, np.nan)

    def encode(self, rewards: np.ndarray) -> np.ndarray:
        """Class index of each reward, (B, N) from (B, N) or (N,) from (N,); -1 where unknown."""
        match = rewards[..., None] == self.values[..., None, :]
        return np.where(match.any(-1), match.argmax(-1), -1)


def _add_new_values(row: np.ndarray, rewards: np.ndarray, run: str) -> None:
    """Write the values of ``rewards`` that ``row`` (K,) lacks into its free classes, in order."""
    for value in rewards:
        if np.any(row == value):
            continue
        free = np.flatnonzero(np.isnan(row))
        if free.size == 0:
            raise ValueError(
                f"{run} saw more than {row.size} distinct reward values; raise max_classes "
                f"or bin a continuous reward into quantile classes"
            )
        row[free[0]] = value


class RewardClasses(_ClassValues):
    """The reward values each of ``n_runs`` runs has seen in its labels (the batched tabular runs).

    :param n_runs: number of independent runs.
    :param n_classes: K, the most distinct values a run may see (a config's ``max_classes``).
    """

    def __init__(self, n_runs: int, n_classes: int) -> None:
        super().__init__((n_runs, n_classes))

    def observe(self, run: int, rewards: np.ndarray) -> None:
        """Add the values of ``rewards`` (labels of run ``run``) not seen before, in the order given."""
        _add_new_values(self.values[run], rewards, f"run {run}")


class RunRewardClasses(_ClassValues):
    """The reward values one run has seen in its labels: :class:`RewardClasses` without the runs' axis
    (``values`` (K,); ``encode`` and ``decode`` (N,) from (N,)).

    :param n_classes: K, the most distinct values the run may see (a config's ``max_classes``).
    """

    def __init__(self, n_classes: int) -> None:
        super().__init__((n_classes,))

    def observe(self, rewards: np.ndarray) -> None:
        """Add the values of ``rewards`` (labels) not seen before, in the order given."""
        _add_new_values(self.values, rewards, "the run")


def _quantile_edges(rewards: np.ndarray, n_classes: int) -> np.ndarray:
    """The inner edges of ``n_classes`` quantile bins of ``rewards`` (n,): one bin per distinct value
    where there are at most ``n_classes``, however rare."""
    distinct = np.unique(rewards)
    if distinct.size <= n_classes:
        return distinct[1:]
    quantiles = np.quantile(rewards, np.arange(1, n_classes) / n_classes)
    # A quantile at or just above the minimum would leave a bin empty. Where the reward mostly
    # takes its smallest value (0 but for a rare goal reward) such quantiles move up to the
    # next labelled value, so the rare rewards keep a class apart from the common one.
    return np.unique(np.maximum(quantiles, distinct[1]))


def _step_value(rewards: np.ndarray, going_on: np.ndarray | None) -> float | None:
    """The one value every label of a step that went on pays, where it lies below or above every other
    label (:meth:`QuantileRewardClasses.fit`'s step class); None where there is none."""
    if going_on is None:
        return None
    steps = np.unique(rewards[np.asarray(going_on, dtype=bool)])
    if steps.size != 1:
        return None
    others = rewards[rewards != steps[0]]
    return float(steps[0]) if steps[0] < others.min() or steps[0] > others.max() else None


class QuantileRewardClasses(_ClassValues):
    """K quantile bins of a continuous reward, for one run (docs/design.md section 2).

    The bin edges are the labelled rewards' quantiles at 1/K, ..., (K-1)/K; a bin's value is the
    mean of the labelled rewards inside it. :meth:`fit` recomputes both from all labels so far, so the
    bins follow the labels as more arrive. Duplicate edges (a reward that fills several quantiles)
    merge their bins, so a run may have fewer than K classes. Two cases keep a rare reward apart from
    a common one: labels of at most K distinct values (a sparse goal reward, 0 or 1) get one class per
    value, and a quantile below the second-smallest labelled value moves up to it. Given which labelled
    steps went on (:meth:`fit`'s ``going_on``), the reward they all pay keeps a bin of its own. The
    interface matches
    :class:`RunRewardClasses`: ``values`` is (K,), ``encode`` and ``decode`` (N,) from (N,).

    :param n_classes: K.
    """

    def __init__(self, n_classes: int) -> None:
        if n_classes < 1:
            raise ValueError(f"need at least one reward class, got {n_classes}")
        super().__init__((n_classes,))  # values (K,): each class's bin mean, NaN where it has none
        self.edges = np.zeros(0)
        """(k - 1,) the inner bin edges: class c holds rewards in [edges[c - 1], edges[c])."""
        self.only_value: float | None = None
        """The labels' one value while they hold a single one (every label 0, no goal yet), else None."""
        self.hidden_edges = np.zeros(0)
        """(k - 1,) the edges :meth:`encode_hidden` reads: each midway between the largest label below
        an edge of ``edges`` and the smallest above it."""

    def fit(self, rewards: np.ndarray, going_on: np.ndarray | None = None) -> None:
        """Set the bins from every labelled reward so far, (n,) float.

        :param going_on: (n,) bool, whether each labelled step's episode went on (the step class,
            ``step_class``): where every such label pays one value v, below or above every other
            label, v keeps a bin of its own and the other labels share the K - 1 others. Queries on
            episode ends make the labels mostly outcomes, and a goal paid by its time (MiniGrid's
            ``1 - 0.9 t / T``) then spreads over the quantiles: a late goal's low pay would share
            the steps' bin, and every step would be paid part of a goal. None: quantiles alone.
        """
        rewards = np.asarray(rewards, dtype=np.float64)
        n_classes = self.values.size
        self.values[:] = np.nan
        if rewards.size == 0:
            self.edges, self.only_value, self.hidden_edges = np.zeros(0), None, np.zeros(0)
            return
        distinct = np.unique(rewards)
        self.only_value = float(distinct[0]) if distinct.size == 1 else None
        step = _step_value(rewards, going_on) if n_classes > 1 and distinct.size > n_classes else None
        if step is None:
            self.edges = _quantile_edges(rewards, n_classes)
        else:
            others = rewards[rewards != step]
            inner = _quantile_edges(others, n_classes - 1)
            below = step < others.min()
            self.edges = np.concatenate([[others.min()], inner] if below else [inner, [step]])
        bins = np.searchsorted(self.edges, rewards, side="right")
        for c in range(self.edges.size + 1):
            self.values[c] = rewards[bins == c].mean()
        # Each edge has labels on both sides: distinct[0] below the first, the largest label above the last.
        self.hidden_edges = np.array(
            [(rewards[bins <= c].max() + rewards[bins > c].min()) / 2 for c in range(self.edges.size)]
        )

    def encode(self, rewards: np.ndarray) -> np.ndarray:
        """Class (bin) index of each reward, (N,) from (N,); -1 before any label was seen, and,
        while every label holds one value, for any other reward: a value no label has shown (a goal
        reward when no goal step is labelled), which the one class cannot stand for."""
        if not self.mask.any():
            return np.full(np.shape(rewards), -1)
        if self.only_value is not None:
            return np.where(np.asarray(rewards) == self.only_value, 0, -1)
        return np.searchsorted(self.edges, rewards, side="right")

    def encode_hidden(self, rewards: np.ndarray) -> np.ndarray:
        """The class of each hidden reward, (N,) from (N,), for the metrics: the class of the
        nearest label. It equals :meth:`encode` on every labelled value and differs only between two
        classes' labels, where :meth:`encode`'s edge, a quantile, may sit at the upper class's
        smallest label: a goal reached later than any labelled one (MiniGrid pays ``1 - 0.9 t / T``)
        pays less than every goal label, and :meth:`encode` would call it class 0, "nothing"."""
        if not self.mask.any() or self.only_value is not None:
            return self.encode(rewards)
        return np.searchsorted(self.hidden_edges, rewards, side="right")


def episode_end_class_mask(
    label_class: np.ndarray, labelled: np.ndarray, terminal: np.ndarray, class_mask: np.ndarray
) -> np.ndarray:
    """The classes each sample may take when a class shown only on episode ends stays there.

    A reward class whose every label fell on a step that ended its episode (a goal, a crash) is
    open only to samples that ended theirs; every other class the run has stays open to every
    sample. A pseudo-reward of such a class on a step that goes on would pay an agent for repeating
    it, a loop worth more than the episode end. A sample left with no class (every class the run has
    is shown only on episode ends, and the sample's episode goes on) keeps them all.

    :param label_class: (N,) int, each sample's labelled class (any value where not labelled).
    :param labelled: (N,) bool.
    :param terminal: (N,) bool, whether each sample's step ended its episode (``terminated``).
    :param class_mask: (K,) bool, the classes the run has.
    :return: (N, K) bool.
    """
    n_classes = class_mask.size
    known = labelled & (label_class >= 0)
    on_end = np.bincount(label_class[known & terminal], minlength=n_classes)[:n_classes] > 0
    elsewhere = np.bincount(label_class[known & ~terminal], minlength=n_classes)[:n_classes] > 0
    end_only = on_end & ~elsewhere
    mask = np.where(terminal[:, None], class_mask, class_mask & ~end_only)
    return np.where(mask.any(axis=1, keepdims=True), mask, class_mask)
