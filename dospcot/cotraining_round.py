"""One round of DOSPCoT with SB3 agents, for any task: the round is here once, a task adapter supplies
the rest (docs/design.md section 2).

A run has one agent per view; each reads its own view as its observation and keeps its own
relabelling replay buffer, and all of them write every step into the task's store. One round, top
to bottom, in :meth:`CoTrainingRun.run_round`:

1. **Collect**: every agent ``learn()``s for ``steps_per_round`` env steps. Its gradient steps sample
   rewards and self-paced weights from the shared :class:`~dospcot.policies.RewardTable` at sample
   time, so what earlier rounds admitted drives this round's updates.
2. **Co-train** (method ``"cotrain"``): the task turns its store into a :class:`Pool` (labelled
   samples and the unlabelled pool U, each view's classifier inputs), which goes to the
   :class:`~dospcot.cotraining.SelfPacedCoTrainer` (select, fit, score per view; Eq. 9).
3. **Pseudo-reward**: each admitted sample's consensus reward and weight go into the reward table,
   whose ids are the pool's samples, so every stored step of a sample reads them.
   Under segment labels (``segment_length`` k > 1, :mod:`dospcot.segments`) the pool's samples are
   k-step segments labelled with their summed reward, and each view's per-step reward model turns
   the labelled and admitted sums back into per-step rewards for the table.
4. **Policy update**: every agent takes ``update_steps`` gradient steps on its replay buffer, which
   now reads this round's pseudo-rewards, so they shape the policy evaluated at the end of the round.
5. **Age**: the pace (admitted share of U) sets every agent's exploration rate via ``set_pace``.
   Baselines, which have no pace, follow the share of rounds done, a plain linear schedule.
6. **Record**: the task measures every agent's greedy policy.

What a task supplies (:class:`CoTrainingTask`): each agent's env (masked, writing the store), its
reward classes, the pool, each sample's true class (metrics only) and the evaluator. The
grid adapter (:mod:`dospcot.neural_cotraining`) pools (s, a) keys and measures against the exact
optimum; the sensor adapter (:mod:`dospcot.transition_cotraining`) pools every step and runs
evaluation episodes.

Agents (``spec.agents``): ExpectedSarsaDQN with its Expected-SARSA target (``esarsa_dqn``) or DQN's max
target (``dqn``), or a Q-table over the view's observations (``tabular``,
:class:`~dospcot.policies.TabularExpectedSarsa`); any mix works, since all three are SB3 ``DQN`` models.

Baselines: ``oracle`` (every reward revealed), ``masked-zero`` (masked rewards read as 0 with weight
1) and ``labels-only`` (masked steps weigh 0). The hidden reward reaches only the metrics.
"""

from __future__ import annotations

import io
import random
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import MaybeCallback

from dospcot.cotraining import CoTrainingConfig, Pool, SelfPacedCoTrainer
from dospcot.demonstrations import DemonstrationsConfig
from dospcot.envs.finite_check import FiniteCheckWrapper
from dospcot.policies import ExpectedSarsaDQN, RewardTable, TabularExpectedSarsa
from dospcot.reward_classes import QuantileRewardClasses, RewardClasses
from dospcot.round_records import VIEW_STATS, record_head, round_stats
from dospcot.run_spec import RunSpec
from dospcot.seeding import agent_seed, classifier_seed, round_reset_seed
from dospcot.segments import SegmentLabelWrapper, SegmentStore, segment_pool, step_rewards

AGENT_TARGETS = {"esarsa_dqn": "expected_sarsa", "dqn": "q", "tabular": "expected_sarsa"}
"""Agent kinds and their TD target: ExpectedSarsaDQN with its Expected-SARSA target or DQN's max target,
and the tabular Expected-SARSA agent."""


class NeuralRunSpec(RunSpec):
    """A run of SB3 agents; agent kinds from :data:`AGENT_TARGETS`."""

    def check_agent(self, kind: str) -> None:
        if kind not in AGENT_TARGETS:
            raise ValueError(f"unknown agent kind {kind!r}; allowed: {sorted(AGENT_TARGETS)}")


