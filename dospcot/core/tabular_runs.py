"""DOSPCoT with tabular agents on a masked discrete MDP, vectorised over runs (the validation path).

A *run* is one method with one seed: m agents (one per view) sharing a transition store and, for
co-training, m reward classifiers. Many runs step in lock step; nothing crosses between them, so a
run's result is the same alone or in a batch (a test checks this).

One round, top to bottom (docs/design.md section 2), in :meth:`TabularCoTraining.run`:

1. **Collect**: every agent plays ``episodes_per_round`` epsilon-greedy episodes and learns online
   from each step with the reward and weight of its run's current reward table: the true reward
   where the step was labelled (revealed by the mask), the pseudo-reward and its self-paced weight
   where admitted, weight 0 elsewhere. Every transition enters the run's store, deduplicated by
   (s, a) key.
2. **Co-train** (method ``"dospcot"``): the store's labelled keys and unlabelled pool U go to the
   :class:`~dospcot.core.self_paced.SelfPacedCoTrainer` (select, fit, score per view; Eq. 9).
3. **Pseudo-reward**: the consensus classes become the run's reward table.
4. **Policy update**: ``replay_sweeps`` synchronous weighted TD sweeps over the stored transitions.
5. **Age**: the pace (admitted share of U) sets the next round's exploration rate.

Baselines run the same loop with a fixed table: ``oracle`` (every key labelled), ``masked-zero``
(masked rewards read as 0, weight 1) and ``labels-only`` (masked keys weight 0). Self-training is
``dospcot`` with one view.

The hidden reward of a masked key reaches only :mod:`dospcot.metrics`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from itertools import groupby

import numpy as np

from dospcot import metrics
from dospcot.config.paper_sections import TabularConfig
from dospcot.core.key_pool import key_features
from dospcot.core.reward_classes import RewardClasses
from dospcot.core.round_records import DEPENDENCE_STATS, VIEW_STATS, record_head, round_stats
from dospcot.core.self_paced import Pool, SelfPacedCoTrainer
from dospcot.envs.masking import StateActionMask
from dospcot.envs.tabular import TabularMDP
from dospcot.policies.tabular import TabularAgents, check_agent_kind
from dospcot.seeding import agent_seed

METHODS: tuple[str, ...] = ("oracle", "masked-zero", "labels-only", "dospcot")
"""``oracle``: every key labelled; ``masked-zero``: masked rewards read as 0; ``labels-only``: masked
steps drive no update; ``dospcot``: DOSPCoT with the run's views (m = 1 is self-training)."""


@dataclass(frozen=True)
class TabularRunSpec:
    """One tabular run of a batch.

    :param method: one of :data:`METHODS`.
    :param agents: agent kind of each view, from :data:`dospcot.policies.tabular.TABULAR_KINDS`.
    :param views: the view of each agent (its reward classifier's input).
    :param gamma: the consensus weight (``cotraining.consensus_weight``, the paper's gamma; co-training
        only).
    :param seed: seeds the mask, the exploration and the classifiers; runs of different methods
        with the same seed share the labelled key set.
    """

    method: str
    agents: tuple[str, ...]
    views: tuple[str, ...]
    gamma: float = 0.3
    seed: int = 0

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if len(self.agents) < 1 or len(self.agents) != len(self.views):
            raise ValueError(
                "need one view per agent and at least one agent; "
                f"got agents={self.agents}, views={self.views}"
            )
        for kind in self.agents:
            check_agent_kind(kind)


@dataclass
class TabularResult:
    """What a study returns.

    :param records: one dict per run, round and agent (the rows of ``metrics.csv``).
    :param q: (n_slots, S, A) final Q-tables, slot order = runs in order, agents in order.
    """

    records: list[dict]
    q: np.ndarray


