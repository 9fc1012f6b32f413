"""SPaMCo selection and the Eq. 9 consensus on hand-made examples."""

import numpy as np
import pytest

from dospcot.core.consensus import consensus_labels
from dospcot.core.selection import class_counts, spamco_select


def _select(scores, **kw):
    scores = np.asarray(scores, dtype=float)[None]
    n = scores.shape[1]
    args = dict(
        candidates=np.ones((1, n), bool),
        label_share=np.array([[0.75, 0.25]]),
        add_num=np.array([4]),
        boost=np.zeros((1, n)),
        consensus=np.full((1, n), -1),
        gamma=0.3,
    )
    args.update(kw)
    return spamco_select(scores, **args)


# Six samples, two classes. Predicted class 0: samples 0, 1, 2, 3 (scores .9, .8, .7, .6);
# class 1: samples 4, 5 (scores .95, .55).
SCORES = [[0.9, 0.1], [0.8, 0.2], [0.7, 0.3], [0.6, 0.4], [0.05, 0.95], [0.45, 0.55]]


def test_per_class_counts_follow_label_shares():
    # add_num 4 with shares (0.75, 0.25): n_0 = ceil(3) = 3, n_1 = ceil(1) = 1.
    assert class_counts(np.array([[0.75, 0.25]]), np.array([4])).tolist() == [[3, 1]]
    sel = _select(SCORES)
    assert sel.admitted[0].tolist() == [True, True, True, False, True, False]
    assert sel.threshold[0].tolist() == pytest.approx([0.7, 0.95])
    assert sel.weight[0].tolist() == [1, 1, 1, 0, 1, 0]


def test_candidate_quotas_admit_each_class_the_same_share_of_its_candidates():
    # add_num 3 of |U| = 6 is a half: class 0 has 4 candidates (n_0 = 2), class 1 has 2 (n_1 = 1),
    # whatever the labels' shares (here 0.9 / 0.1, which would give n_1 = ceil(0.3) = 1, n_0 = 3).
    sel = _select(SCORES, add_num=np.array([3]), label_share=np.array([[0.9, 0.1]]), quota="candidates")
    assert sel.admitted[0].tolist() == [True, True, False, False, True, False]
    # The label-share quota with shares 0.95 / 0.05 and add_num = |U| = 6 starves class 1 (n_1 =
    # ceil(0.3) = 1 of its 2 candidates); the candidate quota admits every candidate of every class.
    share = np.array([[0.95, 0.05]])
    assert _select(SCORES, add_num=np.array([6]), label_share=share).admitted[0, 5] == False  # noqa: E712
    assert _select(SCORES, add_num=np.array([6]), label_share=share, quota="candidates").admitted.all()
    with pytest.raises(ValueError, match="quota must be one of"):
        _select(SCORES, quota="labels")


def test_gamma_boost_changes_a_decision():
    # The other view admitted sample 3 (v = 1) as class 0: its score .6 + .3 * 1 = .9 beats sample 2.
    boost = np.array([[0, 0, 0, 0.3, 0, 0]])
    consensus = np.array([[-1, -1, -1, 0, -1, -1]])
    sel = _select(SCORES, boost=boost, consensus=consensus)
    assert sel.admitted[0].tolist() == [True, True, False, True, True, False]
    # Boosting sample 5 towards class 0 flips its predicted class (.45 + .3 = .75 > .55).
    sel = _select(SCORES, boost=np.array([[0, 0, 0, 0, 0, 0.3]]), consensus=np.array([[-1] * 5 + [0]]))
    assert sel.predicted[0, 5] == 0 and sel.score[0, 5] == pytest.approx(0.75)


def test_soft_weights_ramp_from_the_threshold():
    sel = _select(SCORES, weighting="soft")
    # Class 0 threshold .7: weights (.9-.7)/.3, (.8-.7)/.3, 0; class 1 has only its threshold sample.
    assert sel.weight[0].tolist() == pytest.approx([2 / 3, 1 / 3, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="gamma > 0"):
        _select(SCORES, weighting="soft", gamma=0.0)


def test_only_unlabelled_candidates_are_admitted():
    sel = _select(SCORES, candidates=np.array([[False, True, True, True, True, True]]))
    assert sel.admitted[0].tolist() == [False, True, True, True, True, False]


def test_eq9_consensus_by_hand():
    # Two views, one run, two samples, two classes; cross-entropy losses -log p.
    p1 = np.array([[0.6, 0.4], [0.9, 0.1]])
    p2 = np.array([[0.2, 0.8], [0.5, 0.5]])
    losses = -np.log(np.stack([p1, p2]))[:, None]  # (m, B, N, K)
    # Sample 0: v = (1, 1): sum log p = log .12 vs log .32 -> class 1.
    # Sample 0 with v = (1, .2): .6 * .2**.2 = .43 vs .4 * .8**.2 = .38 -> class 0.
    # Sample 1: no weight -> unlabelled.
    assert consensus_labels(losses, np.array([[[1.0, 0.0]], [[1.0, 0.0]]])).tolist() == [[1, -1]]
    assert consensus_labels(losses, np.array([[[1.0, 0.0]], [[0.2, 0.0]]])).tolist() == [[0, -1]]


def test_eq9_ignores_a_zero_weight_view_with_infinite_loss():
    losses = np.array([[[[0.1, np.inf]]], [[[np.inf, 0.2]]]])
    assert consensus_labels(losses, np.array([[[1.0]], [[0.0]]])).tolist() == [[0]]
