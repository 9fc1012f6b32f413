"""Tabular Q-learning, SARSA and Expected SARSA, vectorised over a batch of independent learners.

Each of the B *slots* is one learner (one agent of one run) with its own Q-table, kind, exploration
rate and random stream; numpy steps all of them at once. Updates take a reward and a per-sample
weight w from the co-trainer: ``Q(s, a) += lr * w * (target - Q(s, a))``, so a weight-0 sample
(a still unlabelled transition) drives no update.

Epsilon-greedy here means: with probability eps a uniformly random action, else a uniformly random
one among the tied maxima of Q(s, .). Expected SARSA's target takes the expectation under exactly
that policy; since every tied maximum has the same value, it equals
``eps * mean_a Q(s', a) + (1 - eps) * max_a Q(s', a)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

TABULAR_KINDS: tuple[str, ...] = ("q", "sarsa", "esarsa")
_Q, _SARSA, _ESARSA = range(3)
# Uniforms are drawn per slot in blocks of this many steps, for speed; changing it changes results.
_BLOCK = 4096


def check_agent_kind(kind: str) -> int:
    """Index of ``kind`` in :data:`TABULAR_KINDS`; ``ValueError`` naming the allowed kinds otherwise."""
    if kind not in TABULAR_KINDS:
        raise ValueError(f"unknown tabular agent kind {kind!r}; allowed: {TABULAR_KINDS}")
    return TABULAR_KINDS.index(kind)


def epsilon_greedy_probs(q: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Action probabilities of epsilon-greedy with the greedy mass split across tied maxima.

    :param q: (..., A) action values.
    :param eps: exploration rate, broadcastable to ``q.shape[:-1]``.
    :return: (..., A) probabilities.
    """
    eps = np.asarray(eps, dtype=np.float64)[..., None]
    ties = q == q.max(axis=-1, keepdims=True)
    return eps / q.shape[-1] + (1.0 - eps) * ties / ties.sum(axis=-1, keepdims=True)


