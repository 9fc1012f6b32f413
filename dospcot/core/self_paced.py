"""Self-paced multi-view co-training of reward classifiers: one round of docs/design.md section 2.

This file holds steps 2 (select, fit, score per view, serially), 3 (the Eq. 9 pseudo-reward) and 5
(ageing and stopping) for any number of views m and any agent kind: it sees only a pool of samples
(features per view, labels, the unlabelled set), never an agent or the hidden rewards. The drivers
that own the agents (the tabular one in :mod:`dospcot.core.tabular_runs`) collect the pool and
apply steps 1 and 4.

Everything is batched over B independent runs; each run has its own classifiers, labels, pool and
schedule, and nothing crosses between runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import torch

from dospcot.config.learning_sections import CoTrainingConfig
from dospcot.core.classifier import BatchedRewardClassifier
from dospcot.core.consensus import consensus_labels
from dospcot.core.selection import spamco_select
from dospcot.seeding import classifier_seed


@dataclass(frozen=True)
class Numerics:
    """How a run's reward classifiers are fitted and its agents' networks computed: a version of a
    run's numbers.

    :param dtype: the classifiers' parameters and inputs.
    :param weighted_only: a one-run fit reads only the samples whose weight is above 0 (the others
        add nothing to its loss).
    :param sparse_inputs: the agents' Q-networks on a view of 0s and 1s and the classifiers compute
        their first layer over the inputs that are on (``ExpectedSarsaDQN(sparse_inputs=True)``,
        ``BatchedRewardClassifier(sparse_inputs=True)``).
    :param fused_adam: the agents' and the classifiers' Adam steps in one fused kernel.
    """

    dtype: torch.dtype
    weighted_only: bool
    sparse_inputs: bool = False
    fused_adam: bool = False

    @property
    def np_dtype(self) -> type:
        """:attr:`dtype` as numpy's."""
        return np.float64 if self.dtype == torch.float64 else np.float32


NUMERICS: dict[int, Numerics] = {
    1: Numerics(torch.float64, False),
    2: Numerics(torch.float32, True),
    3: Numerics(torch.float32, True, sparse_inputs=True, fused_adam=True),
}
"""The numerics versions (``cotraining.numerics``). 1: float64 fits over the whole pool (the paper
protocol's co-trainer keeps it). 2: float32 fits that read only the samples that carry
weight (the others add exactly 0 to the loss, so they move nothing but rounding). Both take
``classifier.epochs`` full-batch Adam steps from the last fit's parameters; what version 2 saves is
measured in docs/guide/profile.md. 3: version 2's fits, and classifiers and agents' Q-networks (on a
view of 0s and 1s, as MiniGrid's egocentric map) that compute their first layer over the inputs that
are on and step a fused Adam: the same sums and updates as 2's, in another order, so equal up to float32
rounding."""


class FitsUnderNumerics:
    """A trainer whose reward classifiers fit under its config's numerics version (:data:`NUMERICS`)."""

    config: CoTrainingConfig

    @property
    def numerics(self) -> int:
        """The numerics version of the classifiers' fits (``cotraining.numerics``; a config pickled
        before the key existed reads 1, the only version there was: ``CoTrainingConfig.added_keys``)."""
        return self.config.numerics

    @property
    def dtype(self) -> torch.dtype:
        """The classifiers' parameters and inputs: float64 (numerics 1) or float32 (numerics 2)."""
        return NUMERICS[self.numerics].dtype

    @property
    def dtype_np(self) -> type:
        """:attr:`dtype` as numpy's."""
        return NUMERICS[self.numerics].np_dtype

    def classifier(self, dim: int, n_classes: int, seeds: list[int]) -> BatchedRewardClassifier:
        """A stack of ``len(seeds)`` reward classifiers of ``dim`` inputs and ``n_classes`` outputs, the
        config's model (``config.classifier``) fitted under its numerics version, each from its seed."""
        numerics = NUMERICS[self.numerics]
        return BatchedRewardClassifier(
            len(seeds),
            dim,
            n_classes,
            self.config.classifier,
            seeds,
            numerics.sparse_inputs,
            numerics.fused_adam,
        ).to(self.dtype)


