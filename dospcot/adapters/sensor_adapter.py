"""The sensor adapter: DOSPCoT on a sensor task (highway driving, or any gymnasium env with discrete
actions: docs/your_env.md), m sensor views.

The round itself is :class:`~dospcot.core.sb3_round.CoTrainingRun`'s; this adapter supplies what
a continuous task does differently (docs/design.md section 3):

- **the store**: a state is a sensor reading that never repeats exactly, so every stored step is one
  pool sample, with every view of s and s' (:class:`StepStore`; each reading stored once); an env
  that names its states (a state key, ``gym.state_key``) pools (key, action) pairs instead
  (:class:`KeyedStepStore`);
- **the pool**: every sample, its classifier input under view j being (view j of s, one-hot action,
  view j of s'); the reward is binned into K classes of the labels
  (:class:`~dospcot.core.reward_classes.QuantileRewardClasses`), and an admitted sample's reward is the
  mean of its consensus class;
- **the evaluator**: greedy evaluation episodes (below).

Policies are measured by greedy evaluation episodes on unmasked copies of the task: the mean true
return, the share of successful episodes (on a highway those that last their whole duration, no
crash; elsewhere those whose return exceeds ``success_return``) and the normalised score
``(R - R_random) / (R_max - R_random)``, where ``R_random`` is a uniformly random policy's return on
the same evaluation seeds and ``R_max`` the number of evaluation steps on a highway (every reward of
highway-env's normalised reward is at most 1) or ``max_return`` (NaN where it is not known). There is
no exact optimum, so no optimal-action agreement (NaN).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from dospcot.adapters.sensor_store import KeyedStepStore, SensorStoreWrapper, StepStore
from dospcot.config.errors import ConfigError
from dospcot.config.task_sections import DemonstrationsConfig, GymConfig, HighwayConfig
from dospcot.core.queries import StoreQueries
from dospcot.core.reward_classes import QuantileRewardClasses, episode_end_class_mask
from dospcot.core.self_paced import RunPool
from dospcot.demonstrations import Demonstrations, load_agent, record_demonstrations
from dospcot.envs.finite_check import FiniteCheckWrapper
from dospcot.policies import ExpectedSarsaDQN
from dospcot.seeding import EVAL_SEED, agent_seed, demonstration_seed

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig

SensorSection = HighwayConfig | GymConfig
"""The section that sets up a sensor task: each has the fields and properties :class:`SensorAdapter` reads
(``episode_steps``, ``reward_classes``, ``eval_episodes``, ``success_return``, ``max_return``,
``keyed``, ``read_termination``, ``episode_end_classes``)."""


class _RandomPolicy:
    """A uniformly random policy with SB3's ``predict`` signature (the normalised score's floor)."""

    def __init__(self, action_space: gym.spaces.Discrete, seed: int) -> None:
        self.n, self.rng = int(action_space.n), np.random.default_rng(seed)

    def predict(
        self, obs: np.ndarray, state: Any = None, episode_start: Any = None, deterministic: bool = False
    ):
        return self.rng.integers(self.n, size=len(obs)), None


class SensorAdapter(StoreQueries):
    """The sensor adapter of a run (:class:`~dospcot.core.task_adapter.TaskAdapter`).

    :param cfg: the run's config: its views, method, seed, label fraction and demonstrations.
    :param section: the task's section (:data:`SensorSection`); its ``episode_steps`` bound evaluation
        episodes and are ``R_max`` of the normalised score where ``max_return`` is None.
    :param make_env: ``make_env(view, views, label_fraction, mask_seed)`` builds a masked sensor env
        observing ``view`` and recording ``views`` (:func:`dospcot.envs.masked_highway.make_masked_highway`).
    :param make_eval_env: builds the evaluation envs, with ``make_env``'s arguments; None:
        ``make_env`` (they differ where training episodes have their own wrappers, e.g. exploring
        starts).
    """

    def __init__(
        self,
        cfg: TrainConfig,
        section: SensorSection,
        make_env: Callable[..., gym.Env],
        make_eval_env: Callable[..., gym.Env] | None = None,
    ) -> None:
        self.cfg, self.section = cfg, section
        fraction = cfg.mask_fraction
        # A keyed pool holds each pair once: its agents must agree on whether it is labelled.
        seeds = [cfg.seed if section.keyed else agent_seed(cfg.seed, k) for k in range(len(cfg.views))]
        envs = [make_env(v, cfg.views, fraction, seed) for v, seed in zip(cfg.views, seeds, strict=True)]
        spaces = {v: envs[0].get_wrapper_attr("view_space")(v) for v in cfg.views}
        self.shapes = {v: space.shape for v, space in spaces.items()}
        dtypes = {v: space.dtype for v, space in spaces.items()}
        self.store = (KeyedStepStore if section.keyed else StepStore)(self.shapes, dtypes)
        self._pairs: dict[int, tuple[str, int]] = {}
        """Sample id -> (its state key as shown to a person, its action), for :meth:`describe`."""
        self.demos = self._read_demonstrations(cfg.demonstrations, make_env)
        draw = cfg.training.rater == "file"
        self._envs = [SensorStoreWrapper(env, self.store, draw) for env in envs]
        self.n_actions = int(envs[0].action_space.n)
        self.n_classes = section.reward_classes
        self.classes = QuantileRewardClasses(section.reward_classes)
        build_eval = make_eval_env or make_env
        self.eval_envs = [_eval_env(build_eval, v, section.episode_steps) for v in cfg.views]
        returns = self._returns(_RandomPolicy(envs[0].action_space, cfg.seed), self.eval_envs[0])[0]
        self.random_return = float(np.mean(returns))

    # What the reward queries read of the pool (dospcot.core.queries.QueriedTask): never a hidden reward.
    def met(self) -> np.ndarray:
        """(N,) bool, the samples the agents have met."""
        return np.ones(len(self.store), dtype=bool)

    def labelled(self) -> np.ndarray:
        """(N,) bool, the samples whose reward is known (revealed, monitored or demonstrated)."""
        return self.store.labelled[: len(self.store)].copy()

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) bool each: the samples that ended their episode, and those the time limit cut."""
        n = len(self.store)
        return self.store.terminal[:n].copy(), self.store.truncated[:n].copy()

    def end_states(self, ids: np.ndarray) -> np.ndarray:
        """(len(ids), d) float, every view of the state each sample's step led to (s'), flattened.

        Features, not keys, even on a keyed pool: the store names a pair by the key of its s alone, and
        where the views are functions of the state (MiniGrid's), equal states give equal features."""
        store = self.store
        rows = store.next_row[ids]
        return np.concatenate([store.rows[v][rows].astype(np.float64) for v in sorted(store.rows)], axis=1)

    def describe(self, sample: int) -> dict[str, Any]:
        """What a person is shown of sample ``sample``: its (state key, action) pair, or its step, and
        where the env draws itself, PNG frames of s (``frame``) and s' (``next_frame``)."""
        store = self.store
        ids = getattr(store, "ids", {})
        if len(self._pairs) != len(ids):  # pairs only ever join the store: rebuilt once per round's queries
            self._pairs = {n: (_state_text(key), action) for (key, action), n in ids.items()}
        where, action = self._pairs.get(sample, (f"step {sample}", int(store.action[sample])))
        described: dict[str, Any] = {"key": f"{where}, action {action}"}
        for column, row in (("frame", store.state_row[sample]), ("next_frame", store.next_row[sample])):
            if int(row) in store.frames:
                described[column] = store.frames[int(row)]
        return described

    def agent_env(self, k: int, view: str) -> gym.Env:
        return self._envs[k]

    def observations(self, view: str) -> None:
        return None  # a sensor reading never repeats exactly: no table of states

    def feature_dims(self) -> list[int]:
        extra = int(self.section.read_termination)
        return [2 * int(np.prod(self.shapes[v])) + self.n_actions + extra for v in self.cfg.views]

    def pool(self, dtype: type = np.float32) -> RunPool:
        store = self.store
        n = len(store)
        labelled, unlabelled = store.labelled[:n], ~store.labelled[:n]
        going_on = ~store.terminal[:n][labelled] if self.section.step_class else None
        self.classes.fit(store.label_value[:n][labelled], going_on)
        label_class = np.where(labelled, self.classes.encode(store.label_value[:n]), -1)
        termination = self.section.read_termination
        features = [store.features(v, self.n_actions, termination, dtype) for v in self.cfg.views]
        class_mask = self.classes.mask
        if self.section.episode_end_classes:
            class_mask = episode_end_class_mask(label_class, labelled, store.terminal[:n], class_mask)
        return RunPool(features, labelled, label_class, unlabelled, class_mask)

    def true_class(self) -> np.ndarray:
        hidden = self.store.hidden_reward[: len(self.store)]  # metrics only
        return self.classes.encode_hidden(hidden)

    def _returns(self, policy: Any, env: DummyVecEnv) -> tuple[np.ndarray, np.ndarray]:
        env.seed(EVAL_SEED)
        returns, lengths = evaluate_policy(
            policy,
            env,
            n_eval_episodes=self.section.eval_episodes,
            deterministic=True,
            return_episode_rewards=True,
        )
        return np.asarray(returns, dtype=np.float64), np.asarray(lengths)

    def evaluate(self, agents: Sequence[ExpectedSarsaDQN]) -> dict[str, np.ndarray]:
        """Greedy evaluation episodes of every agent: (m,) ``greedy_return`` (mean true return),
        ``success`` (share of successful episodes: those whose return exceeds ``success_return``, or
        where it is None those that last ``episode_steps``), ``normalised_score``;
        ``agreement`` is NaN."""
        r_max = self.reference_returns()["max_return"]
        threshold = self.section.success_return
        out: dict[str, list[float]] = {
            "greedy_return": [],
            "success": [],
            "normalised_score": [],
            "agreement": [],
        }
        for agent, env in zip(agents, self.eval_envs, strict=True):
            returns, lengths = self._returns(agent, env)
            out["greedy_return"].append(float(returns.mean()))
            won = lengths >= self.section.episode_steps if threshold is None else returns > threshold
            out["success"].append(float(won.mean()))
            out["normalised_score"].append(
                (returns.mean() - self.random_return) / (r_max - self.random_return)
                if np.isfinite(r_max) and r_max > self.random_return
                else float("nan")
            )
            out["agreement"].append(float("nan"))
        return {key: np.asarray(values) for key, values in out.items()}

    def reference_returns(self) -> dict[str, float]:
        r_max = self.section.max_return
        return {
            "max_return": float(self.section.episode_steps if r_max is None else r_max),
            "random_return": self.random_return,
        }

    def _read_demonstrations(
        self, wanted: DemonstrationsConfig, make_env: Callable[..., gym.Env]
    ) -> Demonstrations | None:
        """The run's demonstrations: recorded from a saved agent, or a file's (its first
        ``wanted.episodes``, or all), each of the run's views checked against the env's; with labels,
        each step a labelled sample of the store."""
        if wanted.agent:
            demos = self._record(wanted, make_env)
        elif wanted.file:
            demos = Demonstrations.load(wanted.file)
            if wanted.episodes:
                demos = demos.first_episodes(wanted.episodes)
        else:
            return None
        for view, shape in self.shapes.items():
            if view not in demos.observations:
                raise ValueError(
                    f"demonstrations.file holds no view {view!r} (it has {', '.join(demos.views)})"
                )
            width = int(np.prod(shape))
            if demos.observations[view].shape[1] != width:
                raise ValueError(
                    f"demonstrations.file: view {view!r} has {demos.observations[view].shape[1]} values per "
                    f"step, the env's {width}"
                )
        if not wanted.labels or demos.rewards is None:
            return demos.without_rewards()
        if self.section.keyed:
            raise ConfigError(
                "demonstrations.labels: a file's steps name no state key, so they cannot join a keyed "
                "pool; set demonstrations.labels = false to use them in the margin loss only"
            )
        for i in range(len(demos)):
            state_row = self.store.add_row({v: demos.observations[v][i] for v in self.shapes})
            next_row = self.store.add_row({v: demos.next_observations[v][i] for v in self.shapes})
            reward = float(demos.rewards[i])
            self.store.add(state_row, int(demos.actions[i]), next_row, True, reward, reward)
        return demos

    def _record(self, wanted: DemonstrationsConfig, make_env: Callable[..., gym.Env]) -> Demonstrations:
        """``wanted.episodes`` greedy episodes of the saved agent on an unmasked copy of the task."""
        agent = load_agent(wanted.agent, wanted.agent_algorithm)
        view = wanted.agent_view or self.cfg.views[0]
        env = make_env(view, tuple(dict.fromkeys([*self.cfg.views, view])), 1.0, self.cfg.seed)
        if agent.observation_space.shape != env.observation_space.shape:
            raise ValueError(
                f"demonstrations.agent observes shape {agent.observation_space.shape}, but view {view!r} "
                f"gives {env.observation_space.shape}; set demonstrations.agent_view to the view it was "
                "trained on"
            )
        env = gym.wrappers.TimeLimit(env, self.section.episode_steps)
        return record_demonstrations(agent, env, wanted.episodes, demonstration_seed(self.cfg.seed))

    def demonstrations(self, view: str) -> tuple[np.ndarray, np.ndarray] | None:
        if self.demos is None:
            return None
        return self.demos.observations[view].reshape(-1, *self.shapes[view]), self.demos.actions


def _eval_env(make_env: Callable[..., gym.Env], view: str, max_steps: int) -> DummyVecEnv:
    """An unmasked copy of the task observing ``view`` (its hidden reward is the reward), checked as the
    agents' envs are."""

    def build() -> gym.Env:
        env = make_env(view, (view,), 1.0, 0)
        checked = FiniteCheckWrapper(env, f"{type(env.unwrapped).__name__} (evaluation, view {view})")
        return Monitor(gym.wrappers.TimeLimit(checked, max_steps))

    return DummyVecEnv([build])


def _state_text(key: Any, longest: int = 48) -> str:
    """A state key as a person reads it in a query: as it is where short, else (e.g. a MiniGrid key,
    which holds the map's encoding as bytes) a 12-digit digest that names the same state the same way
    in every query; the query's frames show the state itself."""
    text = str(key)
    if len(text) > longest:
        return f"state #{hashlib.sha256(text.encode()).hexdigest()[:12]}"
    return f"state {text}"


__all__ = ["SensorAdapter", "SensorSection"]
