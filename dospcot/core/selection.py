"""SPaMCo's closed-form sample selection with co-regularisation (docs/design.md section 2, step 3).

For one view j, over a batch of B independent runs and a pool of N samples:

1. Co-regularisation: the score of each sample for its *consensus class* (the class the other views
   agree on, Eq. 9 over them) is raised by ``gamma * mean_k v_k`` over the other views k, so a sample
   the others chose is easier to admit.
2. Each sample is predicted as the class of its highest (boosted) score.
3. Per class c, the n_c highest-scoring unlabelled samples predicted as c are admitted; the threshold
   ``lambda_c`` is the n_c-th score (ties broken by pool order, so exactly n_c are admitted when
   enough exist). The quota (``quota``):

   - ``"label-share"`` (SPaMCo): ``n_c = ceil(share_c * add_num)``, where ``share_c`` is c's share
     among the labels. A rare class whose few labels understate its share is starved: with 40
     labels, a class holding 10% of U may show 2 labels (5%), and then half its candidates wait
     until add_num reaches twice |U|.
   - ``"candidates"``: ``n_c = ceil(add_num / |U| * N_c)``, where N_c counts the samples predicted as
     c: every class admits the same share of its own candidates, and all of them once add_num
     reaches |U|, whatever the labels' proportions.
4. Weights: ``"hard"`` gives 1 to admitted samples; ``"soft"`` gives the ramp
   ``clip((score - lambda_c) / gamma, 0, 1)`` to admitted samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dospcot.config.choices import QUOTAS, WEIGHTINGS, Quota, Weighting


@dataclass(frozen=True)
class Selection:
    """What one view admits.

    :param weight: (B, N) self-paced weights v_j in [0, 1]; 0 outside the admitted set.
    :param admitted: (B, N) bool, the admitted samples.
    :param predicted: (B, N) int, the class each sample is predicted as (after the boost).
    :param score: (B, N) the boosted score of the predicted class.
    :param threshold: (B, K) lambda_c, the n_c-th score of class c; NaN where no sample is admitted.
    """

    weight: np.ndarray
    admitted: np.ndarray
    predicted: np.ndarray
    score: np.ndarray
    threshold: np.ndarray


def class_counts(label_share: np.ndarray, add_num: np.ndarray) -> np.ndarray:
    """``n_c = ceil(share_c * add_num)``: (B, K) ints from shares (B, K) and add_num (B,).

    A tiny tolerance keeps float noise (0.3 * 10 = 3.0000000000000004) from adding a sample.
    """
    return np.ceil(label_share * np.asarray(add_num, dtype=np.float64)[:, None] - 1e-9).astype(np.int64)


def spamco_select(
    scores: np.ndarray,
    candidates: np.ndarray,
    label_share: np.ndarray,
    add_num: np.ndarray,
    boost: np.ndarray,
    consensus: np.ndarray,
    gamma: float,
    weighting: Weighting = "hard",
    quota: Quota = "label-share",
) -> Selection:
    """Select confident samples of the unlabelled pool for one view.

    :param scores: (B, N, K) confidence of each class in [0, 1] under this view's classifier.
    :param candidates: (B, N) bool, the unlabelled pool U.
    :param label_share: (B, K) share of each class among the labels (0 for absent classes).
    :param add_num: (B,) the number of samples to add this round.
    :param boost: (B, N) ``gamma * mean_k v_k`` over the other views (zeros when m = 1).
    :param consensus: (B, N) int, the other views' consensus class, -1 where they have none.
    :param gamma: co-regularisation weight, also the width of the soft ramp.
    :param weighting: ``"hard"`` or ``"soft"``.
    :param quota: ``"label-share"`` or ``"candidates"`` (see the module docstring).
    """
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    if quota not in QUOTAS:
        raise ValueError(f"quota must be one of {QUOTAS}, got {quota!r}")
    if weighting == "soft" and gamma <= 0:
        raise ValueError(f"weighting='soft' needs gamma > 0 (the ramp width), got gamma={gamma}")
    n_runs, n_samples, n_classes = scores.shape
    boosted = scores.astype(np.float64, copy=True)
    rows, cols = np.nonzero(consensus >= 0)
    boosted[rows, cols, consensus[rows, cols]] += boost[rows, cols]
    predicted = boosted.argmax(axis=-1)
    score = np.take_along_axis(boosted, predicted[..., None], axis=-1)[..., 0]

    if quota == "label-share":
        counts = class_counts(label_share, add_num)
    else:
        fraction = np.asarray(add_num, dtype=np.float64) / np.maximum(candidates.sum(axis=1), 1)
        per_class = (candidates[..., None] & (predicted[..., None] == np.arange(n_classes))).sum(axis=1)
        counts = class_counts(per_class.astype(np.float64), fraction)
    admitted = np.zeros((n_runs, n_samples), dtype=bool)
    threshold = np.full((n_runs, n_classes), np.nan)
    run_index = np.arange(n_runs)
    for c in range(n_classes):
        eligible = candidates & (predicted == c)
        key = np.where(eligible, score, -np.inf)
        order = np.argsort(-key, axis=1, kind="stable")
        rank = np.empty_like(order)
        np.put_along_axis(rank, order, np.arange(n_samples)[None, :], axis=1)
        n_admit = np.minimum(counts[:, c], eligible.sum(axis=1))
        admitted |= eligible & (rank < n_admit[:, None])
        has = n_admit > 0
        last = order[run_index[has], n_admit[has] - 1]
        threshold[has, c] = score[run_index[has], last]

    if weighting == "hard":
        weight = admitted.astype(np.float64)
    else:
        lam = np.take_along_axis(threshold, predicted, axis=1)
        weight = np.where(admitted, np.clip((score - lam) / gamma, 0.0, 1.0), 0.0)
    return Selection(weight, admitted, predicted, score, threshold)
