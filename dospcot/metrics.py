"""Metrics of docs/design.md section 4: policy quality against the exact optimum, pseudo-reward quality
against the hidden truth. Summaries over seeds are :mod:`dospcot.statistics`.

These functions are the only readers of the hidden reward; nothing they return is fed back to a
learner.
"""

from __future__ import annotations

import json
from importlib import resources

import numpy as np

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
