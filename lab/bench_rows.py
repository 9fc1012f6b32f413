"""The rows of ``dospcot-lab bench`` (:mod:`dospcot_lab.bench`): each measures one of the project's
performance claims, ours and a peer's figure in the same run, with the measurement's median, min and
max over repetitions that alternate between the two."""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3 import DQN

from dospcot.config.paper_sections import TabularConfig
from dospcot.config.run_configs import TrainConfig
from dospcot.core.tabular_runs import TabularCoTraining
from dospcot.envs import ViewObservationWrapper
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.tabular import TABULAR_KINDS, expected_value
from dospcot.run import paper_protocol as paper
from dospcot.run.sb3_runs import build_run
from dospcot.seeding import agent_seed
from dospcot.sweeps.sweep import run_sweep
from dospcot.sweeps.sweep_spec import SweepSpec
from dospcot.tasks import load_config
from dospcot.tasks.grid import grid_world
from dospcot_lab.bench_measure import Clock, Row, alternating, onehot_cliff


def _steps_per_second(
    make: Callable[..., DQN], steps: int, seed: int, net: list[int], batch: int, device: str
) -> float:
    model = make(
        "MlpPolicy",
        onehot_cliff(),
        learning_starts=500,
        train_freq=4,
        gradient_steps=1,
        batch_size=batch,
        buffer_size=50_000,
        policy_kwargs={"net_arch": net},
        seed=seed,
        device=device,
    )
    clock = Clock(device)
    clock.start()
    model.learn(steps)
    return steps / clock.stop()


def bench_esarsa_dqn(
    steps: int,
    repeats: int,
    net: list[int],
    batch: int,
    target: str = "expected_sarsa",
    greedy: str = "target",
    device: str = "cpu",
) -> Row:
    """Env steps per second of ExpectedSarsaDQN against SB3 DQN with identical settings, both on
    ``device``."""
    ours_make = partial(ExpectedSarsaDQN, target=target, greedy=greedy)
    ours, peer = alternating(
        repeats,
        lambda rep: _steps_per_second(ours_make, steps, rep, net, batch, device),
        lambda rep: _steps_per_second(DQN, steps, rep, net, batch, device),
    )
    return Row.measured(
        f"ExpectedSarsaDQN (target={target!r}"
        + (f", greedy={greedy!r}" if target == "expected_sarsa" else "")
        + ") vs SB3 DQN: env steps per second",
        f"CliffWalking-v1 one-hot, {steps:,} steps, MlpPolicy {net}, train_freq 4, batch {batch}",
        f"steps/{Clock(device).unit}",
        ours,
        peer,
        higher_is_better=True,
        target=0.95,
    )


class PerStepTabularCoTraining(TabularCoTraining):
    """The tabular row's reference: the same rounds, with collection as a plain Python loop, one agent
    and one step at a time, of the same epsilon-greedy choice and weighted TD update.

    It reads the same per-agent uniform streams (:meth:`TabularAgents.draw`) and the same run store as
    :class:`TabularCoTraining`, so both end with the same Q-tables (a test checks this).
    """

    def _collect(self, progress: Callable[[int], None] | None) -> None:
        run_eps = self.eps()
        for slot, run in enumerate(self.slot_run):
            if self.active[run]:
                self._collect_agent(slot, int(run), float(run_eps[run]), progress)

    def _collect_agent(self, slot: int, run: int, eps: float, progress: Callable[[int], None] | None) -> None:
        mdp, agents = self.mdp, self.agents
        q, kind, me = agents.q[slot], TABULAR_KINDS[agents.kind[slot]], np.array([slot])

        def act(state: int) -> int:
            explore, pick = agents.draw(me)[0]
            if explore < eps:
                return min(int(pick * mdp.n_actions), mdp.n_actions - 1)
            row = q[state]
            ties = np.flatnonzero(row == row.max())
            return int(ties[min(int(pick * len(ties)), len(ties) - 1)])

        for _ in range(self.config.episodes_per_round):
            s = mdp.start_state
            a = act(s)
            for _ in range(mdp.max_episode_steps):
                self.env_steps += 1
                s2, terminated = int(mdp.next_state[s, a]), bool(mdp.terminal[s, a])
                if self.labelled[run, s, a]:
                    reward, weight = float(mdp.reward[s, a]), 1.0
                    self.label_value[run, s, a] = reward
                else:
                    reward, weight = self.table_reward[run, s, a], self.table_weight[run, s, a]
                self.visited[run, s, a] = True
                self.stored_next[run, s, a], self.stored_terminal[run, s, a] = s2, terminated
                a2 = act(s2)
                if kind == "q":
                    value = q[s2].max()
                elif kind == "sarsa":
                    value = q[s2, a2]
                else:
                    value = expected_value(q[s2], np.float64(eps))
                target = reward + agents.discount * (not terminated) * value
                q[s, a] += agents.learning_rate * weight * (target - q[s, a])
                s, a = s2, a2
                if terminated:
                    break
            if progress is not None:
                progress(1)