def _fit(
    clf: BatchedRewardClassifier,
    numerics: Numerics,
    x: torch.Tensor,
    y: torch.Tensor,
    weight: torch.Tensor,
    mask: torch.Tensor,
    runs: np.ndarray | None = None,
) -> torch.Tensor:
    """Fit ``clf`` under ``numerics``: on a batch of one run, only the weighted samples if it says so.
    With ``runs`` ((B,) bool), only those runs' models change: the others get their parameters back,
    as a fit of no samples would still move them (the penalty and Adam's steps)."""
    kept = None if runs is None or runs.all() else [p.detach().clone() for p in clf.parameters()]
    if numerics.weighted_only and x.shape[0] == 1:
        keep = weight[0] > 0
        # Where every sample carries weight, the subset is the pool itself in its order: no copy of it.
        if not bool(keep.all()):
            if mask.dim() == 3:
                mask = mask[:, keep]
            x, y, weight = x[:, keep], y[:, keep], weight[:, keep]
    loss = clf.fit(x, y, weight, mask)
    if kept is not None:
        others = torch.from_numpy(~runs)
        with torch.no_grad():
            for p, old in zip(clf.parameters(), kept, strict=True):
                p[others] = old[others]
    return loss


@dataclass(frozen=True)
class Pool:
    """The samples of one round, for B runs over N pool slots.

    :param features: per view, (B, N, d_j) classifier inputs.
    :param labelled: (B, N) bool, samples whose true reward was revealed.
    :param label_class: (B, N) int class index of the revealed reward (-1 elsewhere).
    :param unlabelled: (B, N) bool, the unlabelled pool U (disjoint from ``labelled``).
    :param class_mask: (B, K) bool, the classes each run has seen; or (B, N, K), the classes each
        sample may take (e.g. :func:`~dospcot.core.reward_classes.episode_end_class_mask`): a class it may
        not take gets no score, so no view predicts it there and no consensus gives it.
    """

    features: list[np.ndarray]
    labelled: np.ndarray
    label_class: np.ndarray
    unlabelled: np.ndarray
    class_mask: np.ndarray


@dataclass(frozen=True)
class RoundResult:
    """What one co-training round decided.

    :param pseudo_class: (B, N) consensus class of each sample of U, -1 if no view admitted it.
    :param pseudo_weight: (B, N) its self-paced weight, the largest v_j over views (0 elsewhere).
    :param view_weight: (m, B, N) the weights v_j of each view.
    :param view_class: (m, B, N) the class each view predicts.
    :param threshold: (m, B, K) lambda_{j,c}.
    :param classifier_loss: (m, B) final training loss of each classifier.
    :param pace: (B,) admitted share of U, in [0, 1]; 1 where U is empty.
    :param changed: (B,) share of U whose pseudo-label changed since the previous round.
    :param stopped: (B,) bool, runs whose stopping rule fired this round.
    :param member_class: (P, B, N) the class each of P predictors predicts, where the predictors whose
        errors the round's dependence figures compare are not the views' classifiers (the reward
        model's ensemble members); None: they are, ``view_class``.
    """

    pseudo_class: np.ndarray
    pseudo_weight: np.ndarray
    view_weight: np.ndarray
    view_class: np.ndarray
    threshold: np.ndarray
    classifier_loss: np.ndarray
    pace: np.ndarray
    changed: np.ndarray
    stopped: np.ndarray
    member_class: np.ndarray | None = None

    def of_run(self, b: int) -> RunRound:
        """Run ``b``'s part of the round."""
        return RunRound(
            self.pseudo_class[b],
            self.pseudo_weight[b],
            self.view_weight[:, b],
            self.view_class[:, b],
            self.threshold[:, b],
            self.classifier_loss[:, b],
            float(self.pace[b]),
            float(self.changed[b]),
            bool(self.stopped[b]),
            None if self.member_class is None else self.member_class[:, b],
        )


