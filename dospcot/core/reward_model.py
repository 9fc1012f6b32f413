"""The reward-model peer (``method = "reward-model"``): the learnt reward a user would reach for instead
of co-training.

Each view has an ensemble of E reward classifiers (the co-trainer's own model,
``cotraining.classifier``; E = ``cotraining.ensemble_size``), each member from its own initial
parameters and fitted, every round, on its own bootstrap of the labels alone: no pseudo-label, no
self-paced selection, no consensus between views. The mean of every member's class probabilities
rewards every unlabelled sample, with weight 1, as the learnt reward of PEBBLE (Lee et al., 2021) and
B-Pref rewards every transition; a score pass inside a round (``training.pass_kind = "score"``,
:meth:`RewardModelTrainer.score`) rewards the samples met since, with no fit. Queries by
``"disagreement"`` go where the members disagree (:meth:`RewardModelTrainer.probabilities` hands every
member to the queries as a view of its own).

It answers :class:`~dospcot.core.sb3_round.CoTrainingRun` as the co-trainer does: ``step`` on a
:class:`~dospcot.core.self_paced.RunPool` returns a :class:`~dospcot.core.self_paced.RunRound`.
"""

from __future__ import annotations

import numpy as np
import torch

from dospcot.config.learning_sections import CoTrainingConfig
from dospcot.core.self_paced import FitsUnderNumerics, RunPool, RunRound
from dospcot.seeding import bootstrap_seed, ensemble_seed


class RewardModelTrainer(FitsUnderNumerics):
    """The ensembles of one run's reward model, one per view.

    :param view_dims: input width of each view's classifiers (m entries).
    :param config: the classifiers' hyperparameters (``classifier``), their ``numerics`` and
        ``ensemble_size``; the self-paced schedule's keys are not read.
    :param seed: the run's seed; member e of view j initialises from ``(seed, j, e)``.
    :param n_classes: K, the most reward classes the run may hold.
    """

    def __init__(self, view_dims: list[int], config: CoTrainingConfig, seed: int, n_classes: int) -> None:
        self.config, self.seed = config, seed
        members = config.ensemble_size
        self.classifiers = [
            self.classifier(dim, n_classes, [ensemble_seed(seed, j, e) for e in range(members)])
            for j, dim in enumerate(view_dims)
        ]
        self.round = 0
        self._previous: np.ndarray | None = None

    def _inputs(self, pool: RunPool, rows: np.ndarray | slice) -> tuple[list[torch.Tensor], torch.Tensor]:
        """Each view's inputs of the samples ``rows``, (E, n, d_j), and their class mask, one copy per
        member."""
        members = self.config.ensemble_size
        np_dtype = self.dtype_np
        xs = [
            torch.from_numpy(np.asarray(f[rows], dtype=np_dtype))[None].expand(members, -1, -1)
            for f in pool.features
        ]
        mask = pool.class_mask if pool.class_mask.ndim == 1 else pool.class_mask[rows]
        return xs, torch.from_numpy(np.ascontiguousarray(mask))[None].expand(members, *mask.shape)

    def step(self, pool: RunPool, passes: int = 1, ages: bool = True) -> RunRound:
        """One step: every member refits on its bootstrap of the labels; the ensembles' mean class
        rewards every sample of U with weight 1.

        :param passes: the steps of this round (``training.cotrain_passes``), as the co-trainer takes
            them; the ensembles have no schedule to age, so every step is fitted alike.
        :param ages: as the co-trainer's; no schedule ages here either way.
        """
        self.round += 1
        members, m = self.config.ensemble_size, len(self.classifiers)
        rows = np.flatnonzero(pool.labelled)
        # Poisson(1) counts: the bootstrap of online bagging, so a member's labels differ from its
        # neighbours' without a fixed sample size.
        counts = np.random.default_rng(bootstrap_seed(self.seed, self.round)).poisson(
            1.0, (m, members, rows.size)
        )
        counts[counts.sum(axis=-1) == 0] = 1  # a member whose draw kept no label learns them all
        xs, mask = self._inputs(pool, rows)
        y = torch.from_numpy(pool.label_class[rows])[None].expand(members, -1)
        losses = np.zeros(m)
        for j, clf in enumerate(self.classifiers):
            weight = torch.from_numpy(counts[j].astype(self.dtype_np))
            losses[j] = float(clf.fit(xs[j], y, weight, mask).mean()) if rows.size else float("nan")
        probabilities = self.probabilities(pool).reshape(m, members, *pool.labelled.shape, -1)
        view_class = probabilities.mean(axis=1).argmax(axis=-1)
        pseudo_class = np.where(pool.unlabelled, probabilities.mean(axis=(0, 1)).argmax(axis=-1), -1)
        admitted = pool.unlabelled.astype(np.float64)
        changed = 1.0
        if self._previous is not None:
            n = min(self._previous.size, pseudo_class.size)
            differs = (self._previous[:n] != pseudo_class[:n]) & pool.unlabelled[:n]
            changed = float(differs.sum() / max(pool.unlabelled.sum(), 1))
        self._previous = pseudo_class.copy()
        return RunRound(
            pseudo_class=pseudo_class,
            pseudo_weight=admitted,
            view_weight=np.repeat(admitted[None], m, axis=0),
            view_class=view_class,
            threshold=np.full((m, probabilities.shape[-1]), np.nan),
            classifier_loss=losses,
            pace=1.0,
            changed=changed,
            stopped=False,
            member_class=probabilities.reshape(m * members, *pool.labelled.shape, -1).argmax(axis=-1),
        )

    def score(self, pool: RunPool) -> tuple[np.ndarray, np.ndarray]:
        """A score pass (``training.pass_kind = "score"``): the ensembles as the last step fitted them
        reward the unlabelled samples the step did not hold (those met since), as the step rewarded every
        unlabelled sample then. Nothing is fitted.

        :param pool: the pool now: the last step's samples first, in the same order, then those since.
        :return: (N,) int, the class of the ensembles' mean probabilities for each unlabelled sample
            the last step did not hold, -1 for every other sample; (N,) its weight, 1 there, 0 elsewhere.
        """
        if self._previous is None:
            raise ValueError("a score pass needs a reward model that has taken a step")
        n = min(self._previous.size, pool.unlabelled.size)
        new = pool.unlabelled.copy()
        new[:n] &= self._previous[:n] < 0  # the step rewarded every sample it held unlabelled
        rows = np.flatnonzero(new)
        pseudo_class = np.full(new.shape, -1, dtype=np.int64)
        if rows.size:
            pseudo_class[rows] = self._member_probabilities(pool, rows).mean(axis=0).argmax(axis=-1)
        return pseudo_class, new.astype(np.float64)

    def probabilities(self, pool: RunPool) -> np.ndarray | None:
        """(m x E, N, K) every member's class probabilities of the pool's samples, view by view, or None
        before the first round fit them."""
        if self.round == 0:
            return None
        return self._member_probabilities(pool, slice(None))

    def _member_probabilities(self, pool: RunPool, rows: np.ndarray | slice) -> np.ndarray:
        """(m x E, n, K) every member's class probabilities of the samples ``rows``, view by view."""
        xs, mask = self._inputs(pool, rows)
        return np.concatenate(
            [clf.scores(x, mask).numpy() for clf, x in zip(self.classifiers, xs, strict=True)]
        )
