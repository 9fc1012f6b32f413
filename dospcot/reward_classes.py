"""Reward classes: the distinct reward values seen in labels, per run.

Classes are numbered in order of first appearance, so a class keeps its index (and the classifier
output unit that stands for it) when a new reward value shows up later in training.
"""

from __future__ import annotations

import numpy as np


class RewardClasses:
    """The reward values each of ``n_runs`` runs has seen in its labels.

    :param n_runs: number of independent runs.
    :param max_classes: K, the most distinct values a run may see.
    """

    def __init__(self, n_runs: int, max_classes: int) -> None:
        self.values = np.full((n_runs, max_classes), np.nan)
        """(B, K) the value of each class, NaN where the run has no such class yet."""

    @property
    def mask(self) -> np.ndarray:
        """(B, K) bool, the classes each run has."""
        return ~np.isnan(self.values)

    def observe(self, run: int, rewards: np.ndarray) -> None:
        """Add the values of ``rewards`` (labels of run ``run``) not seen before, in the order given."""
        for value in rewards:
            row = self.values[run]
            if np.any(row == value):
                continue
            free = np.flatnonzero(np.isnan(row))
            if free.size == 0:
                raise ValueError(
                    f"run {run} saw more than {row.size} distinct reward values; raise max_classes "
                    f"or bin a continuous reward into quantile classes"
                )
            row[free[0]] = value

    def encode(self, rewards: np.ndarray) -> np.ndarray:
        """Class index of each reward, shape (B, N) from rewards (B, N); -1 where unknown."""
        match = rewards[..., None] == self.values[:, None, :]
        return np.where(match.any(-1), match.argmax(-1), -1)

    def decode(self, classes: np.ndarray) -> np.ndarray:
        """Reward value of each class index (B, N); NaN for -1."""
        values = np.take_along_axis(self.values, np.clip(classes, 0, None), axis=1)
        return np.where(classes >= 0, values, np.nan)