@dataclass(frozen=True)
class TrainingConfig:
    """The rounds of one run: the ``[training]`` section of a config, and the first fields of
    :class:`NeuralConfig`.

    :param rounds: co-training rounds.
    :param steps_per_round: env steps each agent takes per round.
    :param label_fraction: share of (s, a) keys whose reward is revealed, in (0, 1].
    :param eps_start: exploration at pace 0.
    :param eps_end: exploration at pace 1.
    :param exploration: what sets the pace that moves exploration from ``eps_start`` to ``eps_end``
        after each round. ``"pace"``: a co-trained run's admitted share of U (a fast self-paced
        schedule ends exploration after a round or two), baselines the share of rounds done.
        ``"rounds"``: the share of rounds done for every method, so co-trained agents and baselines
        explore alike.
    :param update_steps: gradient steps each agent takes at the end of every round, after the
        co-trainer wrote that round's pseudo-rewards and before the agents are evaluated (the policy
        update), so the last round's pseudo-rewards are learned too; 0: none.
    :param learn_from_round: the first round (1-based) in which agents learn while they collect:
        before it they act uniformly at random and take no gradient step during collection (SB3's
        ``learning_starts``, raised to ``(learn_from_round - 1) * steps_per_round``), so a
        co-trained agent's first values come from pseudo-rewards, not from the labels alone. The
        policy update (``update_steps``) still runs at the end of every round. In [1, ``rounds``].
    :param segment_length: k; 1: the labels are single rewards (``label_fraction`` of the (s, a)
        keys or steps). Above 1, co-training only: the labels are the summed rewards of k-step
        segments of the agents' episodes, a share ``label_fraction`` of the segments, so the same
        rater effort in labelled steps (:mod:`dospcot.segments`).
    """

    rounds: int = 5
    steps_per_round: int = 5_000
    label_fraction: float = 0.05
    eps_start: float = 1.0
    eps_end: float = 0.05
    exploration: str = "pace"
    update_steps: int = 0
    learn_from_round: int = 1
    segment_length: int = 1

    def __post_init__(self) -> None:
        if self.segment_length < 1:
            raise ValueError(f"segment_length must be >= 1, got {self.segment_length}")
        if self.rounds < 1 or self.steps_per_round < 1:
            raise ValueError(
                f"rounds and steps_per_round must be >= 1, got {self.rounds}, {self.steps_per_round}"
            )
        if self.update_steps < 0:
            raise ValueError(f"update_steps must be >= 0, got {self.update_steps}")
        if self.exploration not in ("pace", "rounds"):
            raise ValueError(f"exploration must be 'pace' or 'rounds', got {self.exploration!r}")
        if not 1 <= self.learn_from_round <= self.rounds:
            raise ValueError(
                f"learn_from_round must lie in [1, rounds = {self.rounds}], got {self.learn_from_round}"
            )
        if not 0 < self.label_fraction <= 1:
            raise ValueError(f"label_fraction must lie in (0, 1], got {self.label_fraction}")
        for name in ("eps_start", "eps_end"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")

    @property
    def collect_only_steps(self) -> int:
        """Env steps per agent before ``learn_from_round``: the agents learn nothing while they take
        them (every agent's ``learning_starts`` is at least this)."""
        return (self.learn_from_round - 1) * self.steps_per_round


@dataclass(frozen=True)
class NeuralConfig(TrainingConfig):
    """Hyperparameters of a run: :class:`TrainingConfig`'s, and

    :param max_episode_steps: the episode length limit of the evaluation (greedy rollouts).
    :param train_episode_steps: the episode length limit while training (0: ``max_episode_steps``).
        Short training episodes with exploring starts scatter the agents over the map.
    :param dqn: further keyword arguments of every neural agent (SB3 DQN's).
    :param tabular: further keyword arguments of every ``tabular`` agent
        (:class:`~dospcot.policies.TabularExpectedSarsa`'s).
    :param cotraining: the self-paced schedule (its gamma is replaced by the run's).
    :param demonstrations: expert episodes and their roles (a task without them ignores it).
    """

    max_episode_steps: int = 64
    train_episode_steps: int = 0
    dqn: dict[str, Any] = field(default_factory=dict)
    tabular: dict[str, Any] = field(default_factory=dict)
    cotraining: CoTrainingConfig = field(default_factory=CoTrainingConfig)
    demonstrations: DemonstrationsConfig = field(default_factory=DemonstrationsConfig)


class CoTrainingTask(Protocol):
    """What a task adapter supplies to :class:`CoTrainingRun`."""

    store: Any
    """Every step the agents took, in the form the pool is built from; its ``state_dict()`` and
    ``load_state_dict(state)`` checkpoint it in place."""
    classes: RewardClasses | QuantileRewardClasses
    """The reward classes of the run's labels (one run)."""

    def agent_env(self, k: int, view: str) -> gym.Env:
        """Agent ``k``'s env: masked, observing ``view``, writing every step into the store with its
        pool sample in ``info["store_id"]``."""

    def observations(self, view: str) -> np.ndarray | None:
        """(S, d) the view of every state, for a ``tabular`` agent; None where states are not known."""

    def feature_dims(self) -> list[int]:
        """Each view's classifier input width."""

    def pool(self) -> Pool:
        """This round's pool (one run), after the classes have seen every label so far."""

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


def relabelling_kwargs(method: str, table: RewardTable) -> dict[str, Any]:
    """The relabelling replay buffer's arguments for a method: co-training reads the reward table,
    masked-zero counts masked rewards as 0, the rest weigh masked steps 0."""
    return {
        "reward_table": table if method == "cotrain" else None,
        "masked_reward": "zero" if method == "masked-zero" else "ignore",
    }


def make_agent(
    env: gym.Env,
    k: int,
    kind: str,
    view: str,
    spec: RunSpec,
    config: NeuralConfig,
    buffer_kwargs: dict[str, Any],
    observations: np.ndarray | None = None,
) -> ExpectedSarsaDQN:
    """Agent ``k`` of a run, at pace 0, on ``env`` checked for non-finite values.

    :param observations: (S, d) the view of every state, which a ``tabular`` agent's table is built
        over; None for a task whose observations are not known in advance.
    """
    env = FiniteCheckWrapper(env, f"{type(env.unwrapped).__name__} (agent {k}, view {view})")
    common = dict(
        target=AGENT_TARGETS[kind], seed=agent_seed(spec.seed, k), exploration_initial_eps=config.eps_start,
        exploration_final_eps=config.eps_end, replay_buffer_kwargs=buffer_kwargs,
    )  # fmt: skip
    if kind == "tabular":
        if observations is None:
            raise ValueError(
                "agent kind 'tabular' needs a discrete task whose observations are known in advance "
                "(a grid world); use esarsa_dqn or dqn"
            )
        agent = TabularExpectedSarsa("MlpPolicy", env, observations, **common, **config.tabular)
    else:
        demos = config.demonstrations
        agent = ExpectedSarsaDQN(
            "MlpPolicy", env, **common, **config.dqn,
            demo_margin=demos.margin, demo_loss_weight=demos.margin_loss_weight,
        )  # fmt: skip
    agent.learning_starts = max(agent.learning_starts, config.collect_only_steps)
    agent.set_pace(0.0)
    return agent


class CoTrainingRun:
    """One run of SB3 agents on a masked task, round by round.

    :param task: the task adapter (store, pool, evaluator).
    :param spec: the run.
    :param config: its hyperparameters.
    :param n_classes: the most reward classes a run may hold (the classifiers' outputs).
    """

    def __init__(
        self, task: CoTrainingTask, spec: NeuralRunSpec, config: NeuralConfig, n_classes: int
    ) -> None:
        self.task, self.spec, self.config = task, spec, config
        self.table = RewardTable()
        self.segments: SegmentStore | None = None
        """The labelled and unlabelled segments under segment labels (``segment_length`` > 1), or None."""
        self.segment_classes = QuantileRewardClasses(n_classes)
        """The quantile classes of the segments' summed rewards (segment labels only)."""
        if config.segment_length > 1:
            if spec.method != "cotrain":
                raise ValueError(
                    f"segment_length {config.segment_length}: segment labels need co-training (method "
                    f"'cotrain'; one view is self-training), got method {spec.method!r}"
                )
            self.segments = SegmentStore(config.segment_length)
        buffer_kwargs = relabelling_kwargs(spec.method, self.table)
        self.agents: list[ExpectedSarsaDQN] = [
            make_agent(
                self._agent_env(k, view), k, kind, view, spec, config, buffer_kwargs, task.observations(view)
            )
            for k, (kind, view) in enumerate(zip(spec.agents, spec.views, strict=True))
        ]
        for k in range(len(self.agents)):
            self._give_demonstrations(k)
        self.trainer: SelfPacedCoTrainer | None = None
        if spec.method == "cotrain":
            cfg = replace(config.cotraining, gamma=spec.gamma, max_classes=n_classes)
            # A segment's input is the sum of its steps' (dospcot.segments.segment_pool).
            self.trainer = SelfPacedCoTrainer(task.feature_dims(), 1, cfg, [spec.seed])
        self.round = 0
        self.stopped = False
        """Whether the co-trainer's stopping rule (``tol``, ``stop_when_fully_admitted``) has fired."""

    def _agent_env(self, k: int, view: str) -> gym.Env:
        env = self.task.agent_env(k, view)
        return env if self.segments is None else SegmentLabelWrapper(env, self.segments)

    def _give_demonstrations(self, k: int) -> None:
        """Agent ``k``'s large-margin loss reads the task's demonstrations in its own view (a neural
        agent's, with the loss on; a saved agent holds none, so a loaded one gets them again)."""
        if self.spec.agents[k] == "tabular" or self.config.demonstrations.margin_loss_weight == 0:
            return
        demos = self.task.demonstrations(self.spec.views[k])
        if demos is not None:
            self.agents[k].set_demonstrations(*demos)

    @property
    def store(self) -> Any:
        """The task's store."""
        return self.task.store

    @property
    def classes(self) -> RewardClasses | QuantileRewardClasses:
        """The task's reward classes."""
        return self.task.classes

    def run(self) -> list[dict]:
        """All rounds, or until the stopping rule fires; returns one record per round and agent."""
        records: list[dict] = []
        while self.round < self.config.rounds and not self.stopped:
            records += self.run_round()
        return records

    def run_round(self, callback: MaybeCallback = None) -> list[dict]:
        """One round (docs/design.md section 2); returns its records.

        :param callback: passed to every agent's ``learn()`` (SB3 callbacks, e.g. a progress bar).
        """
        self.round += 1
        for k, agent in enumerate(self.agents):  # 1. collect and learn, with last round's rewards and weights
            # Every round starts from fresh episodes with seeded resets, so a run resumed from the
            # checkpoint of the last round continues exactly as the uninterrupted run would.
            env = agent.get_env()
            env.seed(round_reset_seed(self.spec.seed, k, self.round))
            agent.set_env(env, force_reset=True)  # learn() then resets it, with that seed
            agent.learn(self.config.steps_per_round, callback=callback, reset_num_timesteps=False)
        if self.trainer is not None:  # 2-3. co-train, pseudo-rewards
            stats = self.cotrain()
        else:  # a baseline has no co-trainer, but its labels are its effort too
            stats = {"labelled_steps": int(self.store.labelled.sum())}
        for agent in self.agents:  # 4. policy update on the rewards and weights just written
            agent.update(self.config.update_steps)
        pace = self.round / self.config.rounds  # 5. age
        if self.config.exploration == "pace":
            pace = stats.get("pace", pace)
        for agent in self.agents:
            agent.set_pace(min(pace, 1.0))
        return self._records(stats)  # 6. record

    def cotrain(self) -> dict:
        """Steps 2-3 of a round: co-train on the task's pool and write the pseudo-rewards and their
        weights into the reward table; returns the round's co-training figures."""
        pool = self.task.pool()
        if self.segments is not None:
            return self._cotrain_segments(pool)
        result = self.trainer.step(pool)
        pseudo = np.nan_to_num(self.classes.decode(result.pseudo_class)[0], nan=0.0)
        self.table.set(np.arange(pseudo.size), pseudo, result.pseudo_weight[0])
        self.stopped = bool(result.stopped[0])
        stats = round_stats(result, pool.unlabelled[0], self.task.true_class())  # metrics only
        return {**stats, "labelled_steps": int(pool.labelled[0].sum())}

    def _cotrain_segments(self, steps: Pool) -> dict:
        """Steps 2-3 under segment labels: co-train on segments, then turn the labelled and admitted
        segment sums into per-step rewards (:mod:`dospcot.segments`)."""
        segments, n = self.segments, len(self.segments)
        pool = segment_pool(steps, segments, self.segment_classes)
        result = self.trainer.step(pool)
        labelled = pool.labelled[0]
        pseudo = np.nan_to_num(self.segment_classes.decode(result.pseudo_class)[0], nan=0.0)
        sums = np.where(labelled, segments.label[:n], pseudo)
        weight = np.where(labelled, 1.0, result.pseudo_weight[0])
        model = self.config.cotraining.classifier
        reward, step_weight = step_rewards(steps, segments, sums, weight, model, self.step_model_seeds())
        self.table.set(np.arange(reward.size), reward, step_weight)
        self.stopped = bool(result.stopped[0])
        true_class = self.segment_classes.encode_hidden(segments.hidden[None, :n])[0]  # metrics only
        stats = round_stats(result, pool.unlabelled[0], true_class)
        # How far the decoded per-step rewards lie from the hidden ones, where the agents read them.
        decoded = step_weight > 0
        error = np.abs(reward - self.store.hidden_reward[: reward.size])[decoded]  # metrics only
        return {
            **stats,
            "labelled_steps": int((segments.ids[:n][labelled] >= 0).sum()),
            "step_reward_error": float(error.mean()) if decoded.any() else float("nan"),
        }

    def step_model_seeds(self) -> list[int]:
        """One seed per view: the initial parameters of its per-step reward model under segment labels."""
        return [classifier_seed(self.spec.seed, j) for j in range(len(self.spec.views))]

    def evaluate_policies(self) -> dict[str, np.ndarray]:
        """Each agent's greedy policy: (m,) arrays ``greedy_return``, ``success``,
        ``normalised_score`` and ``agreement``."""
        return self.task.evaluate(self.agents)

    def reference_returns(self) -> dict[str, float]:
        """The returns the normalised score is measured between."""
        return self.task.reference_returns()

    def state_dict(self) -> dict[str, Any]:
        """Everything the next rounds depend on, picklable: agents (SB3 zips as bytes), their replay
        buffers, the store, the reward table, the co-trainer and the global and action-space RNGs.

        The envs hold no state across rounds (each round starts from seeded resets). The dict refers
        to live objects: pickle it at once (as ``dospcot train`` does), do not keep it.
        """
        zips = []
        for agent in self.agents:
            blob = io.BytesIO()
            agent.save(blob)
            zips.append(blob.getvalue())
        return {
            "round": self.round,
            "stopped": self.stopped,
            "agents": zips,
            "buffers": [agent.replay_buffer for agent in self.agents],
            "action_space_rng": [agent.action_space.np_random.bit_generator.state for agent in self.agents],
            "store": self.store.state_dict(),
            "segments": None if self.segments is None else self.segments.state_dict(),
            "segment_classes": self.segment_classes,
            "table": self.table.state_dict(),
            "classes": self.classes,
            "trainer": self.trainer,
            # SB3 draws exploration and replay batches from the legacy global generators.
            "rng": {"python": random.getstate(), "numpy": np.random.get_state(), "torch": th.get_rng_state()},  # noqa: NPY002
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict` (this object must be built from the same spec and config)."""
        self.round, self.stopped = state["round"], state["stopped"]
        self.store.load_state_dict(state["store"])  # in place: the store wrappers keep pointing at it
        if self.segments is not None:
            self.segments.load_state_dict(state["segments"])
        self.segment_classes = state.get("segment_classes", self.segment_classes)  # older checkpoints lack it
        self.table.load_state_dict(state["table"])
        self.task.classes, self.trainer = state["classes"], state["trainer"]
        for k, agent in enumerate(self.agents):
            loaded = type(agent).load(io.BytesIO(state["agents"][k]), env=agent.get_env())
            loaded.replay_buffer = state["buffers"][k]
            loaded.replay_buffer.reward_table = agent.replay_buffer.reward_table
            loaded.action_space.np_random.bit_generator.state = state["action_space_rng"][k]
            self.agents[k] = loaded
            self._give_demonstrations(k)
        # Loading re-seeds the global generators (SB3's _setup_model): restore them last.
        random.setstate(state["rng"]["python"])
        np.random.set_state(state["rng"]["numpy"])  # noqa: NPY002
        th.set_rng_state(state["rng"]["torch"])

    def _records(self, stats: dict) -> list[dict]:
        policy = self.evaluate_policies()
        rows = []
        for k in range(len(self.agents)):
            round_view = stats["views"][k] if "views" in stats else {}
            rows.append(
                {
                    **record_head(self.spec, self.round, k),
                    "env_steps": int(self.agents[k].num_timesteps),
                    "agreement": float(policy["agreement"][k]),
                    "greedy_return": float(policy["greedy_return"][k]),
                    "success": float(policy["success"][k]),
                    "normalised_score": float(policy["normalised_score"][k]),
                    "eps": float(self.agents[k].exploration_rate),
                    "pace": stats.get("pace", float("nan")),
                    "coverage": stats.get("coverage", float("nan")),
                    "pseudo_accuracy": stats.get("pseudo_accuracy", float("nan")),
                    "worst_class_recall": stats.get("worst_class_recall", float("nan")),
                    "worst_class_precision": stats.get("worst_class_precision", float("nan")),
                    "labelled_steps": stats.get("labelled_steps", float("nan")),
                    "step_reward_error": stats.get("step_reward_error", float("nan")),
                    **{key: round_view.get(key, float("nan")) for key in VIEW_STATS},
                }
            )
        return rows
