"""Active reward queries: which samples a rater labels, round by round, and how many (docs/queries.md).

Under ``training.label_strategy = "uniform"`` (the default, the paper's setting) a fixed random mask
reveals a share of the rewards whatever the agents do. Every other strategy reveals nothing up front:
after each round's collection it buys labels for chosen samples (keys on a keyed pool, steps
otherwise). A revealed sample stays revealed, for all its visits, past and future.

**How many.** With ``training.label_budget`` B > 0 the run may buy B answers over its whole length,
whatever its number of agents or views, spread by ``training.query_schedule``
(:func:`scheduled_labels`): ``"asap"`` spends it as soon as there are candidates, ``"even"`` B / R a
round over R rounds, ``"decay"`` round r's share in proportion to 1 / r; ``training.first_round_share``
caps round 1, and what a round could not spend carries forward. With B = 0 (the default) the budget
is a share of the samples met: at most ``ceil(label_fraction x samples met so far)`` in all
(:func:`query_budget`), what the uniform mask reveals among them, in expectation.

**Which.** The choice reads what an agent may read (the samples met, their episode ends, the reward
classifiers' outputs), never a hidden reward; the rater alone reads the hidden reward of the samples
it is asked about (:class:`SimulatedRater`, or a person: :mod:`dospcot.raters.file_rater`).

- ``"random"``: the budget spent at random over the samples met (the active strategies' direct control);
- ``"outcomes"``: the queries first cover the kinds of step an agent sees without a reward: steps that
  ended an episode, steps cut by the time limit, and the rest, each kind an equal floor of the round's
  queries (a kind with fewer candidates gives its remainder to the next); the episode ends' floor
  spreads over the distinct states the ends reached, those no label has shown first, before it asks
  about one twice (:func:`spread_ends`);
- ``"uncertainty"``: the smallest margin between the two most likely classes, mean over the views'
  classifiers (uncertainty sampling; one view: self-training's partner);
- ``"disagreement"`` (co-testing, Muslea et al.): samples whose views' classifiers predict different
  classes, the most confident disagreements first (the views' mean confidence in their own class),
  then the rest by uncertainty; needs two or more views, or the reward-model peer's ensemble, whose
  members play the views;
- ``"a+b"`` (``"outcomes+disagreement"``, ``"outcomes+uncertainty"``): a's choice, then b's, each
  half of the chosen queries.

Every strategy but ``"random"`` keeps a random share of each round's queries
(``training.query_random_share``). Each may prefer the samples first met in the latest
``training.query_recent_rounds`` rounds, choose among a random pool of ``training.query_pool_factor``
times its queries, give a floor of its queries to every reward class the classifiers predict
(``training.query_class_floor``) and pass over the samples its views agree on with a confidence of
``training.query_skip_confidence`` or more. Before any classifier was fit (the first round) what needs
one is skipped: a classifier-driven strategy chooses at random, a combination leaves it to its other
part.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from dospcot.config.choices import CLASSIFIER_STRATEGIES
from dospcot.config.learning_sections import TrainingConfig
from dospcot.core.end_states import EndStates, spread_ends

LOG_COLUMNS: tuple[str, ...] = ("round", "sample", "strategy", "answer")
"""The columns of a run's ``queries.csv``."""


class Rater(Protocol):
    """Answers reward queries: :class:`SimulatedRater`, or a person through
    :class:`dospcot.raters.file_rater.FileRater`."""

    def answer(self, round_: int, ids: np.ndarray, described: Sequence[dict[str, Any]]) -> np.ndarray:
        """(n,) the rewards of samples ``ids``."""


class SimulatedRater:
    """Answers each query with the sample's hidden reward.

    :param hidden_reward: the hidden rewards of given sample ids (the task's store): the one reader of a
        hidden reward outside the metrics, and only of the samples it is asked about.
    """

    def __init__(self, hidden_reward: Callable[[np.ndarray], np.ndarray]) -> None:
        self.hidden_reward = hidden_reward

    def answer(self, round_: int, ids: np.ndarray, described: Sequence[dict[str, object]]) -> np.ndarray:
        """(n,) the rewards of samples ``ids`` (``described`` is what a person would be shown)."""
        return np.asarray(self.hidden_reward(ids), dtype=np.float64)


