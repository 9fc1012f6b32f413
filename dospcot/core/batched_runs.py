"""S seeds of one config trained in lock step in one process (docs/batched_seeds.md).

Each member is an ordinary :class:`~dospcot.core.sb3_round.CoTrainingRun` of its own seed: its
task, store, reward table, co-trainer and plain SB3 agents. What the batch shares is the arithmetic of
the agents' networks: per view, one :class:`~dospcot.policies.stacked_esarsa.StackedExpectedSarsa`
holds every member's online and target networks and Adam state, so that one forward pass picks every
member's greedy action and one gradient step updates every member. What that saves is per-call
overhead; at 128 hidden units and batches of 64 the arithmetic itself takes most of a gradient step,
and the classifiers' fits and the envs' steps still run member by member, so the saving is modest
(docs/batched_seeds.md, "Speed").

One round of the batch, top to bottom (:meth:`BatchedRuns.run_round`):

1. **Collect**, view by view: every member's agent of that view steps its own env in lock step with
   the others (this file's loop replaces SB3's ``learn``, with DQN's semantics: uniform actions until
   ``learning_starts``, then eps-greedy at the member's own eps; every transition stored in the
   member's relabelling buffer through the agent's own ``_store_transition``; a gradient step every
   ``train_freq`` steps; the target networks synced every ``target_update_interval`` steps).
2. **Label and co-train**, member by member (the run's own
   :meth:`~dospcot.core.sb3_round.CoTrainingRun.label_and_cotrain`).
3. **Policy update**: ``update_steps`` stacked gradient steps per view, the targets synced as
   ``ExpectedSarsaDQN.update`` syncs them.
4. **Age and record**, member by member (:meth:`~dospcot.core.sb3_round.CoTrainingRun.close_round`).

After each phase that trains, every member's weights and Adam state are written back into its SB3
agent, so that evaluation, ``agent.save`` and checkpoints see plain SB3 agents, and each member's part
of the batch's checkpoint is what a run of its own would checkpoint.

Random draws: a run of its own draws exploration and replay batches from numpy's global generator;
a member draws them from its own stream per agent (:func:`~dospcot.seeding.batched_draws_seed`), so
that a member's trajectory never depends on the other members (a test changes one member's seed and
checks the others bit for bit). A member's results are therefore not a single run's of the same seed,
but the same distribution's (docs/batched_seeds.md measures it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import torch as th

from dospcot.core import sb3_engine as sb3
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.stacked_esarsa import StackedExpectedSarsa, stack_samples
from dospcot.policies.stacked_esarsa.stacked_q_network import linear_layers
from dospcot.seeding import batched_draws_seed

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig


def config_refusal(cfg: TrainConfig) -> str | None:
    """Why the seeds of ``cfg`` cannot train as one batch (one line), or None where they can."""
    if "tabular" in cfg.agent_kinds:
        return "tabular agents keep a table, not a network, so they have nothing to stack"
    if cfg.training.rater == "file":
        return "a file rater stops its run for a person's answers, which a batch cannot do member by member"
    if cfg.dqn.tau != 1.0:
        return "only hard target updates (dqn.tau = 1) are stacked"
    if cfg.dqn.optimize_memory_usage:
        return "dqn.optimize_memory_usage is not stacked"
    if cfg.cotraining.tol > 0 or cfg.cotraining.stop_when_fully_admitted or cfg.training.stop_patience:
        return (
            "a stopping rule (cotraining.tol, stop_when_fully_admitted, training.stop_patience) ends seeds "
            "at different rounds"
        )
    return None


class BatchedRuns:
    """S runs of one config, differing in their seeds alone, trained round by round in lock step.

    :param runs: the members, each built (and, to resume, loaded from its checkpoint) as a run of its
        own would be; all at the same round.
    :raises ValueError: runs that cannot be batched (:func:`config_refusal`, or configs that differ in
        more than their seeds, or runs at different rounds).
    """

    def __init__(self, runs: Sequence[CoTrainingRun]) -> None:
        first = runs[0].cfg
        refusal = config_refusal(first)
        if any(dataclasses.replace(run.cfg, seed=first.seed) != first for run in runs):
            refusal = "the runs' configs differ in more than their seeds"
        elif len({run.cfg.seed for run in runs}) != len(runs):
            refusal = "two runs share a seed"
        elif len({(run.round, run.collected) for run in runs}) != 1:
            refusal = "the runs stand at different rounds"
        if refusal is not None:
            raise ValueError(f"these runs cannot train as one batch: {refusal}")
        self.runs = list(runs)
        self.cfg = runs[0].cfg
        self.n_views = len(self.cfg.views)
        self.learners = [
            StackedExpectedSarsa.from_agents([run.agents[k] for run in runs]) for k in range(self.n_views)
        ]
        self.draws = [
            [np.random.RandomState(batched_draws_seed(run.cfg.seed, k)) for run in runs]
            for k in range(self.n_views)
        ]
        """Per view, each member's stream of exploration, replay and demonstration draws."""

    def draws_of(self, member: int) -> list[tuple]:
        """The state of member ``member``'s draw streams, one per view (for its checkpoint)."""
        return [self.draws[k][member].get_state() for k in range(self.n_views)]

    def set_draws(self, states: Sequence[Sequence[tuple]]) -> None:
        """Continue every member's draw streams from :meth:`draws_of`'s states, member by member."""
        for member, member_states in enumerate(states):
            for k, state in enumerate(member_states):
                self.draws[k][member].set_state(state)

    @property
    def n_members(self) -> int:
        """S, the runs in the batch."""
        return len(self.runs)

    def run(
        self,
        on_round: Callable[[list[list[dict]]], None] | None = None,
        on_steps: Callable[[int], None] | None = None,
    ) -> None:
        """Every round left: the batch's loop over rounds.

        :param on_round: called after each round with every member's records of it.
        :param on_steps: called with the member-steps just taken (S per lock step), e.g. a progress bar.
        """
        first = self.runs[0]
        while first.round < self.cfg.training.rounds:
            rows = self.run_round(on_steps)
            if on_round is not None:
                on_round(rows)

    def run_round(self, on_steps: Callable[[int], None] | None = None) -> list[list[dict]]:
        """One round of every member; returns each member's records."""
        for run in self.runs:
            run.round += 1
        parts = self.runs[0].round_parts()
        for part, steps in enumerate(parts):
            for k in range(self.n_views):  # 1. collect and learn, view by view
                if part == 0:
                    for run in self.runs:
                        run.seed_round_env(k)
                self._collect(k, steps, on_steps)
                self._write_back(k)
            if part < len(parts) - 1:  # 1a. a pass inside the round (training.cotrain_passes)
                for run in self.runs:
                    run.inner_pass(part)
        for run in self.runs:
            run.collected = True
        stats = [run.label_and_cotrain() for run in self.runs]  # 2. label and co-train
        for k in range(self.n_views):  # 3. policy update
            self._update(k)
            self._write_back(k)
        return [run.close_round(s) for run, s in zip(self.runs, stats, strict=True)]  # 4. age, record

    def _agents(self, k: int) -> list[ExpectedSarsaDQN]:
        return [run.agents[k] for run in self.runs]

    def _collect(self, k: int, steps: int, on_steps: Callable[[int], None] | None) -> None:
        """``steps`` lock steps of every member's agent ``k`` (DQN's ``learn`` semantics)."""
        agents, learner, draws = self._agents(k), self.learners[k], self.draws[k]
        first = agents[0]
        for agent in agents:
            sb3.start_collection(agent, steps)
        envs = [agent.get_env() for agent in agents]
        # Windows cut at exploratory actions need the greedy action even during the uniform warm-up.
        flag = first.cut_windows and first.target == "q" and first.n_steps > 1
        train_every, syncs_every = first.train_freq.frequency, max(first.target_update_interval, 1)
        for step in range(1, steps + 1):
            warmup = first.num_timesteps < first.learning_starts
            greedy = None
            if flag or not warmup:
                obs = th.as_tensor(
                    np.stack([sb3.last_observation(agent) for agent in agents]),
                    dtype=th.float32,
                    device=first.device,
                )
                with th.no_grad():
                    greedy = learner.q_net(obs).argmax(dim=2).cpu().numpy()  # (S, 1)
            for s, (agent, env) in enumerate(zip(agents, envs, strict=True)):
                if warmup or draws[s].rand() < agent.exploration_rate:
                    action = np.array([agent.action_space.sample()])
                else:
                    action = greedy[s]
                agent._explored = (action != greedy[s]) if flag else None
                new_obs, rewards, dones, infos = env.step(action)
                sb3.record_step(agent, action, new_obs, rewards, dones, infos)
            if sb3.calls(first) % syncs_every == 0:
                learner.sync_target()
            if step % train_every == 0 and first.num_timesteps > first.learning_starts:
                # gradient_steps = -1: as many as the env steps since the last training (SB3's rule).
                self._train(k, first.gradient_steps if first.gradient_steps >= 0 else train_every)
            if on_steps is not None:
                on_steps(self.n_members)
        for agent in agents:
            agent._explored = None

    def _update(self, k: int) -> None:
        """``update_steps`` gradient steps of every member's agent ``k`` without acting, the targets
        synced as often as during collection (``ExpectedSarsaDQN.update``)."""
        for chunk in self._agents(k)[0].update_chunks(self.cfg.training.update_steps):
            self._train(k, chunk)
            self.learners[k].sync_target()

    def _train(self, k: int, gradient_steps: int) -> None:
        """``gradient_steps`` stacked steps of every member's agent ``k``, logged as one
        ``ExpectedSarsaDQN.train`` call logs them: the updates so far, and the mean loss of the steps
        that updated."""
        agents = self._agents(k)
        losses: list[list[float]] = [[] for _ in agents]
        for _ in range(gradient_steps):
            loss, updated = self._train_step(k)
            for mine, value, took in zip(losses, loss.tolist(), updated.tolist(), strict=True):
                if took:
                    mine.append(value)
        for agent, mine in zip(agents, losses, strict=True):
            sb3.record_update(agent, float(np.mean(mine)) if mine else None)

    def _train_step(self, k: int) -> tuple[th.Tensor, th.Tensor]:
        """One stacked gradient step of every member's agent ``k`` on a batch from its own buffer;
        returns (S,) each member's loss and (S,) bool, which members updated."""
        agents, draws = self._agents(k), self.draws[k]
        first = agents[0]
        batches, demo_states, demo_actions = [], [], []
        for agent, draw in zip(agents, draws, strict=True):
            buffer = agent.replay_buffer
            upper = buffer.buffer_size if buffer.full else buffer.pos
            batches.append(sb3.samples_at(buffer, draw.randint(0, upper, size=first.batch_size)))
            if agent.n_demonstrations and agent.demo_loss_weight:
                index = th.as_tensor(draw.randint(0, agent.n_demonstrations, size=first.batch_size))
                demo_states.append(agent._demo_obs[index])
                demo_actions.append(agent._demo_actions[index])
        eps = th.tensor([agent.exploration_rate for agent in agents], dtype=th.float32, device=first.device)
        demos = (th.stack(demo_states), th.stack(demo_actions)) if demo_states else None
        losses, updated = self.learners[k].train_step(stack_samples(batches), eps, first.gamma, demos)
        for agent in agents:
            sb3.count_gradient_step(agent)
        return losses, updated

    def _write_back(self, k: int) -> None:
        """Every member's agent ``k`` gets its weights and Adam state from the stack."""
        learner = self.learners[k]
        adam = learner.optimizer
        for s, agent in enumerate(self._agents(k)):
            agent.q_net.load_state_dict(learner.q_net.member_state_dict(s))
            agent.q_net_target.load_state_dict(learner.q_net_target.member_state_dict(s))
            optimizer = agent.policy.optimizer
            if adam.steps[s] == 0:  # an agent that has taken no step has no Adam state yet
                continue
            stacked = learner.q_net
            for i, layer in enumerate(linear_layers(agent.q_net)):
                for mine, theirs in ((stacked.weights[i], layer.weight), (stacked.biases[i], layer.bias)):
                    optimizer.state[theirs] = adam.member_state(mine, s, tuple(theirs.shape))
