"""One round of DOSPCoT with SB3 agents, for any task: the round is here once, a task adapter supplies
the rest (docs/design.md section 2).

A run has one agent per view; each reads its own view as its observation and keeps its own
relabelling replay buffer, and all of them write every step into the task's store. One round, top
to bottom, in :meth:`CoTrainingRun.run_round`:

1. **Collect**: every agent ``learn()``s for ``steps_per_round`` env steps. Its gradient steps sample
   rewards and self-paced weights from the shared :class:`~dospcot.policies.RewardTable` at sample
   time, so what earlier rounds admitted drives this round's updates.
   Under ``training.cotrain_passes`` c > 1 (from round ``training.passes_from_round`` on) the
   collection comes in c parts, each but the last followed by steps 2-3, so a step the agents take is
   rewarded in their replay a part later, not a round later; under ``training.pass_kind = "score"``
   each part but the last is followed by a score pass instead (:meth:`CoTrainingRun.score_pass`),
   which pseudo-rewards the steps not yet admitted with the classifiers as they are, fitting nothing.
   Under ``training.first_labels = "first_pass"`` round 1's first pass buys round 1's labels and
   co-trains (:meth:`CoTrainingRun.first_labels`), so round 1's later steps are rewarded in the round.
   **Queries** (an active ``training.label_strategy``, :mod:`dospcot.core.queries`): a rater labels
   the samples the strategy chooses, within the budget the uniform mask would spend.
2. **Co-train** (method ``"dospcot"``): the task turns its store into a
   :class:`~dospcot.core.self_paced.RunPool` (labelled samples and the unlabelled pool U, each view's
   classifier inputs), which goes to the run's :class:`~dospcot.core.self_paced.RunCoTrainer` (select,
   fit, score per view; Eq. 9).
3. **Pseudo-reward**: each admitted sample's consensus reward and weight go into the reward table,
   whose ids are the pool's samples, so every stored step of a sample reads them.
   Under segment labels (``segment_length`` k > 1, :mod:`dospcot.core.segments`) the pool's samples are
   k-step segments labelled with their summed reward, and each view's per-step reward model turns
   the labelled and admitted sums back into per-step rewards for the table.
4. **Policy update**: every agent takes ``update_steps`` gradient steps on its replay buffer, which
   now reads this round's pseudo-rewards, so they shape the policy evaluated at the end of the round.
5. **Age**: the pace (admitted share of U) sets every agent's exploration rate via ``set_pace``.
   Baselines, which have no pace, follow the share of rounds done, a plain linear schedule.
6. **Record**: the task measures every agent's greedy policy.

:meth:`CoTrainingRun.run` is the only loop over rounds; whoever drives a run (``dospcot train``'s run
folder, TensorBoard and checkpoints) hangs on its ``on_round`` hook. The run reads its config
(:class:`~dospcot.config.run_configs.TrainConfig`) directly.

What a task supplies (:class:`~dospcot.core.task_adapter.TaskAdapter`, built by
:func:`dospcot.adapters.build_adapter`): each agent's env (masked, writing the store), its reward
classes, the pool, each sample's true class (metrics only) and the evaluator. The grid adapter
(:mod:`dospcot.adapters.grid_adapter`) pools (s, a) keys and measures against the exact optimum; the
sensor adapter (:mod:`dospcot.adapters.sensor_adapter`) pools every step and runs evaluation episodes.

Agents (``cfg.agent_kinds``): ExpectedSarsaDQN with its Expected-SARSA target (``esarsa_dqn``) or DQN's max
target (``dqn``), or a Q-table over the view's observations (``tabular``,
:class:`~dospcot.policies.TabularExpectedSarsa`); any mix works, since all three are SB3 ``DQN`` models
(built by :func:`dospcot.core.run_agents.make_agent`).

Baselines: ``oracle`` (every reward revealed), ``masked-zero`` (masked rewards read as 0 with weight
1) and ``labels-only`` (masked steps weigh 0); the peer ``reward-model`` takes the co-trainer's place
in step 2 with ensembles fitted on the labels alone (:mod:`dospcot.core.reward_model`). The hidden
reward reaches only the metrics, but under the true-rewards control (``cotraining.pseudo_rewards =
"hidden"``), which writes it for every admitted sample in step 3.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.type_aliases import MaybeCallback, TrainFrequencyUnit

from dospcot.core.agent_draws import AgentDraws
from dospcot.core.queries import Rater, RewardQueries, SimulatedRater
from dospcot.core.reward_classes import QuantileRewardClasses, RunRewardClasses
from dospcot.core.reward_model import RewardModelTrainer
from dospcot.core.round_records import DEPENDENCE_STATS, VIEW_STATS, class_rows, record_head, round_stats
from dospcot.core.run_agents import make_agent, relabelling_kwargs
from dospcot.core.run_state import load_run_state, run_state
from dospcot.core.score_passes import score_run
from dospcot.core.segments import SegmentLabelWrapper, SegmentStore, segment_pool, step_rewards
from dospcot.core.self_paced import RunCoTrainer, RunPool
from dospcot.core.stopping import CO_TRAINER_STOPPED, GreedyPatience
from dospcot.core.task_adapter import TaskAdapter
from dospcot.core.true_rewards import given_truth
from dospcot.policies import ExpectedSarsaDQN, RewardTable
from dospcot.seeding import classifier_seed, query_seed, round_reset_seed

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig


def collection_parts(steps: int, passes: int, unit: int = 1) -> list[int]:
    """A round's ``steps`` env steps per agent cut into ``passes`` parts (``training.cotrain_passes``),
    each a whole number of ``unit`` steps, as equal as they can be, the longer ones first; the steps no
    whole unit holds go to the last part, and with fewer units than passes the unit is one step.
    ``collection_parts(10, 3) == [4, 3, 3]``, ``collection_parts(300, 4, 4) == [76, 76, 76, 72]``.

    :param unit: the agents' ``train_freq``: SB3's ``learn`` collects whole multiples of it, so a part
        that is none would take more steps than asked.
    """
    if steps // unit < passes:
        unit = 1
    units, rest = divmod(steps, unit)
    parts = [unit * (units // passes + (part < units % passes)) for part in range(passes)]
    parts[-1] += rest
    return parts


class CoTrainingRun:
    """One run of SB3 agents on a masked task, round by round.

    :param task: the task adapter (store, pool, evaluator), e.g. ``dospcot.adapters.build_adapter(cfg)``.
    :param cfg: the run's config, read directly: its method, views and agent kinds, seed, ``[training]``,
        ``[dqn]``, ``[tabular_agent]``, ``[cotraining]`` and ``[demonstrations]``.
    :param rater: who answers the reward queries of an active ``training.label_strategy``; None: the
        simulated rater, which answers from the hidden reward.
    """

    def __init__(self, task: TaskAdapter, cfg: TrainConfig, rater: Rater | None = None) -> None:
        self.task, self.cfg = task, cfg
        training = cfg.training
        self.queries: RewardQueries | None = None
        """The reward queries of an active label strategy, or None (the uniform mask)."""
        if training.queries:
            rater = rater or SimulatedRater(task.hidden_reward)
            self.queries = RewardQueries(training, rater)
        self.collected = False
        """Whether this round's collection is done, its queries not yet answered (a run stopped for a
        person's answers resumes there)."""
        self.table = RewardTable()
        self.segments: SegmentStore | None = None
        """The labelled and unlabelled segments under segment labels (``segment_length`` > 1), or None."""
        self.segment_classes = QuantileRewardClasses(task.n_classes)
        """The quantile classes of the segments' summed rewards (segment labels only)."""
        if cfg.training.segment_length > 1:
            self.segments = SegmentStore(cfg.training.segment_length)
        buffer_kwargs = relabelling_kwargs(cfg.method, self.table)
        self.agent_draws = AgentDraws() if training.agent_draws == "own" else None
        """Each agent's own draws (``training.agent_draws = "own"``), or None: the global generators."""
        self.agents: list[ExpectedSarsaDQN] = []
        for k, (kind, view) in enumerate(zip(cfg.agent_kinds, cfg.views, strict=True)):
            env = self._agent_env(k, view)
            self.agents.append(make_agent(env, k, kind, view, cfg, buffer_kwargs, task.observations(view)))
            if self.agent_draws is not None:
                self.agent_draws.add()  # as SB3 seeded the generators for agent k
        for k in range(len(self.agents)):
            self.give_demonstrations(k)
        self.trainer: RunCoTrainer | RewardModelTrainer | None = None
        if cfg.method == "dospcot":
            # A segment's input is the sum of its steps' (dospcot.core.segments.segment_pool).
            self.trainer = RunCoTrainer(task.feature_dims(), cfg.cotraining, cfg.seed, task.n_classes)
        elif cfg.method == "reward-model":
            self.trainer = RewardModelTrainer(task.feature_dims(), cfg.cotraining, cfg.seed, task.n_classes)
        self.scored_classes: np.ndarray | None = None
        """The classes the run had at its last co-training (their mask), which its classifiers were
        fitted to; None before the first (score passes, ``training.pass_kind = "score"``)."""
        self.class_records: list[dict] = []
        """Every round's pseudo-rewards per hidden reward class (metrics only; :func:`class_rows`), for a
        run that learns rewards, on single-step labels."""
        self.round = 0
        self.stopped = False
        """Whether a stopping rule has fired: the co-trainer's (``tol``, ``stop_when_fully_admitted``) or
        the greedy evaluation's (``training.stop_patience``)."""
        self.stop_reason = ""
        """Why the run stopped before its last round ("" while it has not)."""
        self.patience = GreedyPatience(cfg.training.stop_patience, task.reference_returns()["random_return"])

    def _agent_env(self, k: int, view: str) -> gym.Env:
        env = self.task.agent_env(k, view)
        return env if self.segments is None else SegmentLabelWrapper(env, self.segments)

    def give_demonstrations(self, k: int) -> None:
        """Agent ``k``'s large-margin loss reads the task's demonstrations in its own view (a neural
        agent's, with the loss on; a saved agent holds none, so a loaded one gets them again)."""
        if self.cfg.agent_kinds[k] == "tabular" or self.cfg.demonstrations.margin_loss_weight == 0:
            return
        demos = self.task.demonstrations(self.cfg.views[k])
        if demos is not None:
            self.agents[k].set_demonstrations(*demos)

    @property
    def store(self) -> Any:
        """The task's store."""
        return self.task.store

    @property
    def classes(self) -> RunRewardClasses | QuantileRewardClasses:
        """The task's reward classes."""
        return self.task.classes

    def run(
        self,
        on_round: Callable[[CoTrainingRun, list[dict]], None] | None = None,
        callback: MaybeCallback = None,
        until_round: int | None = None,
    ) -> list[dict]:
        """Every round left, or until the stopping rule fires: the only loop over rounds.

        :param on_round: called after each round with the run and that round's records (one per
            agent): where a driver logs, writes files and checkpoints.
        :param callback: passed to every agent's ``learn()`` (SB3 callbacks, e.g. a progress bar).
        :param until_round: stop after this round (1-based) even if the config has more; None: its last.
        :return: one record per round run now and agent.
        """
        last = self.cfg.training.rounds if until_round is None else min(until_round, self.cfg.training.rounds)
        records: list[dict] = []
        # A round stopped for a person's answers (collected, not yet co-trained) is finished first.
        while (self.round < last or self.collected) and not self.stopped:
            rows = self.run_round(callback)
            records += rows
            if on_round is not None:
                on_round(self, rows)
        return records

    def run_round(self, callback: MaybeCallback = None) -> list[dict]:
        """One round (docs/design.md section 2); returns its records.

        :param callback: passed to every agent's ``learn()`` (SB3 callbacks, e.g. a progress bar).
        """
        if not self.collected:  # 1. collect and learn, with the rewards and weights written so far
            self.round += 1
            parts = self.round_parts()
            for part, steps in enumerate(parts):
                for k, agent in enumerate(self.agents):
                    if part == 0:
                        self.seed_round_env(k)  # learn() then resets it, with that seed
                    with self._draws_of(k):  # a later part goes on with the episodes the last one left
                        agent.learn(steps, callback=callback, reset_num_timesteps=False)
                if part < len(parts) - 1:  # 1a. a pass inside the round rewards the steps just taken
                    self.inner_pass(part)
            self.collected = True
        stats = self.label_and_cotrain()  # 1b-3.
        for k, agent in enumerate(self.agents):  # 4. policy update on the rewards and weights just written
            with self._draws_of(k):
                agent.update(self.cfg.training.update_steps)
        return self.close_round(stats)  # 5-6.

    def round_parts(self) -> list[int]:
        """The env steps of each part of this round's collection (:func:`collection_parts`): one part
        before ``training.passes_from_round``, then ``cotrain_passes``, in whole multiples of the
        agents' ``train_freq`` where every agent counts it in steps."""
        training = self.cfg.training
        passes = training.cotrain_passes if self.round >= training.passes_from_round else 1
        freqs = [agent.train_freq for agent in self.agents]
        by_steps = all(freq.unit == TrainFrequencyUnit.STEP for freq in freqs)
        unit = math.lcm(*(freq.frequency for freq in freqs)) if by_steps else 1
        return collection_parts(training.steps_per_round, passes, unit)

    def _draws_of(self, k: int) -> AbstractContextManager[None]:
        """Where agent ``k`` draws: its own generators under ``agent_draws = "own"``, else the global ones."""
        return nullcontext() if self.agent_draws is None else self.agent_draws.of(k)

    def seed_round_env(self, k: int) -> None:
        """Seed agent ``k``'s env for this round and have it reset at the round's start."""
        # Every round starts from fresh episodes with seeded resets, so a run resumed from the
        # checkpoint of the last round continues exactly as the uninterrupted run would.
        agent = self.agents[k]
        env = agent.get_env()
        env.seed(round_reset_seed(self.cfg.seed, k, self.round))
        agent.set_env(env, force_reset=True)

    def label_and_cotrain(self) -> dict:
        """Steps 1b-3 of a collected round: buy labels, co-train and write the pseudo-rewards; returns
        the round's co-training figures."""
        self.buy_labels()  # 1b. (a file rater may stop the run here)
        self.collected = False
        if self.trainer is not None:  # 2-3. co-train, pseudo-rewards
            stats = self.cotrain()
        else:  # a baseline has no co-trainer, but its labels are its effort too
            stats = {"labelled_steps": int(self.store.labelled.sum())}
        return stats

    def buy_labels(self) -> None:
        """Buy what the round's allowance has left, under an active label strategy."""
        if self.queries is not None:
            rng = np.random.default_rng(query_seed(self.cfg.seed, self.round))
            self.queries.buy(self.round, self.task, self._probabilities, rng)

    def close_round(self, stats: dict) -> list[dict]:
        """Steps 5-6 of a round whose policies are updated: age, then record."""
        training = self.cfg.training
        pace = self.round / training.rounds  # 5. age
        if training.exploration == "pace":
            pace = stats.get("pace", pace)
        for agent in self.agents:
            agent.set_pace(min(pace, 1.0))
        rows = self._records(stats)  # 6. record
        self._check_patience(rows)
        return rows

    def _check_patience(self, rows: list[dict]) -> None:
        """Record why the run stops, where a stopping rule fired this round (the co-trainer's, or the
        greedy evaluation's patience, :class:`~dospcot.core.stopping.GreedyPatience`)."""
        out_of_patience = self.patience.update(rows) and self.round < self.cfg.training.rounds
        if self.stopped and not self.stop_reason:
            self.stop_reason = CO_TRAINER_STOPPED
        elif out_of_patience:
            self.stopped, self.stop_reason = True, self.patience.reason()

    def cotrain(self, record: bool = True, ages: bool = True) -> dict:
        """Steps 2-3 of a round: co-train on the task's pool and write the pseudo-rewards and their
        weights into the reward table; returns the round's co-training figures.

        :param record: keep the pseudo-rewards per class in :attr:`class_records` (False for a pass
            inside a round, ``training.cotrain_passes``: a round keeps its last pass's).
        :param ages: whether the co-trainer's step ages its schedule (False: a fit ahead of the round's
            step, :meth:`first_labels`).
        """
        # Segment features are sums of step features, taken in float32 as they always were.
        pool = self.task.pool(np.float32 if self.segments is not None else self.trainer.dtype_np)
        if self.segments is not None:
            return self._cotrain_segments(pool)
        # Score passes take no step of the schedule: the round's co-training ages it by a whole round.
        steps = len(self.round_parts()) if self.cfg.training.pass_kind == "cotrain" else 1
        result = self.trainer.step(pool, steps, ages)
        self.scored_classes = self.classes.mask.copy()
        pseudo = np.nan_to_num(self.classes.decode(result.pseudo_class), nan=0.0)
        true_class = self.task.true_class()  # metrics only, and the true-rewards control's classes
        if self.true_rewards:
            pseudo, result = given_truth(result, pseudo, self.store.hidden_reward, true_class)
        self.table.set(np.arange(pseudo.size), pseudo, result.pseudo_weight)
        read, value = result.pseudo_weight > 0, pseudo.copy()
        if self.queries is not None:  # a bought label reaches every stored and future step of its sample
            bought = np.flatnonzero(self.queries.revealed)
            read[bought], value[bought] = True, self.store.label_value[bought]
            self.table.set(bought, value[bought], 1.0)
        self.stopped = result.stopped
        stats = round_stats(result, pool.unlabelled, true_class, self.true_rewards)
        rewards = self.classes.decode(np.arange(self.task.n_classes))
        labelled, unlabelled = pool.labelled, pool.unlabelled
        if record:
            self.class_records += class_rows(self.round, result, labelled, unlabelled, true_class, rewards)
        # The classes' values too: a right class can pay the wrong reward (a late goal's in the steps').
        error = np.abs(value - self.store.hidden_reward[: value.size])[read].mean() if read.any() else np.nan
        return {**stats, "labelled_steps": int(labelled.sum()), "step_reward_error": float(error)}

    def inner_pass(self, part: int) -> None:
        """A pass inside a round (``training.cotrain_passes``) after its collection's part ``part``
        (0-based): a co-training pass, or a score pass under ``training.pass_kind = "score"``; round
        1's first under ``training.first_labels = "first_pass"`` buys labels first
        (:meth:`first_labels`)."""
        training = self.cfg.training
        if self.round == 1 and part == 0 and training.first_labels == "first_pass":
            self.first_labels()
        elif training.pass_kind == "score":
            self.score_pass()
        else:
            self.cotrain(record=False)

    def first_labels(self) -> None:
        """Round 1's labels bought at its first pass, among the samples met by then, and fitted there,
        so the steps round 1 takes after it read rewards before the round ends; the pass's own step of
        the schedule under co-training passes, a fit ahead of the round's step under score passes."""
        self.buy_labels()
        if self.trainer is not None:
            self.cotrain(record=False, ages=self.cfg.training.pass_kind == "cotrain")

    def score_pass(self) -> None:
        """A score pass inside a round (``training.pass_kind = "score"``): the steps the last co-training
        did not admit read the pseudo-rewards (under the true-rewards control, the hidden rewards) of
        the samples the classifiers as it left them admit (:mod:`dospcot.core.score_passes`; the reward
        model's ensembles reward every sample met since, :meth:`RewardModelTrainer.score`); nothing is
        fitted. Before the run's first co-training, or where a class has appeared or merged since
        it (the classifiers never fitted the classes as they are), the pass admits nothing."""
        pool = self.task.pool(self.trainer.dtype_np)
        before = self.scored_classes
        if before is None or not np.array_equal(before, self.classes.mask):
            return
        if isinstance(self.trainer, RewardModelTrainer):
            pseudo_class, weight = self.trainer.score(pool)
        else:
            pseudo_class, weight = score_run(self.trainer, pool)
        admitted = np.flatnonzero(weight > 0)
        if self.true_rewards:
            reward = self.store.hidden_reward[admitted]
        else:
            reward = np.nan_to_num(self.classes.decode(pseudo_class[admitted]), nan=0.0)
        self.table.set(admitted, reward, weight[admitted])

    def _cotrain_segments(self, steps: RunPool) -> dict:
        """Steps 2-3 under segment labels: co-train on segments, then turn the labelled and admitted
        segment sums into per-step rewards (:mod:`dospcot.core.segments`)."""
        segments, n = self.segments, len(self.segments)
        pool = segment_pool(steps, segments, self.segment_classes)
        result = self.trainer.step(pool)
        labelled = pool.labelled
        pseudo = np.nan_to_num(self.segment_classes.decode(result.pseudo_class), nan=0.0)
        # Metrics only, and the true-rewards control's classes.
        true_class = self.segment_classes.encode_hidden(segments.hidden[:n])
        if self.true_rewards:
            pseudo, result = given_truth(result, pseudo, segments.hidden, true_class)
        sums = np.where(labelled, segments.label[:n], pseudo)
        weight = np.where(labelled, 1.0, result.pseudo_weight)
        model = self.cfg.cotraining.classifier
        reward, step_weight = step_rewards(steps, segments, sums, weight, model, self.step_model_seeds())
        self.table.set(np.arange(reward.size), reward, step_weight)
        self.stopped = result.stopped
        stats = round_stats(result, pool.unlabelled, true_class, self.true_rewards)
        # How far the decoded per-step rewards lie from the hidden ones, where the agents read them.
        decoded = step_weight > 0
        error = np.abs(reward - self.store.hidden_reward[: reward.size])[decoded]  # metrics only
        return {
            **stats,
            "labelled_steps": int((segments.ids[:n][labelled] >= 0).sum()),
            "step_reward_error": float(error.mean()) if decoded.any() else float("nan"),
        }

    @property
    def true_rewards(self) -> bool:
        """Whether the admitted samples read their true rewards (``cotraining.pseudo_rewards = "hidden"``)."""
        return self.cfg.cotraining.pseudo_rewards == "hidden"

    def _probabilities(self) -> np.ndarray | None:
        """(m, N, K) the views' class probabilities of the task's pool, or None before any fit."""
        if self.trainer is None:
            return None
        return self.trainer.probabilities(self.task.pool(self.trainer.dtype_np))

    def step_model_seeds(self) -> list[int]:
        """One seed per view: the initial parameters of its per-step reward model under segment labels."""
        return [classifier_seed(self.cfg.seed, j) for j in range(len(self.cfg.views))]

    def evaluate_policies(self) -> dict[str, np.ndarray]:
        """Each agent's greedy policy: (m,) arrays ``greedy_return``, ``success``,
        ``normalised_score`` and ``agreement``."""
        return self.task.evaluate(self.agents)

    def reference_returns(self) -> dict[str, float]:
        """The returns the normalised score is measured between."""
        return self.task.reference_returns()

    def state_dict(self) -> dict[str, Any]:
        """Everything the next rounds depend on, picklable (:func:`dospcot.core.run_state.run_state`)."""
        return run_state(self)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict` (this object must be built from the same spec and config)."""
        load_run_state(self, state)

    def _records(self, stats: dict) -> list[dict]:
        policy = self.evaluate_policies()
        cfg = self.cfg
        head = (cfg.method, cfg.agent_kinds, cfg.views, cfg.cotraining.consensus_weight, cfg.seed)
        rows = []
        for k in range(len(self.agents)):
            round_view = stats["views"][k] if "views" in stats else {}
            rows.append(
                {
                    **record_head(*head, self.round, k),
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
                    **{key: stats.get(key, float("nan")) for key in DEPENDENCE_STATS},
                    # Runs on the uniform mask keep the columns they always had.
                    **({} if self.queries is None else {"queries": self.queries.answers_of(self.round).size}),
                }
            )
        return rows