@dataclass(frozen=True)
class RunPool(Pool):
    """The samples of one round of one run: a :class:`Pool` without the runs' axis, so ``features``
    per view (N, d_j), ``labelled``, ``label_class`` and ``unlabelled`` (N,), ``class_mask`` (K,) or
    (N, K)."""


@dataclass(frozen=True)
class RunRound(RoundResult):
    """What one co-training round decided for one run (:meth:`RoundResult.of_run`): a
    :class:`RoundResult` without the runs' axis, so ``pseudo_class`` and ``pseudo_weight`` (N,),
    ``view_weight`` and ``view_class`` (m, N), ``member_class`` (P, N) or None, ``threshold`` (m, K),
    ``classifier_loss`` (m,), and ``pace``, ``changed`` and ``stopped`` plain numbers."""


class SelfPacedCoTrainer(FitsUnderNumerics):
    """m reward classifiers co-trained by serial SPaMCo over B independent runs.

    :param view_dims: input width of each view's classifier (m entries).
    :param n_runs: B.
    :param config: the schedule's hyperparameters.
    :param seeds: one seed per run; view j of run b initialises from ``(seeds[b], j)``.
    :param n_classes: K, the most reward classes a run may hold (the classifiers' outputs).
    """

    _seen: np.ndarray | None = None
    """(B, K) the classes each run's labels have shown so far (None in a checkpoint older than it)."""
    _age: Fraction | None = None
    """The rounds of the schedule done; None in a checkpoint older than it, whose :attr:`round` counts
    them in steps of ``passes_per_round`` (1 before that key)."""

    def __init__(
        self,
        view_dims: list[int],
        n_runs: int,
        config: CoTrainingConfig,
        seeds: list[int],
        n_classes: int,
    ) -> None:
        self.config, self.n_classes = config, n_classes
        self.n_views = len(view_dims)
        if self.n_views < 1:
            raise ValueError("co-training needs at least one view")
        self.classifiers = [
            self.classifier(dim, n_classes, [classifier_seed(s, j) for s in seeds])
            for j, dim in enumerate(view_dims)
        ]
        self.round = 0
        """The steps taken (passes, where a round has several)."""
        self._age = Fraction(0)
        self._previous: np.ndarray | None = None
        self._weights: np.ndarray | None = None
        self._seen = np.zeros((n_runs, n_classes), dtype=bool)

    @property
    def age(self) -> Fraction:
        """The rounds of the schedule done: a step of a round in c passes ages it by 1/c."""
        if self._age is None:
            return Fraction(self.round, vars(self).get("passes_per_round", 1))
        return self._age

    @property
    def last_weights(self) -> np.ndarray | None:
        """(m, B, N) each view's weights v_j over the pool of the last step, or None before any."""
        return self._weights

    @property
    def add_fraction(self) -> float:
        """add_num of the current step as a share of |U| (grows by ``add_fraction_step`` a round)."""
        return self.config.add_fraction_start + self.config.add_fraction_step * float(self.age)

    def step(self, pool: Pool, passes: int = 1, ages: bool = True) -> RoundResult:
        """Run one step: for each view in turn select, fit and score; then Eq. 9; then age.

        :param passes: the steps the driver takes in this round of the schedule
            (``training.cotrain_passes``, 1 before ``training.passes_from_round``).
        :param ages: whether the step ages the schedule by 1/``passes``; False: a fit ahead of the
            round's step (``training.first_labels = "first_pass"`` under score passes), which neither
            ages, stops nor is compared with.
        """
        cfg, m = self.config, self.n_views
        mask = torch.from_numpy(pool.class_mask)
        numerics = NUMERICS[self.numerics]
        xs = [torch.from_numpy(np.asarray(f, dtype=numerics.np_dtype)) for f in pool.features]
        label_class = torch.from_numpy(pool.label_class)
        labelled_w = torch.from_numpy(pool.labelled.astype(numerics.np_dtype))
        share = _label_share(pool)
        add_num = np.ceil(self.add_fraction * pool.unlabelled.sum(axis=1) - 1e-9).astype(np.int64)

        seen = share > 0
        before = seen if self._seen is None else self._seen  # None: a checkpoint from before the key
        fresh = np.ones(seen.shape[0], dtype=bool) if self.round == 0 else (seen & ~before).any(axis=1)
        self._seen = before | seen
        if self.round == 0 or (cfg.refit_new_classes and fresh.any()):
            # The paper's initialisation: each classifier first learns the labels alone; again where a
            # class first shows, whose output no fit has trained.
            for clf, x in zip(self.classifiers, xs, strict=True):
                _fit(clf, numerics, x, label_class, labelled_w, mask, fresh)
        scores = [clf.scores(x, mask).numpy() for clf, x in zip(self.classifiers, xs, strict=True)]
        losses = np.stack([_class_losses(clf, x, mask) for clf, x in zip(self.classifiers, xs, strict=True)])
        n_runs, n_samples = pool.labelled.shape
        # Serial SPaMCo: a view not yet revisited this round co-regularises with its last weights.
        weights = np.zeros((m, n_runs, n_samples))
        if self._weights is not None:
            n = min(n_samples, self._weights.shape[2])
            weights[:, :, :n] = self._weights[:, :, :n] * pool.unlabelled[None, :, :n]
        view_class = np.zeros((m, n_runs, n_samples), dtype=np.int64)
        threshold = np.zeros((m, n_runs, self.n_classes))
        fit_loss = np.zeros((m, n_runs))

        for j in range(m):
            others = [k for k in range(m) if k != j]
            if others:
                boost = cfg.consensus_weight * weights[others].mean(axis=0)
                consensus = consensus_labels(losses[others], weights[others])
            else:
                boost, consensus = np.zeros((n_runs, n_samples)), np.full((n_runs, n_samples), -1)
            sel = spamco_select(
                scores[j],
                pool.unlabelled,
                share,
                add_num,
                boost,
                consensus,
                cfg.consensus_weight,
                cfg.weighting,
                cfg.quota,
            )
            weights[j], view_class[j], threshold[j] = sel.weight, sel.predicted, sel.threshold
            # g_j learns its admitted samples under the current consensus (Eq. 9 with the new v_j).
            pseudo = consensus_labels(losses, weights)
            targets = torch.from_numpy(np.where(pool.labelled, pool.label_class, pseudo))
            sample_w = torch.from_numpy(np.where(pool.labelled, 1.0, weights[j]).astype(numerics.np_dtype))
            fit_loss[j] = _fit(self.classifiers[j], numerics, xs[j], targets, sample_w, mask).numpy()
            scores[j] = self.classifiers[j].scores(xs[j], mask).numpy()
            losses[j] = _class_losses(self.classifiers[j], xs[j], mask)

        self._weights = weights.copy()
        pseudo_class = np.where(pool.unlabelled, consensus_labels(losses, weights), -1)
        pseudo_weight = np.where(pseudo_class >= 0, weights.max(axis=0), 0.0)
        n_unlabelled = pool.unlabelled.sum(axis=1)
        # With nothing unlabelled (every reward revealed), the schedule has nothing left to admit.
        pace = np.where(n_unlabelled > 0, (pseudo_weight > 0).sum(axis=1) / np.maximum(n_unlabelled, 1), 1.0)
        # The stopping rules read rounds: a pass inside a round neither stops nor is compared with.
        age = self.age + Fraction(int(ages), passes)
        round_end = ages and age.denominator == 1
        changed = self._changed_share(pseudo_class, pool.unlabelled, round_end)
        stopped = np.zeros(n_runs, dtype=bool)
        if cfg.tol > 0 and self.age >= 1 and round_end:
            stopped |= changed < cfg.tol
        if cfg.stop_when_fully_admitted and round_end:
            stopped |= pace >= 1.0
        self.round += 1
        self._age = age
        return RoundResult(
            pseudo_class, pseudo_weight, weights, view_class, threshold, fit_loss, pace, changed, stopped
        )

    def _changed_share(self, pseudo_class: np.ndarray, unlabelled: np.ndarray, keep: bool) -> np.ndarray:
        """(B,) the share of each run's unlabelled samples whose pseudo-class differs from the last
        kept step's; ``keep``: this step's is the next one compared with (a round's last pass)."""
        previous = self._previous
        if keep:
            self._previous = pseudo_class.copy()
        if previous is None:
            return np.ones(pseudo_class.shape[0])
        n = min(previous.shape[1], pseudo_class.shape[1])
        differs = (previous[:, :n] != pseudo_class[:, :n]) & unlabelled[:, :n]
        return differs.sum(axis=1) / np.maximum(unlabelled.sum(axis=1), 1)