def expected_value(q: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Expected SARSA's bootstrap value sum_a pi_eps(a | s') Q(s', a) for rows ``q`` (..., A)."""
    return (epsilon_greedy_probs(q, eps) * q).sum(axis=-1)


class TabularAgents:
    """B independent tabular learners.

    :param kinds: the kind of each slot, from :data:`TABULAR_KINDS`.
    :param n_states: S.
    :param n_actions: A.
    :param learning_rate: step size alpha.
    :param discount: discount factor.
    :param seeds: one seed per slot for its exploration stream.
    """

    def __init__(
        self,
        kinds: Sequence[str],
        n_states: int,
        n_actions: int,
        learning_rate: float,
        discount: float,
        seeds: Sequence[int],
    ) -> None:
        if len(kinds) != len(seeds):
            raise ValueError(f"need one seed per slot: {len(kinds)} kinds, {len(seeds)} seeds")
        if not 0 < learning_rate <= 1:
            raise ValueError(f"learning_rate must lie in (0, 1], got {learning_rate}")
        if not 0 <= discount <= 1:
            raise ValueError(f"discount must lie in [0, 1], got {discount}")
        self.kind = np.array([check_agent_kind(k) for k in kinds])
        self.q = np.zeros((len(kinds), n_states, n_actions))
        self.learning_rate = learning_rate
        self.discount = discount
        self._rngs = [np.random.default_rng(s) for s in seeds]
        self._uniforms = np.stack([rng.random((_BLOCK, 2)) for rng in self._rngs])
        self._cursor = np.zeros(len(kinds), dtype=np.int64)

    @property
    def n_slots(self) -> int:
        return int(self.q.shape[0])

    def draw(self, slots: np.ndarray) -> np.ndarray:
        """Two uniforms for each slot in ``slots`` (B_sub,) from its own stream: (B_sub, 2)."""
        exhausted = slots[self._cursor[slots] >= _BLOCK]
        for i in exhausted:
            self._uniforms[i] = self._rngs[i].random((_BLOCK, 2))
            self._cursor[i] = 0
        u = self._uniforms[slots, self._cursor[slots]]
        self._cursor[slots] += 1
        return u

    def act(self, slots: np.ndarray, states: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """Epsilon-greedy actions (random tie-breaking) of ``slots`` in ``states``; eps per slot."""
        return self._choose(self.q[slots, states], self.draw(slots), eps)

    def _choose(self, rows: np.ndarray, u: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """Epsilon-greedy actions for Q rows (B_sub, A) from uniforms ``u`` (B_sub, 2)."""
        ties = rows == rows.max(axis=1, keepdims=True)
        n_ties = ties.sum(axis=1)
        pick = np.minimum((u[:, 1] * n_ties).astype(np.int64), n_ties - 1)
        greedy = (np.cumsum(ties, axis=1) > pick[:, None]).argmax(axis=1)
        n_actions = self.q.shape[2]
        random_action = np.minimum((u[:, 1] * n_actions).astype(np.int64), n_actions - 1)
        return np.where(u[:, 0] < eps, random_action, greedy)

    def _bootstrap(
        self, slots: np.ndarray, rows: np.ndarray, next_actions: np.ndarray, eps: np.ndarray
    ) -> np.ndarray:
        """The bootstrap value of each slot's kind from its Q(s', .) row: max (Q), Q(s', a') (SARSA),
        expectation (ESARSA)."""
        sarsa = rows[np.arange(len(slots)), next_actions]
        expected = expected_value(rows, eps)
        kind = self.kind[slots]
        return np.where(kind == _Q, rows.max(axis=1), np.where(kind == _SARSA, sarsa, expected))

    def _learn(
        self,
        slots: np.ndarray,
        states: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        weights: np.ndarray,
        terminated: np.ndarray,
        value: np.ndarray,
    ) -> None:
        """Q(s, a) += lr * w * (r + discount * value - Q(s, a)), with no bootstrap after termination."""
        target = rewards + self.discount * (~terminated) * value
        current = self.q[slots, states, actions]
        self.q[slots, states, actions] = current + self.learning_rate * weights * (target - current)

    def update(
        self,
        slots: np.ndarray,
        states: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        weights: np.ndarray,
        next_states: np.ndarray,
        terminated: np.ndarray,
        next_actions: np.ndarray,
        eps: np.ndarray,
    ) -> None:
        """One weighted TD update per slot; ``next_actions`` is used by SARSA slots only.

        Truncated (time-limit) transitions bootstrap as usual; only ``terminated`` ones do not.
        """
        value = self._bootstrap(slots, self.q[slots, next_states], next_actions, eps)
        self._learn(slots, states, actions, rewards, weights, terminated, value)

    def act_and_update(
        self,
        slots: np.ndarray,
        states: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        weights: np.ndarray,
        next_states: np.ndarray,
        terminated: np.ndarray,
        eps: np.ndarray,
    ) -> np.ndarray:
        """``a' = act(slots, next_states, eps)`` then ``update(..., a', eps)``, reading the rows
        Q(s', .) once (the online step of the collection loop); returns a'."""
        rows = self.q[slots, next_states]
        next_actions = self._choose(rows, self.draw(slots), eps)
        value = self._bootstrap(slots, rows, next_actions, eps)
        self._learn(slots, states, actions, rewards, weights, terminated, value)
        return next_actions

    def sweep(
        self,
        known: np.ndarray,
        next_state: np.ndarray,
        terminal: np.ndarray,
        rewards: np.ndarray,
        weights: np.ndarray,
        eps: np.ndarray,
    ) -> None:
        """One synchronous weighted TD update of every known transition of every slot.

        The policy update after co-training: each agent re-learns its stored transitions under the
        new rewards and weights. SARSA slots draw a' from their epsilon-greedy policy at s'.

        :param known: (B, S, A) bool, transitions the slot's run has stored.
        :param next_state: (B, S, A) the stored s' (any value where not known).
        :param terminal: (B, S, A) bool, whether the stored transition ended the episode.
        :param rewards: (B, S, A) rewards (true where labelled, pseudo where admitted).
        :param weights: (B, S, A) weights in [0, 1].
        :param eps: (B,) exploration rate of each slot.
        """
        n_slots, n_states, n_actions = self.q.shape
        slot_index = np.arange(n_slots)[:, None, None]
        rows = self.q[slot_index, np.where(known, next_state, 0)]  # (B, S, A, A)
        eps_b = eps[:, None, None]
        probs = epsilon_greedy_probs(rows, eps_b)
        u = np.stack([rng.random((n_states, n_actions)) for rng in self._rngs])
        sampled = (np.cumsum(probs, axis=-1) > u[..., None]).argmax(axis=-1)
        kind = self.kind[:, None, None]
        value = np.where(
            kind == _Q,
            rows.max(axis=-1),
            np.where(
                kind == _SARSA,
                np.take_along_axis(rows, sampled[..., None], axis=-1)[..., 0],
                (probs * rows).sum(axis=-1),
            ),
        )
        target = rewards + self.discount * (~terminal) * value
        self.q += self.learning_rate * np.where(known, weights, 0.0) * (target - self.q)

    def greedy_actions(self) -> np.ndarray:
        """(B, S) argmax_a Q(s, a), lowest index on ties (the paper's convention)."""
        return self.q.argmax(axis=2)