class QueriedTask(Protocol):
    """What a task adapter tells the queries about its pool of N samples (never a hidden reward)."""

    def met(self) -> np.ndarray:
        """(N,) bool, the samples the agents have met."""

    def labelled(self) -> np.ndarray:
        """(N,) bool, the samples whose reward is known (revealed, monitored or demonstrated)."""

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) bool each: the samples that ended their episode, and those cut by the time limit."""

    def end_states(self, ids: np.ndarray) -> np.ndarray:
        """The states samples ``ids`` led to, as :data:`EndStates` describes them (read by
        ``"outcomes"`` alone)."""

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


def scheduled_labels(budget: int, rounds: int, round_: int, schedule: str, first_round_share: float) -> int:
    """The answers rounds 1 to ``round_`` may have bought in all under a label budget.

    :param budget: ``training.label_budget``, the answers of the whole run.
    :param rounds: R, the run's rounds.
    :param round_: r, 1-based; the last round may spend whatever is left.
    :param schedule: ``"asap"`` (all of it), ``"even"`` (r / R of it) or ``"decay"`` (H_r / H_R of it,
        H_r the r-th harmonic number: round r's own share in proportion to 1 / r).
    :param first_round_share: the cap on round 1's share, in (0, 1].
    :return: floor(budget x share), so a round buys this minus what the rounds before it bought.
    """
    if round_ >= rounds:
        return budget
    if schedule == "asap":
        share = 1.0
    elif schedule == "even":
        share = round_ / rounds
    else:
        harmonic = np.cumsum(1.0 / np.arange(1, rounds + 1))
        share = float(harmonic[round_ - 1] / harmonic[-1])
    if round_ == 1:
        share = min(share, first_round_share)
    return math.floor(budget * share + 1e-9)


def strategy_parts(strategy: str) -> tuple[str, ...]:
    """The strategies a label strategy combines: ``("outcomes", "disagreement")`` for
    ``"outcomes+disagreement"``, the strategy alone otherwise."""
    return tuple(strategy.split("+"))


def reads_classifiers(strategy: str) -> bool:
    """Whether a label strategy (or a part of a combination) reads the reward classifiers."""
    return any(part in CLASSIFIER_STRATEGIES for part in strategy_parts(strategy))


def margins(probabilities: np.ndarray) -> np.ndarray:
    """(N,) the mean over views of the gap between each sample's two most likely classes.

    :param probabilities: (m, N, K) each view's class probabilities.
    """
    top = np.sort(probabilities, axis=-1)
    second = top[..., -2] if probabilities.shape[-1] > 1 else np.zeros(top.shape[:-1])
    return (top[..., -1] - second).mean(axis=0)


def uncertainty_order(probabilities: np.ndarray) -> np.ndarray:
    """Sample indices by the views' mean margin (:func:`margins`), smallest first; ties by id.

    :param probabilities: (m, N, K) each view's class probabilities.
    """
    return np.lexsort((np.arange(probabilities.shape[1]), margins(probabilities)))


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
    candidates: np.ndarray,
    n: int,
    terminated: np.ndarray,
    truncated: np.ndarray,
    rng: np.random.Generator,
    end_states: EndStates | None = None,
    labelled: np.ndarray | None = None,
) -> np.ndarray:
    """``n`` candidate indices that cover the kinds of step: each kind present (ended its episode, cut
    by the time limit, the rest) an equal floor ``ceil(n / kinds)``, in that order; what a kind lacks
    goes to the next, and what is left at random.

    Within the episode ends, with ``end_states`` the floor spreads over the distinct states the ends
    reached, those no labelled end (``labelled``: (N,) bool) reached first (:func:`spread_ends`);
    without it, and within the other kinds, at random."""
    kinds = [terminated, truncated & ~terminated, ~terminated & ~truncated]
    pools = [rng.permutation(np.flatnonzero(candidates & kind)) for kind in kinds]
    present = [i for i, pool in enumerate(pools) if pool.size]
    chosen: list[int] = []
    floor = math.ceil(n / len(present)) if present else 0
    for i in present:
        want = min(floor, n - len(chosen))
        if i == 0 and end_states is not None:
            seen = labelled if labelled is not None else np.zeros_like(terminated)
            labelled_ends = np.flatnonzero(seen & terminated)
            chosen += spread_ends(pools[0], want, end_states, labelled_ends, rng).tolist()
        else:
            chosen += pools[i][:want].tolist()
    rest = np.setdiff1d(np.flatnonzero(candidates), chosen)
    chosen += rng.permutation(rest)[: n - len(chosen)].tolist()
    return np.asarray(chosen, dtype=np.int64)


def class_floors(candidates: np.ndarray, n: int, probabilities: np.ndarray) -> np.ndarray:
    """``n`` candidate indices spread over the reward classes the views predict (the class of their
    mean probability): each class an equal floor ``ceil(n / classes)``, the rarest class among the
    candidates first, its least certain candidates first (:func:`margins`); a class with fewer
    candidates leaves its remainder unspent.

    :param candidates: (N,) bool.
    :param probabilities: (m, N, K) each view's class probabilities.
    """
    predicted = probabilities.mean(axis=0).argmax(axis=-1)
    order = uncertainty_order(probabilities)
    order = order[candidates[order]]
    classes, counts = np.unique(predicted[order], return_counts=True)
    if n <= 0 or classes.size == 0:
        return np.zeros(0, dtype=np.int64)
    floor = math.ceil(n / classes.size)
    chosen: list[np.ndarray] = []
    for c in classes[np.argsort(counts, kind="stable")]:
        room = n - sum(map(len, chosen))
        chosen.append(order[predicted[order] == c][: min(floor, room)])
    return np.concatenate(chosen).astype(np.int64)


def _part_choice(
    part: str,
    candidates: np.ndarray,
    n: int,
    rng: np.random.Generator,
    probabilities: np.ndarray | None,
    terminated: np.ndarray | None,
    truncated: np.ndarray | None,
    end_states: EndStates | None = None,
    labelled: np.ndarray | None = None,
) -> np.ndarray:
    """``n`` of the candidates as one strategy (not ``"random"``, nor a combination) chooses them."""
    if n <= 0:
        return np.zeros(0, dtype=np.int64)
    if part == "outcomes":
        return outcome_order(candidates, n, terminated, truncated, rng, end_states, labelled)
    if part == "uncertainty":
        order = uncertainty_order(probabilities)
    else:
        order = disagreement_order(probabilities)
    return order[candidates[order]][:n]


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
    class_floor: float = 0.0,
    pool_factor: int = 0,
    end_states: EndStates | None = None,
    labelled: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The samples to query now and, for each, whether it was drawn at random.

    :param strategy: one of :data:`~dospcot.config.choices.LABEL_STRATEGIES` but ``"uniform"``.
    :param candidates: (N,) bool, the samples that may be queried (met, not yet labelled).
    :param n: how many to query (at most the candidates).
    :param rng: the round's query stream (:func:`dospcot.seeding.query_seed`).
    :param random_share: the share of ``n`` drawn at random by a strategy other than ``"random"``.
    :param probabilities: (m, N, K) the views' class probabilities; None before any classifier was fit
        (what needs them is then skipped).
    :param terminated: (N,) bool, samples that ended their episode (``"outcomes"``).
    :param truncated: (N,) bool, samples cut by the time limit (``"outcomes"``).
    :param class_floor: the share of the chosen queries spread over the predicted classes first
        (:func:`class_floors`; needs ``probabilities``).
    :param pool_factor: choose among at most this many times the chosen queries' number of
        candidates, drawn at random (0: among all).
    :param end_states: describes the states samples led to (``"outcomes"``: its episode ends spread
        over them, :func:`spread_ends`); None: the episode ends at random.
    :param labelled: (N,) bool, the samples whose reward is known (``"outcomes"``, with
        ``end_states``: their end states count as asked).
    :return: (n,) int sample indices in the order chosen, and (n,) bool, True where drawn at random.
    """
    n = min(n, int(candidates.sum()))
    parts = [
        part
        for part in strategy_parts(strategy)
        if part != "random" and (probabilities is not None or part not in CLASSIFIER_STRATEGIES)
    ]
    guided = n - round(random_share * n) if parts else 0
    pool = candidates
    if pool_factor and guided:
        pool = np.zeros_like(candidates)
        pool[rng.permutation(np.flatnonzero(candidates))[: pool_factor * guided]] = True
    chosen = np.zeros(0, dtype=np.int64)
    if class_floor and probabilities is not None and guided:
        chosen = class_floors(pool, round(class_floor * guided), probabilities)
    for i, part in enumerate(parts):
        left = pool.copy()
        left[chosen] = False
        want = min((guided - chosen.size) // (len(parts) - i), int(left.sum()))
        picked = _part_choice(
            part, left, want, rng, probabilities, terminated, truncated, end_states, labelled
        )
        chosen = np.concatenate([chosen, picked]).astype(np.int64)
    rest = candidates.copy()
    rest[chosen] = False
    drawn = rng.permutation(np.flatnonzero(rest))[: n - chosen.size]
    ids = np.concatenate([chosen, drawn]).astype(np.int64)
    return ids, np.arange(ids.size) >= chosen.size


class RewardQueries:
    """A run's reward queries: which samples are revealed, the round each sample was first met, and
    every answer, bought after each round's collection (:meth:`buy`).

    :param training: the run's ``[training]`` section: its ``label_strategy`` (not ``"uniform"``), the
        budget (``label_budget`` with its schedule, or ``label_fraction``) and the ``query_*`` keys.
    :param rater: answers the queries (:class:`Rater`).
    """

    def __init__(self, training: TrainingConfig, rater: Rater) -> None:
        self.training, self.strategy, self.rater = training, training.label_strategy, rater
        self.revealed = np.zeros(0, dtype=bool)
        """(N,) the samples the rater labelled."""
        self.met_round = np.zeros(0, dtype=np.int64)
        """(N,) the round (1-based) each sample was first met; 0: not yet."""
        self.log: list[dict[str, Any]] = []
        """One row per answer: round, sample, how it was chosen (the strategy or ``"random"``), answer."""

    @property
    def reads_probabilities(self) -> bool:
        """Whether choosing reads the classifiers' probabilities: a classifier strategy, class floors
        or skipping the confident samples."""
        training = self.training
        return (
            reads_classifiers(self.strategy)
            or training.query_class_floor > 0
            or training.query_skip_confidence < 1
        )

    def allowance(self, round_: int, met: int) -> int:
        """How many answers round ``round_`` may buy, before the candidates are counted: what the
        schedule allows by now (:func:`scheduled_labels`) or the share of the ``met`` samples
        (:func:`query_budget`), less what was bought before."""
        training, bought = self.training, int(self.revealed.sum())
        if not training.label_budget:
            return query_budget(training.label_fraction, met, bought)
        allowed = scheduled_labels(
            training.label_budget,
            training.rounds,
            round_,
            training.query_schedule,
            training.first_round_share,
        )
        return max(0, allowed - bought)

    def buy(
        self, round_: int, task: QueriedTask, probabilities: ProbabilitiesOf, rng: np.random.Generator
    ) -> None:
        """Choose this round's queries, ask the rater and reveal the answers in the task's store.

        :param probabilities: the views' class probabilities of the task's pool, or None before any
            classifier was fit; called only when choosing reads them (:attr:`reads_probabilities`).
        :raises QueriesPending: the rater waits for a person; nothing was revealed.
        """
        training = self.training
        met = task.met()
        grow = met.size - self.revealed.size
        self.revealed = np.concatenate([self.revealed, np.zeros(grow, dtype=bool)])
        self.met_round = np.concatenate([self.met_round, np.zeros(grow, dtype=np.int64)])
        self.met_round[met & (self.met_round == 0)] = round_
        labelled = task.labelled()
        candidates = met & ~labelled
        probs = probabilities() if self.reads_probabilities else None
        if probs is not None and training.query_skip_confidence < 1:  # what the views agree on is known
            predicted = probs.argmax(axis=-1)
            agreed = (predicted == predicted[0]).all(axis=0)
            sure = probs.max(axis=-1).min(axis=0) >= training.query_skip_confidence
            candidates = candidates & ~(agreed & sure)
        n = min(self.allowance(round_, int(met.sum())), int(candidates.sum()))
        if training.query_recent_rounds:  # the latest rounds' samples first, the older ones when short
            recent = candidates & (self.met_round > round_ - training.query_recent_rounds)
            candidates = recent if recent.sum() >= n else candidates
        terminated, truncated = task.episode_ends()
        ids, drawn = choose_queries(
            self.strategy,
            candidates,
            n,
            rng,
            random_share=training.query_random_share,
            probabilities=probs,
            terminated=terminated,
            truncated=truncated,
            class_floor=training.query_class_floor,
            pool_factor=training.query_pool_factor,
            end_states=task.end_states if training.query_end_states == "spread" else None,
            labelled=labelled & met,
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
