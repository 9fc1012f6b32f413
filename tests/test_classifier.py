"""Reward classifiers."""

import numpy as np
import torch

from dospcot.core.classifier import BatchedRewardClassifier, ClassifierConfig


def _separable(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(60, 2))
    y = (x[:, 0] + 0.5 * x[:, 1] > 0).astype(np.int64)
    x[y == 1] += 0.5  # a margin
    x[y == 0] -= 0.5
    return torch.from_numpy(x)[None], torch.from_numpy(y)[None]


def test_hinge_linear_svm_separates_a_separable_set():
    x, y = _separable(0)
    clf = BatchedRewardClassifier(1, 2, 3, ClassifierConfig("linear", "hinge", epochs=300, lr=0.05), [0])
    mask = torch.tensor([[True, True, False]])
    clf.fit(x, y, torch.ones(1, 60, dtype=torch.float64), mask)
    predicted = clf.scores(x, mask).argmax(-1)
    assert torch.equal(predicted, y)
    # Hinge: every sample beyond the margin means a zero data loss (Weston-Watkins).
    losses = clf.class_losses(clf(x, mask), mask).gather(-1, y[..., None])[..., 0]
    assert float(losses.detach().max()) < 0.5


def test_models_in_a_batch_are_independent():
    x0, y0 = _separable(0)
    x1, y1 = _separable(1)
    cfg = ClassifierConfig(epochs=50)
    mask = torch.ones(2, 2, dtype=torch.bool)
    w = torch.ones(2, 60, dtype=torch.float64)
    both = BatchedRewardClassifier(2, 2, 2, cfg, [5, 9])
    both.fit(torch.cat([x0, x1]), torch.cat([y0, y1]), w, mask)
    alone = BatchedRewardClassifier(1, 2, 2, cfg, [9])
    alone.fit(x1, y1, w[:1], mask[:1])
    assert torch.equal(both(x1.expand(2, -1, -1), mask)[1], alone(x1, mask[:1])[0])


def test_zero_weight_samples_do_not_change_the_fit():
    x, y = _separable(2)
    cfg = ClassifierConfig(epochs=30)
    mask = torch.ones(1, 2, dtype=torch.bool)
    w = torch.ones(1, 60, dtype=torch.float64)
    w[0, 30:] = 0
    a = BatchedRewardClassifier(1, 2, 2, cfg, [1])
    a.fit(x, y, w, mask)
    flipped = y.clone()
    flipped[0, 30:] = 1 - flipped[0, 30:]
    b = BatchedRewardClassifier(1, 2, 2, cfg, [1])
    b.fit(x, flipped, w, mask)
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters(), strict=True))