class TabularCoTraining:
    """Trains a batch of tabular runs on one masked MDP.

    :param mdp: the task; its ``views`` must hold every view the specs name.
    :param specs: the runs.
    :param config: shared hyperparameters.
    :param reference_policy: (S,) actions for the paper accuracy, if the task has one.
    """

    def __init__(
        self,
        mdp: TabularMDP,
        specs: Sequence[TabularRunSpec],
        config: TabularConfig,
        reference_policy: np.ndarray | None = None,
    ) -> None:
        missing = sorted({v for spec in specs for v in spec.views} - set(mdp.views))
        if missing:
            raise ValueError(f"unknown view(s) {missing}; this task has {sorted(mdp.views)}")
        self.mdp, self.specs, self.config = mdp, list(specs), config
        self.reference_policy = reference_policy
        n_runs, n_s, n_a = len(self.specs), mdp.n_states, mdp.n_actions
        self.slot_run = np.array([r for r, spec in enumerate(self.specs) for _ in spec.agents])
        self.slot_agent = np.array([k for spec in self.specs for k in range(len(spec.agents))])
        kinds = [kind for spec in self.specs for kind in spec.agents]
        seeds = [
            agent_seed(self.specs[r].seed, k) for r, k in zip(self.slot_run, self.slot_agent, strict=True)
        ]
        self.agents = TabularAgents(kinds, n_s, n_a, config.learning_rate, config.discount, seeds)
        self.labelled = np.stack(
            [
                np.ones((n_s, n_a), dtype=bool)
                if spec.method == "oracle"
                else StateActionMask(n_s, n_a, config.label_fraction, spec.seed).labelled
                for spec in self.specs
            ]
        )
        # The run's store: which keys were seen, with their s', termination and revealed reward.
        self.visited = np.zeros((n_runs, n_s, n_a), dtype=bool)
        self.stored_next = np.zeros((n_runs, n_s, n_a), dtype=np.int64)
        self.stored_terminal = np.zeros((n_runs, n_s, n_a), dtype=bool)
        self.label_value = np.zeros((n_runs, n_s, n_a))
        # The reward table for unlabelled keys: pseudo-rewards and their weights (or a baseline's rule).
        self.table_reward = np.zeros((n_runs, n_s, n_a))
        self.table_weight = np.array([1.0 if s.method == "masked-zero" else 0.0 for s in self.specs])[
            :, None, None
        ] * np.ones((n_runs, n_s, n_a))
        self.pace = np.zeros(n_runs)
        self.active = np.ones(n_runs, dtype=bool)
        self.env_steps = 0  # agent steps collected so far, summed over slots
        self.groups = self._make_groups()
        self.policy_metrics = metrics.GreedyPolicyMetrics(mdp, config.discount)

    def _make_groups(self) -> list[tuple[list[int], SelfPacedCoTrainer, RewardClasses]]:
        """One co-trainer per (views, gamma): runs that share them are batched in one classifier."""
        cotrain = [r for r, s in enumerate(self.specs) if s.method == "dospcot"]

        def signature(r: int) -> tuple:
            return self.specs[r].views, self.specs[r].gamma

        groups = []
        for (views, gamma), members in groupby(sorted(cotrain, key=signature), key=signature):
            runs = list(members)
            cfg = replace(self.config.cotraining, consensus_weight=gamma)
            dims = [2 * self.mdp.views[v].shape[1] + self.mdp.n_actions for v in views]
            seeds = [self.specs[r].seed for r in runs]
            trainer = SelfPacedCoTrainer(dims, len(runs), cfg, seeds, cfg.max_classes)
            groups.append((runs, trainer, RewardClasses(len(runs), cfg.max_classes)))
        return groups

    def eps(self) -> np.ndarray:
        """(n_runs,) exploration rate eps(pace)."""
        cfg = self.config
        return cfg.eps_start + (cfg.eps_end - cfg.eps_start) * self.pace

    def run(self, progress: Callable[[int], None] | None = None) -> TabularResult:
        """Train every run for ``config.rounds`` rounds (or until its stopping rule fires).

        :param progress: called with the number of episodes just finished (summed over slots).
        """
        records: list[dict] = []
        for round_index in range(1, self.config.rounds + 1):
            self._collect(progress)  # 1. collect, learning online from the current table
            stats_by_run = {}
            for runs, trainer, classes in self.groups:  # 2-3. co-train, pseudo-rewards
                if self.active[runs].any():
                    stats_by_run.update(self._cotrain(runs, trainer, classes))
            reward, weight = self._effective_table()
            slot_eps = self.eps()[self.slot_run]
            live_slots = self.active[self.slot_run][:, None, None]
            for _ in range(self.config.replay_sweeps):  # 4. policy update
                self.agents.sweep(
                    self.visited[self.slot_run] & live_slots,
                    self.stored_next[self.slot_run],
                    self.stored_terminal[self.slot_run],
                    reward[self.slot_run],
                    weight[self.slot_run],
                    slot_eps,
                )
            for r, stats in stats_by_run.items():  # 5. age: the pace drives exploration
                self.pace[r] = stats["pace"]
                if stats.pop("stopped"):
                    self.active[r] = False
            records.extend(self._records(round_index, stats_by_run))
        return TabularResult(records, self.agents.q.copy())

    def _collect(self, progress: Callable[[int], None] | None) -> None:
        mdp, agents, n_slots = self.mdp, self.agents, len(self.slot_run)
        target = self.config.episodes_per_round
        eps = self.eps()[self.slot_run]
        running = self.active[self.slot_run].copy()
        state = np.full(n_slots, mdp.start_state)
        steps = np.zeros(n_slots, dtype=np.int64)
        episodes = np.zeros(n_slots, dtype=np.int64)
        action = np.zeros(n_slots, dtype=np.int64)
        # Flat views of the (runs, S, A) and (S, A) tables: one index per step instead of three.
        n_keys = mdp.n_states * mdp.n_actions
        next_state, terminal, true_reward = (
            x.reshape(-1) for x in (mdp.next_state, mdp.terminal, mdp.reward)
        )
        labelled, table_reward, table_weight = (
            x.reshape(-1) for x in (self.labelled, self.table_reward, self.table_weight)
        )
        visited, stored_next, stored_terminal, label_value = (
            x.reshape(-1) for x in (self.visited, self.stored_next, self.stored_terminal, self.label_value)
        )
        idx = np.flatnonzero(running)
        action[idx] = agents.act(idx, state[idx], eps[idx])
        while idx.size:
            self.env_steps += idx.size
            s, a = state[idx], action[idx]
            sa = s * mdp.n_actions + a
            key = self.slot_run[idx] * n_keys + sa
            s2, terminated = next_state[sa], terminal[sa]
            revealed = labelled[key]
            # The mask: a learner sees the true reward only where the key is labelled.
            observed_reward = np.where(revealed, true_reward[sa], 0.0)
            reward = np.where(revealed, observed_reward, table_reward[key])
            weight = np.where(revealed, 1.0, table_weight[key])
            visited[key] = True
            stored_next[key] = s2
            stored_terminal[key] = terminated
            label_value[key] = np.where(revealed, observed_reward, label_value[key])
            next_action = agents.act_and_update(idx, s, a, reward, weight, s2, terminated, eps[idx])
            steps[idx] += 1
            ended = terminated | (steps[idx] >= mdp.max_episode_steps)
            episodes[idx] += ended
            state[idx] = np.where(ended, mdp.start_state, s2)
            steps[idx] = np.where(ended, 0, steps[idx])
            action[idx] = next_action
            restart = idx[ended & (episodes[idx] < target)]
            if restart.size:
                action[restart] = agents.act(restart, state[restart], eps[restart])
            if progress is not None and ended.any():
                progress(int(ended.sum()))
            running[idx[ended & (episodes[idx] >= target)]] = False
            idx = np.flatnonzero(running)

    def _cotrain(
        self, runs: list[int], trainer: SelfPacedCoTrainer, classes: RewardClasses
    ) -> dict[int, dict]:
        n_runs = len(runs)
        labelled = (self.visited[runs] & self.labelled[runs]).reshape(n_runs, -1)
        unlabelled = (self.visited[runs] & ~self.labelled[runs]).reshape(n_runs, -1)
        values = self.label_value[runs].reshape(n_runs, -1)
        for b in range(n_runs):
            classes.observe(b, np.unique(values[b, labelled[b]]))
        label_class = np.where(labelled, classes.encode(values), -1)
        views = self.specs[runs[0]].views
        visited = self.visited[runs].reshape(n_runs, -1)
        next_state = self.stored_next[runs].reshape(n_runs, -1)
        features = [key_features(self.mdp.views[v], next_state, visited, self.mdp.n_actions) for v in views]
        pool = Pool(features, labelled, label_class, unlabelled, classes.mask)
        # Stopped runs stay in the batch (its classifiers are stacked) but keep their last table.
        result = trainer.step(pool)
        live = self.active[runs]
        shape = (int(live.sum()), self.mdp.n_states, self.mdp.n_actions)
        pseudo = classes.decode(result.pseudo_class)[live]
        live_runs = np.asarray(runs)[live]
        self.table_reward[live_runs] = np.nan_to_num(pseudo, nan=0.0).reshape(shape)
        self.table_weight[live_runs] = result.pseudo_weight[live].reshape(shape)
        truth = classes.encode(np.broadcast_to(self.mdp.reward.reshape(-1), labelled.shape))  # metrics only
        return {
            r: round_stats(result.of_run(b), pool.unlabelled[b], truth[b])
            for b, r in enumerate(runs)
            if self.active[r]
        }

    def _effective_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Reward and weight of every key per run: revealed labels, else the run's table."""
        known = self.visited & self.labelled
        return (
            np.where(known, self.label_value, self.table_reward),
            np.where(known, 1.0, self.table_weight),
        )

    def _records(self, round_index: int, stats_by_run: dict[int, dict]) -> list[dict]:
        greedy = self.agents.greedy_actions()
        policy = self.policy_metrics(greedy)
        paper = (
            metrics.paper_accuracy(greedy, self.reference_policy)
            if self.reference_policy is not None
            else np.full(len(greedy), np.nan)
        )
        eps = self.eps()
        rows = []
        for slot, (r, k) in enumerate(zip(self.slot_run, self.slot_agent, strict=True)):
            spec = self.specs[r]
            stats = stats_by_run.get(r)
            view_stats = stats["views"][k] if stats else {}
            rows.append(
                {
                    **record_head(
                        spec.method, spec.agents, spec.views, spec.gamma, spec.seed, round_index, k
                    ),
                    "paper_accuracy": float(paper[slot]),
                    "agreement": float(policy["agreement"][slot]),
                    "greedy_return": float(policy["greedy_return"][slot]),
                    "success": float(policy["success"][slot]),
                    "normalised_score": float(policy["normalised_score"][slot]),
                    "eps": float(eps[r]),
                    "pace": float(self.pace[r]),
                    "coverage": stats["coverage"] if stats else float("nan"),
                    "pseudo_accuracy": stats["pseudo_accuracy"] if stats else float("nan"),
                    **{key: view_stats.get(key, float("nan")) for key in VIEW_STATS},
                    **{key: stats[key] if stats else float("nan") for key in DEPENDENCE_STATS},
                    "active": bool(self.active[r]),
                }
            )
        return rows