def _collection_steps_per_second(
    cls: type[TabularCoTraining], seeds: list[int], config: TabularConfig
) -> float:
    """Agent steps per second of the collection phase (acting and online TD updates, summed over
    agents) over a paper-protocol run of ``seeds``; co-training and replay sweeps are not timed."""

    class Timed(cls):
        collect_seconds = 0.0

        def _collect(self, progress: Callable[[int], None] | None) -> None:
            start = time.perf_counter()
            super()._collect(progress)
            self.collect_seconds += time.perf_counter() - start

    trainer = Timed(paper.cliffwalking_mdp(config.label_fraction), paper.protocol_specs(seeds), config)
    trainer.run()
    return trainer.env_steps / trainer.collect_seconds


def bench_tabular(quick: bool, repeats: int) -> Row:
    """The paper protocol's agents: vectorised over every run at once against a per-step Python loop."""
    seeds = [0, 1] if quick else list(range(10))
    quick_settings = ["tabular.rounds=2", "tabular.episodes_per_round=10"] if quick else []
    config = load_config("paper-text", quick_settings).tabular
    ours, peer = alternating(
        repeats,
        lambda _: _collection_steps_per_second(TabularCoTraining, seeds, config),
        lambda _: _collection_steps_per_second(PerStepTabularCoTraining, seeds[:1], config),
    )
    return Row.measured(
        "Tabular agents, vectorised vs a per-step Python loop: agent steps per second",
        f"paper protocol (CliffWalking, {config.rounds} rounds x {config.episodes_per_round} episodes, "
        "`paper-text`); ours: "
        f"seeds {seeds[0]}-{seeds[-1]} in one batch ({len(paper.protocol_specs(seeds))} runs), the loop: "
        f"seed {seeds[0]} ({len(paper.protocol_specs(seeds[:1]))} runs)",
        "steps/s",
        ours,
        peer,
        higher_is_better=True,
        target=20.0,
    )


def _cotraining_seconds(cfg: TrainConfig) -> float:
    run = build_run(cfg)
    start = time.perf_counter()
    run.run()
    return time.perf_counter() - start


def _independent_seconds(cfg: TrainConfig) -> float:
    """The peer: each view's agent alone, the same env stack, DQN kwargs and steps, no co-training."""
    make_env, views, _ = grid_world(cfg)
    total = cfg.training.rounds * cfg.training.steps_per_round
    limit = cfg.env.train_episode_steps or cfg.env.episode_steps
    seconds = 0.0
    for k, view in enumerate(cfg.views):
        env = ViewObservationWrapper(gym.wrappers.TimeLimit(make_env(), limit), views[view])
        model = ExpectedSarsaDQN(
            "MlpPolicy",
            env,
            seed=agent_seed(cfg.seed, k),
            exploration_horizon=total,
            exploration_initial_eps=cfg.training.eps_start,
            exploration_final_eps=cfg.training.eps_end,
            exploration_fraction=1.0,
            **{**cfg.dqn.sb3_kwargs(), "buffer_size": cfg.buffer_size},
        )
        model.learning_starts = max(model.learning_starts, cfg.training.collect_only_steps)
        start = time.perf_counter()
        model.learn(total)
        seconds += time.perf_counter() - start
    return seconds


def bench_cotraining_overhead(quick: bool, repeats: int) -> Row:
    """Wall time of a DOSPCoT run over that of its agents trained alone for the same steps."""
    overrides = ["training.rounds=2", "training.steps_per_round=1000"] if quick else []
    cfg = load_config("grid16-dospcot", overrides)
    ours, peer = alternating(repeats, lambda _: _cotraining_seconds(cfg), lambda _: _independent_seconds(cfg))
    steps = cfg.training.rounds * cfg.training.steps_per_round
    return Row.measured(
        "DOSPCoT run vs its two ExpectedSarsaDQN agents alone: wall time",
        f"`grid16-dospcot` (patch + rays), {cfg.training.rounds} rounds, {steps:,} steps per agent",
        "s",
        ours,
        peer,
        higher_is_better=False,
        target=1.3,
    )


def _trials_per_minute(spec: SweepSpec, workers: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        result = run_sweep(Path(tmp) / "sweep", spec, workers=workers, show_progress=False)
        seconds = time.perf_counter() - start
    if result.failed:
        raise RuntimeError(f"benchmark sweep trials failed: {result.failed}")
    return len(result.trials) / seconds * 60


def bench_sweep_throughput(quick: bool, repeats: int) -> Row:
    """Trials per minute of ``dospcot sweep``'s local backend with 2 worker processes against 1."""
    # Trials of about 10 s: worker start-up (spawn, importing torch and SB3: seconds) is paid once per
    # pool, and with trials of a few seconds it would be most of what the row measures.
    steps = 300 if quick else 4_000
    gammas = ("0", "0.3") if quick else ("0", "0.1", "0.3", "1")
    seeds = (0,) if quick else (0, 1)
    grid = {"cotraining.consensus_weight": gammas}
    spec = SweepSpec(("tiny",), grid, seeds, (f"training.steps_per_round={steps}",))
    ours, peer = alternating(
        repeats, lambda _: _trials_per_minute(spec, 2), lambda _: _trials_per_minute(spec, 1)
    )
    trials = len(spec.configs) * len(gammas) * len(seeds)
    return Row.measured(
        "`dospcot sweep` local backend, 2 workers vs 1: throughput",
        f"{trials} trials of `tiny` (2 rounds x {steps:,} steps), process start-up included",
        "trials/min",
        ours,
        peer,
        higher_is_better=True,
        target=1.7,
    )
