"""What a co-training round reports, for every kind of run (the SB3 runs of
:mod:`dospcot.core.sb3_round` and the batched tabular runs of :mod:`dospcot.core.tabular_runs`):
the co-trainer's figures for the round and the head that names each record (one row of
``metrics.csv`` per run, round and agent).

The figures read the hidden truth: they are metrics, never an input of training.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dospcot.core.self_paced import RunRound

VIEW_STATS = ("view_coverage", "view_pseudo_accuracy", "view_error", "lambda", "classifier_loss")
"""The per-view figures of :func:`round_stats`, under the names a record gives them."""
DEPENDENCE_STATS = ("joint_error", "independent_error", "disagreement", "error_correlation")
"""The figures of :func:`error_dependence`, under the names a record gives them."""
CLASS_COLUMNS = ("round", "class", "reward", "samples", "labelled", "admitted", "recall", "precision")
"""The columns of a run's ``pseudo_rewards.csv`` (:func:`class_rows`)."""


def record_head(
    method: str,
    agents: Sequence[str],
    views: Sequence[str],
    gamma: float,
    seed: int,
    round_index: int,
    k: int,
) -> dict[str, Any]:
    """The first columns of agent ``k``'s record of round ``round_index`` (1-based) of a run: what the
    run is (its method, agent kinds, views, consensus weight ``gamma`` and seed) and which agent the row
    describes. The column ``gamma`` holds ``cotraining.consensus_weight``, the paper's gamma."""
    return {
        "method": method,
        "agents": "-".join(agents),
        "views": "-".join(views),
        "m": len(agents),
        "gamma": gamma,
        "seed": seed,
        "round": round_index,
        "agent": int(k),
        "kind": agents[k],
        "view": views[k],
    }


def _view_stats(result: RunRound, j: int, unlabelled: np.ndarray, correct: np.ndarray) -> dict[str, float]:
    """View j's round: coverage of U, accuracy of what it admitted, its error rate over all of U
    (admitted or not), mean lambda and classifier loss. ``correct`` (N,) says where its predicted class
    matches the truth."""
    taken = result.view_weight[j] > 0
    lam = result.threshold[j]
    return {
        "view_coverage": float(taken[unlabelled].mean()) if unlabelled.any() else 0.0,
        "view_pseudo_accuracy": float(correct[taken].mean()) if taken.any() else float("nan"),
        "view_error": float(1.0 - correct[unlabelled].mean()) if unlabelled.any() else float("nan"),
        "lambda": float(np.nanmean(lam)) if np.isfinite(lam).any() else float("nan"),
        "classifier_loss": float(result.classifier_loss[j]),
    }


def error_dependence(predicted: np.ndarray, true_class: np.ndarray, where: np.ndarray) -> dict[str, float]:
    """How dependent P predictors' errors are over the samples ``where`` of a class some label showed:
    co-training's second view pays when its errors are close to independent of the first's given the
    label. A sample of a value no label showed is left out: every predictor errs on it, whatever its
    view, so it would make any two predictors look dependent (``view_error`` counts it).

    - ``joint_error``: the share of samples every predictor gets wrong;
    - ``independent_error``: the product of their error rates, what ``joint_error`` would be were
      their errors independent (below it: errors in different places; above it: the same places);
    - ``disagreement``: the share of samples on which the predictors do not all predict one class;
    - ``error_correlation``: the correlation of two predictors' error indicators (the phi
      coefficient; 0 for independent errors, 1 for errors on the same samples), averaged over pairs;
      NaN where a predictor is never or always wrong.

    All NaN for fewer than two predictors or no sample.

    :param predicted: (P, N) each predictor's class of each sample.
    :param true_class: (N,) each sample's hidden class, -1 for a value no label showed.
    :param where: (N,) bool, the samples scored (a round's U).
    """
    scored = where & (true_class >= 0)
    if predicted.shape[0] < 2 or not scored.any():
        return dict.fromkeys(DEPENDENCE_STATS, float("nan"))
    classes = predicted[:, scored]
    wrong = classes != true_class[scored]  # (P, n)
    rates = wrong.mean(axis=1)
    pairs = [(a, b) for a in range(len(wrong)) for b in range(a + 1, len(wrong))]
    spread = np.sqrt(rates * (1.0 - rates))
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = [
            ((wrong[a] & wrong[b]).mean() - rates[a] * rates[b]) / (spread[a] * spread[b]) for a, b in pairs
        ]
    return {
        "joint_error": float(wrong.all(axis=0).mean()),
        "independent_error": float(np.prod(rates)),
        "disagreement": float((classes != classes[0]).any(axis=0).mean()),
        "error_correlation": float(np.mean(phi)),
    }


