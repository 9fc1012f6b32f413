"""Score passes (``training.pass_kind = "score"``): between the parts of a round's collection, the
views' reward classifiers, as the last co-training left them, pseudo-reward the steps it did not
admit, the ones taken since among them, with no fit and no step of the self-paced schedule.

A co-training pass (``"cotrain"``) refits every classifier on the whole pool, which on a wide view
(MiniGrid's egocentric map) costs most of a round; a score pass costs one forward pass of each. The
rule a pass admits by is the last co-training's own: view j admits a sample to the class c it
predicts where its score for c is at least that of the least sure sample it admitted to c then
(under the classifier as that co-training fitted it), so a pass admits what that co-training would
have admitted at its pace, and nothing of a class it admitted nothing of. The views' consensus
(Eq. 9) gives the class; a sample weighs the largest weight of the views that admit it, 1 under
``"hard"`` weighting, the ramp from the bound under ``"soft"``. The co-regularisation boost is left out:
it reads the other views' weights of the same step, which a pass does not take.
"""

from __future__ import annotations

import numpy as np
import torch

from dospcot.core.consensus import consensus_labels
from dospcot.core.self_paced import NUMERICS, Pool, RunCoTrainer, RunPool, SelfPacedCoTrainer, batched


def admission_bounds(scores: np.ndarray, admitted: np.ndarray) -> np.ndarray:
    """(B, K) the least score of each class among the samples one view admitted to it: each
    admitted sample counts for the class it predicts (its highest score); NaN where none.

    :param scores: (B, N, K) the view's class scores.
    :param admitted: (B, N) bool, the samples the view admitted.
    """
    n_classes = scores.shape[-1]
    predicted = scores.argmax(axis=-1)
    top = np.take_along_axis(scores, predicted[..., None], axis=-1)[..., 0]
    bounds = np.full((scores.shape[0], n_classes), np.nan)
    for c in range(n_classes):
        chosen = np.where(admitted & (predicted == c), top, np.inf).min(axis=1)
        bounds[:, c] = np.where(np.isfinite(chosen), chosen, np.nan)
    return bounds


def score_pool(trainer: SelfPacedCoTrainer, pool: Pool) -> tuple[np.ndarray, np.ndarray]:
    """The pseudo-class and weight a score pass gives the samples of ``pool`` the trainer's last step
    did not admit (module docstring).

    :param trainer: a co-trainer that has taken at least one step; its classifiers are not changed.
    :param pool: the pool now: the last step's samples first, in the same order, then those since.
    :return: (B, N) int, each such sample's consensus class, -1 where no view admits it (and for every
        labelled sample and every sample the last step admitted); (B, N) its weight, 0 there.
    """
    last = trainer.last_weights
    if last is None:
        raise ValueError("a score pass needs a co-trainer that has taken a step")
    n_runs, n_samples = pool.labelled.shape
    n_old = min(last.shape[2], n_samples)
    numerics = NUMERICS[trainer.numerics]
    mask = torch.from_numpy(pool.class_mask)
    views = range(trainer.n_views)
    weights = np.zeros((trainer.n_views, n_runs, n_samples))
    losses = np.zeros((trainer.n_views, n_runs, n_samples, trainer.n_classes))
    already = np.zeros((n_runs, n_samples), dtype=bool)
    already[:, :n_old] = (last[:, :, :n_old] > 0).any(axis=0)
    open_ = pool.unlabelled & ~already
    for j, clf, features in zip(views, trainer.classifiers, pool.features, strict=True):
        x = torch.from_numpy(np.asarray(features, dtype=numerics.np_dtype))
        with torch.no_grad():
            outputs = clf(x, mask)
            losses[j] = clf.class_losses(outputs, mask).numpy()
            scores = torch.softmax(outputs, dim=-1).numpy()
        bound = admission_bounds(scores[:, :n_old], last[j, :, :n_old] > 0)
        predicted = scores.argmax(axis=-1)
        top = np.take_along_axis(scores, predicted[..., None], axis=-1)[..., 0]
        lam = np.take_along_axis(bound, predicted, axis=1)
        admitted = open_ & (top >= np.nan_to_num(lam, nan=np.inf))
        if trainer.config.weighting == "hard":
            weights[j] = admitted
        else:
            ramp = np.clip((top - lam) / trainer.config.consensus_weight, 0.0, 1.0)
            weights[j] = np.where(admitted, ramp, 0.0)
    pseudo_class = np.where(open_, consensus_labels(losses, weights), -1)
    pseudo_weight = np.where(pseudo_class >= 0, weights.max(axis=0), 0.0)
    return np.where(pseudo_weight > 0, pseudo_class, -1), pseudo_weight


def score_run(trainer: RunCoTrainer, pool: RunPool) -> tuple[np.ndarray, np.ndarray]:
    """:func:`score_pool` for the co-trainer of one run: (N,) classes and (N,) weights."""
    pseudo_class, pseudo_weight = score_pool(trainer.batch, batched(pool))
    return pseudo_class[0], pseudo_weight[0]
