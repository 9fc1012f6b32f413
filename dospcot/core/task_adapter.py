"""What a task adapter supplies to a co-training run (:class:`TaskAdapter`): its envs, its store and
pool, its reward classes and its evaluator. The adapters that implement it are
:mod:`dospcot.adapters`; the round that drives one is :class:`~dospcot.core.sb3_round.CoTrainingRun`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from dospcot.core.queries import QueriedTask
from dospcot.core.reward_classes import QuantileRewardClasses, RunRewardClasses
from dospcot.core.self_paced import RunPool
from dospcot.policies import ExpectedSarsaDQN


class TaskAdapter(QueriedTask, Protocol):
    """What a task adapter supplies to :class:`~dospcot.core.sb3_round.CoTrainingRun` (and, for reward
    queries, what :class:`~dospcot.core.queries.QueriedTask` asks, plus ``hidden_reward(ids)`` for the
    simulated rater alone)."""

    store: Any
    """Every step the agents took, in the form the pool is built from; its ``state_dict()`` and
    ``load_state_dict(state)`` checkpoint it in place."""
    classes: RunRewardClasses | QuantileRewardClasses
    """The reward classes of the run's labels (one run)."""
    n_classes: int
    """K, the most reward classes the run may hold (the classifiers' outputs)."""

    def agent_env(self, k: int, view: str) -> gym.Env:
        """Agent ``k``'s env: masked, observing ``view``, writing every step into the store with its
        pool sample in ``info["store_id"]``."""

    def observations(self, view: str) -> np.ndarray | None:
        """(S, d) the view of every state, for a ``tabular`` agent; None where states are not known."""

    def feature_dims(self) -> list[int]:
        """Each view's classifier input width."""

    def pool(self, dtype: type = np.float32) -> RunPool:
        """This round's pool, after the classes have seen every label so far, its features in
        ``dtype`` (the classifiers' own, so that a fit makes no copy of them)."""

    def true_class(self) -> np.ndarray:
        """(N,) each pool sample's hidden reward as a class of the run, -1 where the reward is a value
        no label has shown (metrics only)."""

    def evaluate(self, agents: Sequence[ExpectedSarsaDQN]) -> dict[str, np.ndarray]:
        """Each agent's greedy policy: (m,) ``greedy_return``, ``success``, ``normalised_score``,
        ``agreement``."""

    def reference_returns(self) -> dict[str, float]:
        """The returns the normalised score is measured between."""

    def demonstrations(self, view: str) -> tuple[np.ndarray, np.ndarray] | None:
        """(N, d) the demonstrated states in ``view`` and (N,) the demonstrated actions, for the
        agents' large-margin loss (read only when it is on); None: the run has no demonstrations."""