def round_stats(
    result: RunRound, unlabelled: np.ndarray, true_class: np.ndarray, given_truth: bool = False
) -> dict[str, Any]:
    """A run's round: pace, coverage of U (``unlabelled``,
    (N,) bool), accuracy of the admitted pseudo-rewards with its worst class, whether the stopping rule
    fired, and each view's figures (:data:`VIEW_STATS`). ``true_class`` (N,) is each sample's hidden
    class (-1: a value no label showed, never a right prediction). With ``given_truth`` the admitted
    samples were given their hidden rewards (``cotraining.pseudo_rewards = "hidden"``; ``result``'s
    ``pseudo_class`` is then their true class), so each one is right, a value no label showed included;
    each view's figures still score its classifier's predictions.

    The worst-class figures show what the mean hides: a rare class (lava) admitted on ordinary steps,
    or a class no label showed (the goal) read as another. ``worst_class_recall`` is the lowest share
    of the admitted samples of one hidden class given that class (samples of an unseen value count as
    one class, always wrong); ``worst_class_precision`` the lowest share of the samples given one
    class that truly are of it. NaN when nothing is admitted.
    """
    admitted = result.pseudo_weight > 0
    right = (result.view_class == true_class) & (true_class >= 0)  # (m, N) per view
    given, truth = result.pseudo_class[admitted], true_class[admitted]
    correct = (given == truth) & ((truth >= 0) | given_truth)
    recall = [correct[truth == c].mean() for c in np.unique(truth)]
    precision = [correct[given == c].mean() for c in np.unique(given)]
    return {
        "pace": result.pace,
        "coverage": float(admitted[unlabelled].mean()) if unlabelled.any() else 0.0,
        "pseudo_accuracy": float(correct.mean()) if admitted.any() else float("nan"),
        "worst_class_recall": float(min(recall, default=float("nan"))),
        "worst_class_precision": float(min(precision, default=float("nan"))),
        "stopped": result.stopped,
        "views": [_view_stats(result, j, unlabelled, c) for j, c in enumerate(right)],
        **error_dependence(
            result.view_class if result.member_class is None else result.member_class, true_class, unlabelled
        ),
    }


def class_rows(
    round_index: int,
    result: RunRound,
    labelled: np.ndarray,
    unlabelled: np.ndarray,
    true_class: np.ndarray,
    rewards: np.ndarray,
) -> list[dict[str, Any]]:
    """A round's pseudo-rewards per hidden reward class, so that a shortfall reads as wrong rewards
    (low precision), missing ones (low recall, high precision) or a class no label showed (class -1).

    One row per class the pool's samples truly hold: its ``samples`` met (labelled or in U), how many are
    ``labelled``, how many of the others were ``admitted`` with a pseudo-reward, ``recall`` (the share
    of its unlabelled samples given their own class) and ``precision`` (the share of the samples given
    the class that truly hold it; NaN where none was given it).

    :param labelled: (N,) bool; ``unlabelled`` (N,) bool, U.
    :param true_class: (N,) each sample's hidden class, -1 for a value no label showed (metrics only).
    :param rewards: (K,) each class's reward value.
    """
    admitted, met = result.pseudo_weight > 0, labelled | unlabelled
    rows = []
    for c in np.unique(true_class[met]):
        truly, given = (true_class == c) & met, admitted & (result.pseudo_class == c)
        in_u = truly & unlabelled
        rows.append(
            {
                "round": round_index,
                "class": int(c),
                "reward": float(rewards[c]) if c >= 0 else float("nan"),
                "samples": int(truly.sum()),
                "labelled": int((truly & labelled).sum()),
                "admitted": int((in_u & admitted).sum()),
                "recall": float((given & in_u).sum() / in_u.sum()) if in_u.any() else float("nan"),
                "precision": float((given & truly).sum() / given.sum()) if given.any() else float("nan"),
            }
        )
    return rows
