"""The grid adapter: what one co-training run on the masked grid world (``task = "grid"``,
:mod:`dospcot.tasks.grid`) needs, for any deterministic discrete task (a toy-text env with ``P`` and ``s``).

The round itself is :class:`~dospcot.core.sb3_round.CoTrainingRun`'s; this adapter supplies what
a discrete task does differently (docs/design.md section 3):

- **the store** pools (s, a) keys: a key's id is ``s * A + a``, so the reward table is indexed by
  key, and a step of a key admitted in an earlier round reads its pseudo-reward at once;
- **the pool**: every seen key, its classifier input under view j being (view j of s, one-hot a,
  view j of the stored s') (:func:`~dospcot.core.key_pool.key_features`); classes are the distinct
  labelled reward values;
- **the evaluator**: value iteration gives the exact optimum, and each agent's greedy action in every
  state (read through its own view) is measured against it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from dospcot import metrics
from dospcot.core.key_pool import key_features
from dospcot.core.queries import StoreQueries
from dospcot.core.reward_classes import RunRewardClasses, episode_end_class_mask
from dospcot.core.self_paced import RunPool
from dospcot.demonstrations import expert_demonstrations
from dospcot.envs.masking import RewardMaskWrapper
from dospcot.envs.tabular import TabularMDP
from dospcot.envs.views import View, ViewObservationWrapper
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.in_place_state import InPlaceState

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig


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
        """The true reward of each seen key: metrics only, never the learners (and the simulated rater)."""
        self.terminated = np.zeros(n_keys, dtype=bool)
        """Whether a step of the key ended its episode (an agent sees that without a reward)."""
        self.truncated = np.zeros(n_keys, dtype=bool)
        """Whether the time limit cut an episode at a step of the key."""

    def add(
        self,
        state: int,
        action: int,
        next_state: int,
        observed: bool,
        reward: float,
        hidden: float,
        ends: tuple[bool, bool] = (False, False),
    ) -> int:
        """Record one step (``ends``: whether it ended its episode, whether the time limit cut it);
        return its key."""
        key = state * self.n_actions + action
        self.visited[key] = True
        self.next_state[key] = next_state
        self.hidden_reward[key] = hidden
        self.terminated[key] |= ends[0]
        self.truncated[key] |= ends[1]
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
            (bool(terminated), bool(truncated)),
        )
        self._state = next_state
        return obs, reward, terminated, truncated, info


MakeEnv = Callable[[], gym.Env]
"""Builds a fresh copy of a discrete task (a toy-text env with ``P`` and ``s``)."""


class GridAdapter(StoreQueries):
    """The grid adapter of a run (:class:`~dospcot.core.task_adapter.TaskAdapter`).

    :param cfg: the run's config: its views, method, seed, label fraction, episode lengths
        (``env.episode_steps``, ``env.train_episode_steps``), reward classes and demonstrations.
    :param make_env: builds a fresh copy of the task (a toy-text env with ``P`` and ``s``).
    :param views: every view the task offers, by name.
    :param monitored_states: bool (S,), states whose every reward a monitor reveals
        (:class:`~dospcot.envs.RewardMaskWrapper`); None: none.
    """

    def __init__(
        self,
        cfg: TrainConfig,
        make_env: MakeEnv,
        views: dict[str, View],
        monitored_states: np.ndarray | None = None,
    ) -> None:
        missing = sorted(set(cfg.views) - set(views))
        if missing:
            raise ValueError(f"unknown view(s) {missing}; this task has {sorted(views)}")
        self.cfg, self.make_env, self.views = cfg, make_env, views
        self.monitored_states = monitored_states
        self.mdp = TabularMDP.from_env(
            make_env(), {name: views[name] for name in cfg.views}, cfg.env.episode_steps
        )
        self.store = KeyStore(self.mdp.n_states, self.mdp.n_actions)
        self._frame_env: gym.Env | None = None
        self.n_classes = cfg.cotraining.max_classes
        self.classes = RunRewardClasses(self.n_classes)
        self.policy_metrics = metrics.GreedyPolicyMetrics(self.mdp, discount=1.0)
        wanted = cfg.demonstrations
        self.demos = (
            expert_demonstrations(self.mdp, wanted.episodes, cfg.seed, with_rewards=wanted.labels)
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
            ends = self.mdp.terminal[self.demos.states, self.demos.actions]
            for s, a, s2, r, end in zip(
                self.demos.states, self.demos.actions, nxt, self.demos.rewards, ends, strict=True
            ):
                # Whether a demonstrated step ended its episode is the task's, as on an agent's step.
                self.store.add(int(s), int(a), int(s2), True, float(r), float(r), (bool(end), False))

    # What the reward queries read of the pool (dospcot.core.queries.QueriedTask): never a hidden reward.
    def met(self) -> np.ndarray:
        """(N,) bool, the samples the agents have met."""
        return self.store.visited.copy()

    def labelled(self) -> np.ndarray:
        """(N,) bool, the samples whose reward is known (revealed, monitored or demonstrated)."""
        return self.store.labelled.copy()

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) bool each: the samples that ended their episode, and those the time limit cut."""
        return self.store.terminated.copy(), self.store.truncated.copy()

    def end_states(self, ids: np.ndarray) -> np.ndarray:
        """(len(ids),) int, the state each key's step led to: its key (the task is deterministic)."""
        return self.store.next_state[ids].copy()

    def describe(self, sample: int) -> dict[str, Any]:
        """What a person is shown of sample ``sample``: its key and, where the env draws itself as text,
        a frame of the state (the agent as ``A``)."""
        state, action = divmod(sample, self.mdp.n_actions)
        described = {"key": f"state {state}, action {action}"}
        if self._frame_env is None:  # one copy of the task draws every query's frame
            self._frame_env = self.make_env()
        env = self._frame_env
        if "ansi" in env.metadata.get("render_modes", ()):
            env.unwrapped.render_mode, env.unwrapped.s = "ansi", state
            described["frame"] = env.render()
        return described

    def agent_env(self, k: int, view: str) -> gym.Env:
        cfg = self.cfg
        fraction = cfg.mask_fraction
        env = gym.wrappers.TimeLimit(self.make_env(), cfg.env.train_episode_steps or cfg.env.episode_steps)
        env = RewardMaskWrapper(
            env,
            fraction,
            mode="state-action",
            mask_seed=cfg.seed,
            monitored_states=self.monitored_states,
            revealed_keys=self.revealed_keys,
            queried=cfg.training.queries,
        )
        return ViewObservationWrapper(StoreWrapper(env, self.store), self.views[view])

    def observations(self, view: str) -> np.ndarray:
        return self.mdp.views[view]

    def feature_dims(self) -> list[int]:
        return [2 * self.mdp.views[v].shape[1] + self.mdp.n_actions for v in self.cfg.views]

    def pool(self, dtype: type = np.float32) -> RunPool:
        store = self.store
        labelled = store.visited & store.labelled
        unlabelled = store.visited & ~store.labelled
        self.classes.observe(np.unique(store.label_value[labelled]))
        label_class = np.where(labelled, self.classes.encode(store.label_value), -1)
        features = [
            key_features(self.mdp.views[v], store.next_state, store.visited, self.mdp.n_actions).astype(
                dtype, copy=False
            )
            for v in self.cfg.views
        ]
        class_mask = self.classes.mask
        if self.cfg.env.episode_end_classes:
            class_mask = episode_end_class_mask(label_class, labelled, store.terminated, class_mask)
        return RunPool(features, labelled, label_class, unlabelled, class_mask)

    def true_class(self) -> np.ndarray:
        return self.classes.encode(self.store.hidden_reward)

    def greedy_actions(self, agents: Sequence[ExpectedSarsaDQN]) -> np.ndarray:
        """(m, S) each agent's greedy action in every state, read through its own view."""
        return np.stack(
            [
                agent.predict(self.mdp.views[v], deterministic=True)[0]
                for agent, v in zip(agents, self.cfg.views, strict=True)
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


__all__ = ["GridAdapter", "KeyStore", "StoreWrapper"]
