"""The true-rewards control (``cotraining.pseudo_rewards = "hidden"``): every admitted sample reads its
hidden reward in the agents' reward table, while what is admitted, when and with what weight stays the
co-trainer's, so the gap from DOSPCoT to the oracle splits into wrong pseudo-rewards and what the
co-training path loses (docs/design.md)."""

from __future__ import annotations

import dataclasses

import numpy as np

from dospcot.core.self_paced import RunRound


def given_truth(
    result: RunRound, pseudo: np.ndarray, hidden: np.ndarray, true_class: np.ndarray
) -> tuple[np.ndarray, RunRound]:
    """Each admitted sample's pseudo-reward replaced by its hidden reward (``hidden``, indexed by pool
    sample), and the round with ``pseudo_class`` the class given, its true one, for the record. Which
    samples are admitted, and their weights, stay the co-trainer's; the others keep their entries,
    which weigh 0.

    :param result: the co-trainer's round (``pseudo_class``, ``pseudo_weight``: (N,)).
    :param pseudo: (N,) the rewards the classifiers' classes decode to.
    :param hidden: the hidden rewards of the pool's samples, (N,) or longer.
    :param true_class: (N,) each sample's hidden reward class.
    :return: (N,) the rewards written to the table, and the round as recorded.
    """
    admitted = result.pseudo_weight > 0
    given = np.where(admitted, hidden[: pseudo.size], pseudo)
    given_class = np.where(admitted, true_class, result.pseudo_class)
    return given, dataclasses.replace(result, pseudo_class=given_class)
