"""Metrics of docs/design.md section 4: policy quality against the exact optimum, pseudo-reward quality
against the hidden truth, and summaries over seeds.

These functions are the only readers of the hidden reward; nothing they return is fed back to a
learner.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources

import numpy as np
from scipy import stats

from dospcot.envs.tabular import TabularMDP


def paper_reference_policy() -> np.ndarray:
    """The 48 greedy actions the seed paper's code scores CliffWalking policies against."""
    text = resources.files("dospcot").joinpath("data/paper_reference_policy.json").read_text()
    return np.array(json.loads(text)["greedy_action"], dtype=np.int64)


def published_paper_tables() -> dict:
    """The numbers printed in the seed paper (for side-by-side comparison only)."""
    return json.loads(resources.files("dospcot").joinpath("data/paper_tables.json").read_text())


def paper_accuracy(greedy: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Share of states whose greedy action equals the reference: (B,) from greedy actions (B, S)."""
    return (greedy == reference[None, :]).mean(axis=1)


def optimal_action_agreement(greedy: np.ndarray, optimal: np.ndarray, states: np.ndarray) -> np.ndarray:
    """Share of ``states`` where the greedy action is optimal (any of tied optima): (B,).

    :param greedy: (B, S) greedy actions.
    :param optimal: (S, A) bool optimal-action sets from value iteration.
    :param states: (S,) bool, the states that count (reachable and non-terminal).
    """
    hits = optimal[np.arange(optimal.shape[0])[None, :], greedy]
    return hits[:, states].mean(axis=1)


def greedy_rollout(mdp: TabularMDP, greedy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undiscounted true return and success (goal reached) of each greedy policy (B, S): two (B,)."""
    n = greedy.shape[0]
    state = np.full(n, mdp.start_state)
    ret = np.zeros(n)
    running = np.ones(n, dtype=bool)
    success = np.zeros(n, dtype=bool)
    for _ in range(mdp.max_episode_steps):
        action = greedy[np.arange(n), state]
        ret += np.where(running, mdp.reward[state, action], 0.0)
        ended = mdp.terminal[state, action] & running
        success |= ended
        running &= ~ended
        state = mdp.next_state[state, action]
    return ret, success


def random_policy_return(mdp: TabularMDP) -> float:
    """Exact expected undiscounted return of the uniform random policy over one episode."""
    value = np.zeros(mdp.n_states)
    for _ in range(mdp.max_episode_steps):
        value = (mdp.reward + (~mdp.terminal) * value[mdp.next_state]).mean(axis=1)
    return float(value[mdp.start_state])


def normalised_score(ret: np.ndarray, random_return: float, oracle_return: float) -> np.ndarray:
    """``(R - R_random) / (R_oracle - R_random)``: 0 for the random policy, 1 for the optimum."""
    return (ret - random_return) / (oracle_return - random_return)


class GreedyPolicyMetrics:
    """Exact metrics of greedy policies on a deterministic task (docs/design.md section 4), with the optimum
    and the random policy's return computed once.

    :param mdp: the task.
    :param discount: discount of the value iteration that defines the optimal actions and the
        optimal greedy policy (whose undiscounted return is the score's R_oracle).
    """

    def __init__(self, mdp: TabularMDP, discount: float) -> None:
        self.mdp = mdp
        self.optimal_actions = mdp.optimal_actions(discount)
        self.counted = mdp.reachable_nonterminal()
        self.random_return = random_policy_return(mdp)
        best = mdp.value_iteration(discount).argmax(axis=1)[None]
        self.optimal_return = float(greedy_rollout(mdp, best)[0][0])

    def __call__(self, greedy: np.ndarray) -> dict[str, np.ndarray]:
        """(B,) ``greedy_return``, ``success`` (bool), ``normalised_score`` and ``agreement`` of the
        greedy policies (B, S)."""
        ret, success = greedy_rollout(self.mdp, greedy)
        return {
            "greedy_return": ret,
            "success": success,
            "normalised_score": normalised_score(ret, self.random_return, self.optimal_return),
            "agreement": optimal_action_agreement(greedy, self.optimal_actions, self.counted),
        }


def bootstrap_ci(
    values: np.ndarray, confidence: float = 0.95, n_resamples: int = 10_000, seed: int = 0
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``values``: ``scipy.stats.bootstrap`` with the
    percentile method, ``n_resamples`` resamples of the values drawn with replacement, from a generator
    seeded by ``seed`` (so a table rebuilds to the same digits). One value is its own interval (SciPy
    needs two); no value gives NaN. Why percentile and not SciPy's default BCa: docs/design.md,
    "Statistics"."""
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return float("nan"), float("nan")
    if values.size == 1:
        return float(values[0]), float(values[0])
    result = stats.bootstrap(
        (values,),
        np.mean,
        n_resamples=n_resamples,
        confidence_level=confidence,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean after dropping ``floor(n / 4)`` values at each end
    (``scipy.stats.trim_mean`` at 0.25, as rliable computes it)."""
    return float(stats.trim_mean(np.asarray(values, dtype=np.float64), 0.25))


@dataclass(frozen=True)
class SeedSummary:
    """A metric over seeds: mean, 95% bootstrap interval, IQM and the number of finite values."""

    mean: float
    low: float
    high: float
    iqm: float
    n: int

    @classmethod
    def of(cls, values: Sequence[float], iqm_min_n: int = 1) -> SeedSummary:
        """Summarise the finite ``values``; the IQM is NaN below ``iqm_min_n`` of them."""
        finite = np.array([v for v in values if math.isfinite(v)], dtype=np.float64)
        if finite.size == 0:
            return cls(math.nan, math.nan, math.nan, math.nan, 0)
        low, high = bootstrap_ci(finite)
        iqm_value = iqm(finite) if finite.size >= iqm_min_n else math.nan
        return cls(float(finite.mean()), low, high, iqm_value, int(finite.size))

    def __str__(self) -> str:
        if self.n == 0 or math.isnan(self.mean):
            return "n/a"
        digits = 1 if abs(self.mean) >= 10 else 3
        return f"{self.mean:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"
