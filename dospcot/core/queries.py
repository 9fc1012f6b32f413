"""Active reward queries: which samples a rater labels, round by round, under the uniform mask's budget
(docs/queries.md).

Under ``training.label_strategy = "uniform"`` (the default, the paper's setting) a fixed random mask
reveals a share of the rewards whatever the agents do. Every other strategy reveals nothing up front:
after each round's collection it buys labels for chosen samples, at most
``ceil(label_fraction x samples met so far)`` revealed in all (keys on a keyed pool, steps otherwise),
which is what the uniform mask reveals among the samples met, in expectation. A revealed sample stays
revealed, for all its visits, past and future.

The choice reads what an agent may read (the samples met, their episode ends, the reward classifiers'
outputs), never a hidden reward; the rater alone reads the hidden reward of the samples it is asked
about (:mod:`dospcot.core.raters`).

- ``"random"``: the budget spent at random over the samples met (the active strategies' direct control);
- ``"outcomes"``: the queries first cover the kinds of step an agent sees without a reward: steps that
  ended an episode, steps cut by the time limit, and the rest, each kind an equal floor of the round's
  queries (a kind with fewer candidates gives its remainder to the next);
- ``"uncertainty"``: the smallest margin between the two most likely classes, mean over the views'
  classifiers (uncertainty sampling; one view: self-training's partner);
- ``"disagreement"`` (co-testing, Muslea et al.): samples whose views' classifiers predict different
  classes, the most confident disagreements first (the views' mean confidence in their own class),
  then the rest by uncertainty; needs two or more views.

Every strategy but ``"random"`` keeps a random share of each round's queries
(``training.query_random_share``), and each may prefer the samples first met in the latest
``training.query_recent_rounds`` rounds. Before any classifier was fit (the first round) the
classifier-driven strategies choose at random.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from dospcot.config.choices import CLASSIFIER_STRATEGIES

LOG_COLUMNS: tuple[str, ...] = ("round", "sample", "strategy", "answer")
"""The columns of a run's ``queries.csv``."""


class Rater(Protocol):
    """Answers reward queries (:mod:`dospcot.core.raters`)."""

    def answer(self, round_: int, ids: np.ndarray, described: Sequence[dict[str, Any]]) -> np.ndarray:
        """(n,) the rewards of samples ``ids``."""


class QueriedTask(Protocol):
    """What a task adapter tells the queries about its pool of N samples (never a hidden reward)."""

    def met(self) -> np.ndarray:
        """(N,) bool, the samples the agents have met."""

    def labelled(self) -> np.ndarray:
        """(N,) bool, the samples whose reward is known (revealed, monitored or demonstrated)."""

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) bool each: the samples that ended their episode, and those cut by the time limit."""

    def describe(self, sample: int) -> dict[str, Any]:
        """What a person is shown of a sample: its key or step."""

    def reveal(self, ids: np.ndarray, rewards: np.ndarray) -> None:
        """Label samples ``ids`` with ``rewards`` in the store, for all their visits."""


class StoreQueries:
    """What the reward queries write into a task adapter's store, whose samples hold ``labelled``,
    ``label_value`` and ``hidden_reward`` arrays; and the hidden rewards the simulated rater reads."""

    store: Any

    def reveal(self, ids: np.ndarray, rewards: np.ndarray) -> None:
        """Label samples ``ids`` with ``rewards``, for all their visits."""
        self.store.labelled[ids] = True
        self.store.label_value[ids] = rewards

    def hidden_reward(self, ids: np.ndarray) -> np.ndarray:
        """The hidden rewards of samples ``ids``: for the simulated rater alone, never a learner."""
        return self.store.hidden_reward[ids]


ProbabilitiesOf = Callable[[], "np.ndarray | None"]
"""Returns the (m, N, K) class probabilities of the task's pool, or None before any classifier was fit."""