class RunCoTrainer:
    """The co-trainer of one run (the SB3 runs of :mod:`dospcot.core.sb3_round`): a
    :class:`SelfPacedCoTrainer` whose pools and results hold one run, so its callers never index a
    batch.

    :param view_dims: input width of each view's classifier (m entries).
    :param config: the schedule's hyperparameters.
    :param seed: the run's seed; view j's classifier initialises from ``(seed, j)``.
    :param n_classes: K, the most reward classes the run may hold.
    """

    def __init__(
        self,
        view_dims: list[int],
        config: CoTrainingConfig,
        seed: int,
        n_classes: int,
    ) -> None:
        self._batch = SelfPacedCoTrainer(view_dims, 1, config, [seed], n_classes)

    @property
    def numerics(self) -> int:
        """The numerics version of the classifiers' fits (:data:`NUMERICS`)."""
        return self._batch.numerics

    @property
    def dtype_np(self) -> type:
        """The classifiers' inputs' numpy dtype (:attr:`SelfPacedCoTrainer.dtype_np`)."""
        return self._batch.dtype_np

    @property
    def classifiers(self) -> list[BatchedRewardClassifier]:
        """Each view's reward classifier (a batch of one model, as
        :func:`~dospcot.core.classifier.save_classifier` writes it)."""
        return self._batch.classifiers

    def probabilities(self, pool: RunPool) -> np.ndarray | None:
        """(m, N, K) each view's class probabilities of the pool's samples, or None before the first
        round fit the classifiers."""
        if self._batch.round == 0:
            return None
        mask = torch.from_numpy(pool.class_mask[None])
        return np.stack(
            [
                clf.scores(torch.from_numpy(np.asarray(f, dtype=self._batch.dtype_np)[None]), mask)[0].numpy()
                for clf, f in zip(self.classifiers, pool.features, strict=True)
            ]
        )

    @property
    def batch(self) -> SelfPacedCoTrainer:
        """The co-trainer of a batch of one run that this one wraps."""
        return self._batch

    def step(self, pool: RunPool, passes: int = 1, ages: bool = True) -> RunRound:
        """One step (:meth:`SelfPacedCoTrainer.step`) on the run's pool, of a round in ``passes`` steps."""
        return self._batch.step(batched(pool), passes, ages).of_run(0)


def batched(pool: RunPool) -> Pool:
    """The pool of one run as a batch of one run."""
    return Pool(
        [f[None] for f in pool.features],
        pool.labelled[None],
        pool.label_class[None],
        pool.unlabelled[None],
        pool.class_mask[None],
    )


def _label_share(pool: Pool) -> np.ndarray:
    """(B, K) share of each class among each run's labels."""
    n_classes = pool.class_mask.shape[-1]
    onehot = (pool.label_class[..., None] == np.arange(n_classes)) & pool.labelled[..., None]
    counts = onehot.sum(axis=1).astype(np.float64)
    return counts / np.maximum(counts.sum(axis=1, keepdims=True), 1.0)


def _class_losses(clf: BatchedRewardClassifier, x: torch.Tensor, mask: torch.Tensor) -> np.ndarray:
    with torch.no_grad():
        return clf.class_losses(clf(x, mask), mask).numpy()


__all__ = [
    "NUMERICS",
    "Numerics",
    "Pool",
    "RoundResult",
    "RunCoTrainer",
    "RunPool",
    "RunRound",
    "SelfPacedCoTrainer",
    "batched",
]
