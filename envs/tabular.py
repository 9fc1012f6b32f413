"""A deterministic tabular MDP read from a gymnasium toy-text env, for vectorised agents and exact metrics.

The vectorised tabular path steps thousands of (run, agent) pairs in lock step with numpy; doing
that through gymnasium env objects would be orders of magnitude slower. This module reads the
transition table ``env.unwrapped.P`` once, so the env stays the single source of truth (a test
checks that stepping both gives the same transitions), and gives value iteration for the exact
optimum.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from dospcot.envs.views import View


@dataclass(frozen=True)
class TabularMDP:
    """Arrays of a deterministic MDP with ``S`` states and ``A`` actions.

    :param next_state: int array (S, A), the state reached.
    :param reward: float array (S, A), the true reward. Only the masking layer and metrics may read
        it; learners receive what the mask reveals.
    :param terminal: bool array (S, A), whether the transition ends the episode.
    :param start_state: the state every episode starts from.
    :param max_episode_steps: the episode length limit.
    :param views: feature matrix (S, d) of every state under each view, by view name.
    """

    next_state: np.ndarray
    reward: np.ndarray
    terminal: np.ndarray
    start_state: int
    max_episode_steps: int
    views: Mapping[str, np.ndarray]

    @property
    def n_states(self) -> int:
        return int(self.next_state.shape[0])

    @property
    def n_actions(self) -> int:
        return int(self.next_state.shape[1])

    @classmethod
    def from_env(cls, env: gym.Env, views: Mapping[str, View], max_episode_steps: int) -> TabularMDP:
        """Read the transition table of a deterministic toy-text env (one with ``unwrapped.P``)."""
        base = env.unwrapped
        n_states, n_actions = int(base.observation_space.n), int(base.action_space.n)
        next_state = np.zeros((n_states, n_actions), dtype=np.int64)
        reward = np.zeros((n_states, n_actions), dtype=np.float64)
        terminal = np.zeros((n_states, n_actions), dtype=bool)
        for s in range(n_states):
            for a in range(n_actions):
                outcomes = base.P[s][a]
                if len(outcomes) != 1:
                    raise ValueError(f"TabularMDP needs a deterministic env; P[{s}][{a}] has {outcomes}")
                _, next_state[s, a], reward[s, a], terminal[s, a] = outcomes[0]
        features = {
            name: np.stack([view.fn(s) for s in range(n_states)]).astype(np.float32)
            for name, view in views.items()
        }
        start = int(np.flatnonzero(base.initial_state_distrib)[0])
        return cls(next_state, reward, terminal, start, max_episode_steps, features)

    def value_iteration(self, discount: float, tol: float = 1e-10, max_iter: int = 100_000) -> np.ndarray:
        """Optimal action values Q* of shape (S, A) under the true rewards.

        With ``discount = 1`` this is a stochastic shortest path problem: states that can reach no
        terminal transition (pockets walled off from the goal) have value -inf, and the others
        converge because every step costs.
        """
        proper = self.can_terminate()
        counted = proper if discount == 1.0 else np.ones(self.n_states, dtype=bool)
        v = np.zeros(self.n_states)
        for _ in range(max_iter):
            new_v = self._backup(v, discount).max(axis=1)
            if np.max(np.abs(new_v - v)[counted], initial=0.0) < tol:
                return self._backup(np.where(counted, new_v, -np.inf), discount)
            v = new_v
        raise RuntimeError(f"value iteration did not converge in {max_iter} sweeps")

    def _backup(self, v: np.ndarray, discount: float) -> np.ndarray:
        """``r + discount * v(s')`` for every (s, a), with no bootstrap after a terminal transition."""
        return np.where(self.terminal, self.reward, self.reward + discount * v[self.next_state])

    def can_terminate(self) -> np.ndarray:
        """Bool array (S,): states from which some sequence of actions ends the episode."""
        proper = self.terminal.any(axis=1)
        while True:
            grown = proper | proper[self.next_state].any(axis=1)
            if np.array_equal(grown, proper):
                return proper
            proper = grown

    def optimal_actions(self, discount: float, atol: float = 1e-8) -> np.ndarray:
        """Bool array (S, A): True for every action within ``atol`` of the optimum (all ties)."""
        q = self.value_iteration(discount)
        return q >= q.max(axis=1, keepdims=True) - atol

    def reachable_nonterminal(self) -> np.ndarray:
        """Bool array (S,): states reachable from the start without passing a terminal transition."""
        seen = np.zeros(self.n_states, dtype=bool)
        frontier = [self.start_state]
        seen[self.start_state] = True
        while frontier:
            s = frontier.pop()
            for a in range(self.n_actions):
                nxt = int(self.next_state[s, a])
                if not self.terminal[s, a] and not seen[nxt]:
                    seen[nxt] = True
                    frontier.append(nxt)
        return seen