def query_budget(label_fraction: float, met: int, revealed: int) -> int:
    """How many samples may be revealed now: ``ceil(label_fraction x met) - revealed``, at least 0."""
    return max(0, math.ceil(label_fraction * met - 1e-9) - revealed)


def margins(probabilities: np.ndarray) -> np.ndarray:
    """(N,) the mean over views of the gap between each sample's two most likely classes.

    :param probabilities: (m, N, K) each view's class probabilities.
    """
    top = np.sort(probabilities, axis=-1)
    second = top[..., -2] if probabilities.shape[-1] > 1 else np.zeros(top.shape[:-1])
    return (top[..., -1] - second).mean(axis=0)


def disagreement_order(probabilities: np.ndarray) -> np.ndarray:
    """Sample indices, most confident disagreements first, then the agreeing samples by uncertainty.

    A sample is a disagreement when two views predict different classes; its confidence is the views'
    mean probability of their own predicted class.

    :param probabilities: (m, N, K) each view's class probabilities, m >= 2.
    """
    predicted = probabilities.argmax(axis=-1)
    disagree = (predicted != predicted[0]).any(axis=0)
    confidence = probabilities.max(axis=-1).mean(axis=0)
    # lexsort sorts by its last key first: disagreements, then by confidence or by margin; ties by id.
    secondary = np.where(disagree, -confidence, margins(probabilities))
    return np.lexsort((np.arange(disagree.size), secondary, ~disagree))


