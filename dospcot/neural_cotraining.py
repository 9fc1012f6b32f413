"""The grid adapter: DOSPCoT on a deterministic discrete task (a grid world), m views.

The round itself is :class:`~dospcot.cotraining_round.CoTrainingRun`'s; this adapter supplies what
a discrete task does differently (docs/design.md section 3):

- **the store** pools (s, a) keys: a key's id is ``s * A + a``, so the reward table is indexed by
  key, and a step of a key admitted in an earlier round reads its pseudo-reward at once;
- **the pool**: every seen key, its classifier input under view j being (view j of s, one-hot a,
  view j of the stored s') (:func:`~dospcot.key_pool.key_features`); classes are the distinct
  labelled reward values;
- **the evaluator**: value iteration gives the exact optimum, and each agent's greedy action in every
  state (read through its own view) is measured against it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from dospcot import metrics
from dospcot.checkpointing import InPlaceState
from dospcot.cotraining import Pool
from dospcot.cotraining_round import CoTrainingRun, NeuralConfig, NeuralRunSpec
from dospcot.demonstrations import expert_demonstrations
from dospcot.envs.masking import RewardMaskWrapper
from dospcot.envs.tabular import TabularMDP
from dospcot.envs.views import View, ViewObservationWrapper
from dospcot.key_pool import key_features
from dospcot.policies import ExpectedSarsaDQN
from dospcot.reward_classes import RewardClasses


class KeyStore(InPlaceState):
    """What the agents of one run have seen, by (s, a) key: the pool of the co-trainer.

    A key's id is ``s * A + a``; the reward table is indexed by it too, so a step of a key admitted
    in an earlier round reads its pseudo-reward at once, before the next co-training.

    :param n_states: S.
    :param n_actions: A.
    """

    def __init__(self, n_states: int, n_actions: int) -> None:
        self.n_actions = n_actions
        n_keys = n_states * n_actions
        self.visited = np.zeros(n_keys, dtype=bool)
        self.next_state = np.zeros(n_keys, dtype=np.int64)
        self.labelled = np.zeros(n_keys, dtype=bool)
        self.label_value = np.zeros(n_keys)
        self.hidden_reward = np.zeros(n_keys)
        """The true reward of each seen key: metrics only, never the learners."""

    def add(
        self, state: int, action: int, next_state: int, observed: bool, reward: float, hidden: float
    ) -> int:
        """Record one step; return its key."""
        key = state * self.n_actions + action
        self.visited[key] = True
        self.next_state[key] = next_state
        self.hidden_reward[key] = hidden
        if observed:
            self.labelled[key] = True
            self.label_value[key] = reward
        return key


class StoreWrapper(gym.Wrapper):
    """Write every step into a :class:`KeyStore` and put its key in ``info["store_id"]``.

    Sits above :class:`~dospcot.envs.RewardMaskWrapper`, whose ``info`` says whether the reward was
    observed; the hidden reward it passes on is stored for the metrics only.
    """

    def __init__(self, env: gym.Env, store: KeyStore) -> None:
        super().__init__(env)
        self.store = store
        self._state = 0

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        self._state = int(self.env.unwrapped.s)
        return obs, info

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        next_state = int(self.env.unwrapped.s)
        info = dict(info)
        info["store_id"] = self.store.add(
            self._state,
            int(action),
            next_state,
            info["reward_observed"],
            float(reward),
            info["hidden_reward"],
        )
        self._state = next_state
        return obs, reward, terminated, truncated, info


MakeEnv = Callable[[], gym.Env]
"""Builds a fresh copy of a discrete task (a toy-text env with ``P`` and ``s``)."""


class GridTask:
    """The grid adapter of a run (:class:`~dospcot.cotraining_round.CoTrainingTask`).

    :param make_env: builds a fresh copy of the task (a toy-text env with ``P`` and ``s``).
    :param views: every view the task offers, by name.
    :param spec: the run.
    :param config: its hyperparameters.
    :param monitored_states: bool (S,), states whose every reward a monitor reveals
        (:class:`~dospcot.envs.RewardMaskWrapper`); None: none.
    """

    def __init__(
        self,
        make_env: MakeEnv,
        views: dict[str, View],
        spec: NeuralRunSpec,
        config: NeuralConfig,
        monitored_states: np.ndarray | None = None,
    ) -> None:
        missing = sorted(set(spec.views) - set(views))
        if missing:
            raise ValueError(f"unknown view(s) {missing}; this task has {sorted(views)}")
        self.make_env, self.views, self.spec, self.config = make_env, views, spec, config
        self.monitored_states = monitored_states
        self.mdp = TabularMDP.from_env(
            make_env(), {name: views[name] for name in spec.views}, config.max_episode_steps
        )
        self.store = KeyStore(self.mdp.n_states, self.mdp.n_actions)
        self.classes = RewardClasses(1, config.cotraining.max_classes)
        self.policy_metrics = metrics.GreedyPolicyMetrics(self.mdp, discount=1.0)
        wanted = config.demonstrations
        self.demos = (
            expert_demonstrations(self.mdp, wanted.episodes, spec.seed, with_rewards=wanted.labels)
            if wanted.episodes
            else None
        )
        """The run's expert episodes (:func:`~dospcot.demonstrations.expert_demonstrations`), or None."""
        self.revealed_keys: np.ndarray | None = None
        """bool (S, A): the keys whose rewards the demonstrations reveal (labelled ones only), or None."""
        if self.demos is not None and self.demos.rewards is not None:
            self.revealed_keys = np.zeros((self.mdp.n_states, self.mdp.n_actions), dtype=bool)
            self.revealed_keys[self.demos.states, self.demos.actions] = True
            # Labelled samples of the pool from the start, as if the agents had stepped there.
            nxt = self.mdp.next_state[self.demos.states, self.demos.actions]
            for s, a, s2, r in zip(
                self.demos.states, self.demos.actions, nxt, self.demos.rewards, strict=True
            ):
                self.store.add(int(s), int(a), int(s2), True, float(r), float(r))

    def agent_env(self, k: int, view: str) -> gym.Env:
        fraction = 1.0 if self.spec.method == "oracle" else self.config.label_fraction
        env = gym.wrappers.TimeLimit(
            self.make_env(), self.config.train_episode_steps or self.config.max_episode_steps
        )
        env = RewardMaskWrapper(
            env,
            fraction,
            mode="state-action",
            mask_seed=self.spec.seed,
            monitored_states=self.monitored_states,
            revealed_keys=self.revealed_keys,
        )
        return ViewObservationWrapper(StoreWrapper(env, self.store), self.views[view])

    def observations(self, view: str) -> np.ndarray:
        return self.mdp.views[view]

    def feature_dims(self) -> list[int]:
        return [2 * self.mdp.views[v].shape[1] + self.mdp.n_actions for v in self.spec.views]

    def pool(self) -> Pool:
        store = self.store
        labelled = (store.visited & store.labelled)[None]
        unlabelled = (store.visited & ~store.labelled)[None]
        self.classes.observe(0, np.unique(store.label_value[labelled[0]]))
        label_class = np.where(labelled, self.classes.encode(store.label_value[None]), -1)
        features = [
            key_features(self.mdp.views[v], store.next_state[None], store.visited[None], self.mdp.n_actions)
            for v in self.spec.views
        ]
        return Pool(features, labelled, label_class, unlabelled, self.classes.mask)

    def true_class(self) -> np.ndarray:
        return self.classes.encode(self.store.hidden_reward[None])[0]

    def greedy_actions(self, agents: Sequence[ExpectedSarsaDQN]) -> np.ndarray:
        """(m, S) each agent's greedy action in every state, read through its own view."""
        return np.stack(
            [
                agent.predict(self.mdp.views[v], deterministic=True)[0]
                for agent, v in zip(agents, self.spec.views, strict=True)
            ]
        )

    def evaluate(self, agents: Sequence[ExpectedSarsaDQN]) -> dict[str, np.ndarray]:
        """Each agent's greedy policy against the exact optimum: (m,) arrays ``greedy_return``,
        ``success``, ``normalised_score`` and ``agreement``."""
        return self.policy_metrics(self.greedy_actions(agents))

    def reference_returns(self) -> dict[str, float]:
        return {
            "optimal_return": self.policy_metrics.optimal_return,
            "random_return": self.policy_metrics.random_return,
        }

    def demonstrations(self, view: str) -> tuple[np.ndarray, np.ndarray] | None:
        return None if self.demos is None else (self.demos.observations[view], self.demos.actions)


class NeuralCoTraining(CoTrainingRun):
    """One run on a deterministic discrete task: :class:`CoTrainingRun` with the :class:`GridTask`
    adapter, whose parameters it takes."""

    def __init__(
        self,
        make_env: MakeEnv,
        views: dict[str, View],
        spec: NeuralRunSpec,
        config: NeuralConfig,
        monitored_states: np.ndarray | None = None,
    ) -> None:
        task = GridTask(make_env, views, spec, config, monitored_states)
        super().__init__(task, spec, config, config.cotraining.max_classes)

    @property
    def mdp(self) -> TabularMDP:
        """The task's exact MDP (metrics only)."""
        return self.task.mdp

    def greedy_actions(self) -> np.ndarray:
        """(m, S) each agent's greedy action in every state, read through its own view."""
        return self.task.greedy_actions(self.agents)


__all__ = ["GridTask", "KeyStore", "NeuralCoTraining", "NeuralConfig", "NeuralRunSpec", "StoreWrapper"]