def outcome_order(
    candidates: np.ndarray, n: int, terminated: np.ndarray, truncated: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """``n`` candidate indices that cover the kinds of step: each kind present (ended its episode, cut
    by the time limit, the rest) an equal floor ``ceil(n / kinds)``, in that order, at random within a
    kind; what a kind lacks goes to the next, and what is left at random."""
    kinds = [terminated, truncated & ~terminated, ~terminated & ~truncated]
    pools = [rng.permutation(np.flatnonzero(candidates & kind)) for kind in kinds]
    present = [pool for pool in pools if pool.size]
    chosen: list[int] = []
    floor = math.ceil(n / len(present)) if present else 0
    for pool in present:
        chosen += pool[: min(floor, n - len(chosen))].tolist()
    rest = np.setdiff1d(np.flatnonzero(candidates), chosen)
    chosen += rng.permutation(rest)[: n - len(chosen)].tolist()
    return np.asarray(chosen, dtype=np.int64)


def choose_queries(
    strategy: str,
    candidates: np.ndarray,
    n: int,
    rng: np.random.Generator,
    *,
    random_share: float,
    probabilities: np.ndarray | None = None,
    terminated: np.ndarray | None = None,
    truncated: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The samples to query now and, for each, whether it was drawn at random.

    :param strategy: one of :data:`~dospcot.config.choices.LABEL_STRATEGIES` but ``"uniform"``.
    :param candidates: (N,) bool, the samples that may be queried (met, not yet labelled).
    :param n: how many to query (at most the candidates).
    :param rng: the round's query stream (:func:`dospcot.seeding.query_seed`).
    :param random_share: the share of ``n`` drawn at random by a strategy other than ``"random"``.
    :param probabilities: (m, N, K) the views' class probabilities; None before any classifier was fit
        (the classifier strategies then choose at random).
    :param terminated: (N,) bool, samples that ended their episode (``"outcomes"``).
    :param truncated: (N,) bool, samples cut by the time limit (``"outcomes"``).
    :return: (n,) int sample indices in the order chosen, and (n,) bool, True where drawn at random.
    """
    n = min(n, int(candidates.sum()))
    guided = 0 if strategy == "random" else n - round(random_share * n)
    if strategy in CLASSIFIER_STRATEGIES and probabilities is None:
        guided = 0
    if guided == 0:
        chosen = np.zeros(0, dtype=np.int64)
    elif strategy == "outcomes":
        chosen = outcome_order(candidates, guided, terminated, truncated, rng)
    else:
        if strategy == "uncertainty":
            order = np.lexsort((np.arange(candidates.size), margins(probabilities)))
        else:
            order = disagreement_order(probabilities)
        chosen = order[candidates[order]][:guided]
    rest = candidates.copy()
    rest[chosen] = False
    drawn = rng.permutation(np.flatnonzero(rest))[: n - chosen.size]
    ids = np.concatenate([chosen, drawn]).astype(np.int64)
    return ids, np.arange(ids.size) >= chosen.size


class RewardQueries:
    """A run's reward queries: which samples are revealed, the round each sample was first met, and
    every answer, bought after each round's collection (:meth:`buy`).

    :param strategy: the run's ``training.label_strategy`` (not ``"uniform"``).
    :param label_fraction: the budget's share of the samples met.
    :param random_share: ``training.query_random_share``.
    :param recent_rounds: ``training.query_recent_rounds`` (0: every round's samples alike).
    :param rater: answers the queries (:mod:`dospcot.core.raters`).
    """

    def __init__(
        self, strategy: str, label_fraction: float, random_share: float, recent_rounds: int, rater: Rater
    ) -> None:
        self.strategy, self.label_fraction = strategy, label_fraction
        self.random_share, self.recent_rounds, self.rater = random_share, recent_rounds, rater
        self.revealed = np.zeros(0, dtype=bool)
        """(N,) the samples the rater labelled."""
        self.met_round = np.zeros(0, dtype=np.int64)
        """(N,) the round (1-based) each sample was first met; 0: not yet."""
        self.log: list[dict[str, Any]] = []
        """One row per answer: round, sample, how it was chosen (the strategy or ``"random"``), answer."""

    def buy(
        self, round_: int, task: QueriedTask, probabilities: ProbabilitiesOf, rng: np.random.Generator
    ) -> None:
        """Choose this round's queries, ask the rater and reveal the answers in the task's store.

        :param probabilities: the views' class probabilities of the task's pool, or None before any
            classifier was fit; called only by the classifier strategies.
        :raises QueriesPending: the rater waits for a person; nothing was revealed.
        """
        met = task.met()
        grow = met.size - self.revealed.size
        self.revealed = np.concatenate([self.revealed, np.zeros(grow, dtype=bool)])
        self.met_round = np.concatenate([self.met_round, np.zeros(grow, dtype=np.int64)])
        self.met_round[met & (self.met_round == 0)] = round_
        candidates = met & ~task.labelled()
        n = min(
            query_budget(self.label_fraction, int(met.sum()), int(self.revealed.sum())), int(candidates.sum())
        )
        if self.recent_rounds:  # the latest rounds' samples first, the older ones when they run short
            recent = candidates & (self.met_round > round_ - self.recent_rounds)
            candidates = recent if recent.sum() >= n else candidates
        terminated, truncated = task.episode_ends()
        probs = probabilities() if self.strategy in CLASSIFIER_STRATEGIES else None
        ids, drawn = choose_queries(
            self.strategy,
            candidates,
            n,
            rng,
            random_share=self.random_share,
            probabilities=probs,
            terminated=terminated,
            truncated=truncated,
        )
        described = [task.describe(int(i)) for i in ids]
        if probs is not None:
            for row, i in zip(described, ids, strict=True):
                for j in range(probs.shape[0]):
                    row[f"view{j}_class"] = int(probs[j, i].argmax())
                    row[f"view{j}_confidence"] = round(float(probs[j, i].max()), 4)
        answers = self.rater.answer(round_, ids, described)
        task.reveal(ids, answers)
        self.revealed[ids] = True
        self.log += [
            {
                "round": round_,
                "sample": int(i),
                "strategy": "random" if r else self.strategy,
                "answer": float(a),
            }
            for i, r, a in zip(ids, drawn, answers, strict=True)
        ]

    def answers_of(self, round_: int) -> np.ndarray:
        """The answers given in round ``round_``."""
        return np.array([row["answer"] for row in self.log if row["round"] == round_])
