"""The rows of ``dospcot bench`` (:mod:`dospcot.experiment.bench`): each measures one of the project's
performance claims, ours and a peer's figure in the same run, with the measurement's median, min and
max over repetitions that alternate between the two."""

from __future__ import annotations

import math
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import DQN

from dospcot.config.learning_sections import TabularConfig
from dospcot.config.loading import load_config
from dospcot.config.run_configs import TrainConfig
from dospcot.core.cotraining_run import CoTrainingRun
from dospcot.envs import CLIFF_VIEWS, StateActionMask, ViewObservationWrapper
from dospcot.experiment.sweep import run_sweep
from dospcot.experiment.sweep_spec import SweepSpec
from dospcot.experiment.train import build_run
from dospcot.paper import protocol as paper
from dospcot.paper.tabular_cotraining import TabularCoTraining
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.tabular import TABULAR_KINDS, expected_value
from dospcot.seeding import agent_seed
from dospcot.tasks.grid import grid_world


@dataclass(frozen=True)
class Measurement:
    """Median, min and max of repeated measurements, in ``unit``."""

    median: float
    low: float
    high: float
    unit: str

    @classmethod
    def of(cls, values: list[float], unit: str) -> Measurement:
        """The median, min and max of repeated measurements ``values``, in ``unit``."""
        return cls(statistics.median(values), min(values), max(values), unit)

    @property
    def _format(self) -> str:
        return ",.0f" if self.median >= 100 else ".2f"

    @property
    def brief(self) -> str:
        """The median and the unit alone."""
        return f"{self.median:{self._format}} {self.unit}"

    def __str__(self) -> str:
        return f"{self.brief} [{self.low:{self._format}}, {self.high:{self._format}}]"


@dataclass(frozen=True)
class Row:
    """One benchmark: ours against the peer, their ratio and the target it should meet."""

    name: str
    setting: str
    ours: Measurement
    peer: Measurement
    higher_is_better: bool
    target: float

    @classmethod
    def measured(
        cls, name: str, setting: str, unit: str, ours: list[float], peer: list[float], **verdict: Any
    ) -> Row:
        """A row of the repetitions of ours and the peer, in ``unit``; ``verdict`` holds
        ``higher_is_better`` and ``target``."""
        return cls(name, setting, Measurement.of(ours, unit), Measurement.of(peer, unit), **verdict)

    @property
    def ratio(self) -> float:
        """Ours over the peer, of the medians (infinite over a peer of 0, which no target meets)."""
        return self.ours.median / self.peer.median if self.peer.median else math.inf

    @property
    def met(self) -> bool:
        """Whether the ratio meets the target (at least it, or at most it where lower is better)."""
        return self.ratio >= self.target if self.higher_is_better else self.ratio <= self.target


def _alternating(
    repeats: int, ours: Callable[[int], float], peer: Callable[[int], float]
) -> tuple[list[float], list[float]]:
    """``repeats`` measurements of ours and of the peer (each called with the repetition index),
    alternating which goes first, so drift in the machine's speed hits both alike."""
    results: tuple[list[float], list[float]] = ([], [])
    for rep in range(repeats):
        for side in (0, 1) if rep % 2 == 0 else (1, 0):
            results[side].append((ours, peer)[side](rep))
    return results


def onehot_cliff() -> gym.Env:
    """CliffWalking with one-hot observations, 100 steps an episode: the agent rows' task."""
    return ViewObservationWrapper(gym.make("CliffWalking-v1", max_episode_steps=100), CLIFF_VIEWS["onehot"])


class Clock:
    """Seconds spent between :meth:`start` and :meth:`stop`: the process's CPU time on the CPU (see
    NOTES), wall time on a GPU, whose work the CPU only queues (the GPU finishes its queue first)."""

    def __init__(self, device: str) -> None:
        self.device = device
        self._started = 0.0

    @property
    def unit(self) -> str:
        """``"CPU-s"`` or ``"s"``."""
        return "CPU-s" if self.device == "cpu" else "s"

    def _now(self) -> float:
        if self.device == "cpu":
            return time.process_time()
        torch.cuda.synchronize(self.device)
        return time.perf_counter()

    def start(self) -> None:
        """Start counting."""
        self._started = self._now()

    def stop(self) -> float:
        """The seconds since :meth:`start`."""
        return self._now() - self._started


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
    ours, peer = _alternating(
        repeats,
        lambda rep: _steps_per_second(ours_make, steps, rep, net, batch, device),
        lambda rep: _steps_per_second(DQN, steps, rep, net, batch, device),
    )
    return Row.measured(
        f"ExpectedSarsaDQN (target={target!r}"
        + (f", greedy={greedy!r}" if target == "expected_sarsa" else "")
        + ") vs SB3 DQN: env steps per second",
        f"CliffWalking-v1 one-hot, {steps:,} steps, MlpPolicy {net}, train_freq 4, batch {batch}",
        f"steps/{Clock(device).unit}", ours, peer, higher_is_better=True, target=0.95,
    )  # fmt: skip


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
    ours, peer = _alternating(
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
        "steps/s", ours, peer, higher_is_better=True, target=20.0,
    )  # fmt: skip


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
            "MlpPolicy", env, seed=agent_seed(cfg.seed, k), exploration_horizon=total,
            exploration_initial_eps=cfg.training.eps_start, exploration_final_eps=cfg.training.eps_end,
            exploration_fraction=1.0, **{**cfg.dqn.sb3_kwargs(), "buffer_size": cfg.buffer_size},
        )  # fmt: skip
        model.learning_starts = max(model.learning_starts, cfg.training.collect_only_steps)
        start = time.perf_counter()
        model.learn(total)
        seconds += time.perf_counter() - start
    return seconds


def bench_cotraining_overhead(quick: bool, repeats: int) -> Row:
    """Wall time of a DOSPCoT run over that of its agents trained alone for the same steps."""
    overrides = ["training.rounds=2", "training.steps_per_round=1000"] if quick else []
    cfg = load_config("grid16-dospcot", overrides)
    ours, peer = _alternating(
        repeats, lambda _: _cotraining_seconds(cfg), lambda _: _independent_seconds(cfg)
    )
    steps = cfg.training.rounds * cfg.training.steps_per_round
    return Row.measured(
        "DOSPCoT run vs its two ExpectedSarsaDQN agents alone: wall time",
        f"`grid16-dospcot` (patch + rays), {cfg.training.rounds} rounds, {steps:,} steps per agent",
        "s", ours, peer, higher_is_better=False, target=1.3,
    )  # fmt: skip


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
    ours, peer = _alternating(
        repeats, lambda _: _trials_per_minute(spec, 2), lambda _: _trials_per_minute(spec, 1)
    )
    trials = len(spec.configs) * len(gammas) * len(seeds)
    return Row.measured(
        "`dospcot sweep` local backend, 2 workers vs 1: throughput",
        f"{trials} trials of `tiny` (2 rounds x {steps:,} steps), process start-up included",
        "trials/min", ours, peer, higher_is_better=True, target=1.7,
    )  # fmt: skip


def _random_steps_per_second(env: gym.Env, steps: int, seed: int) -> float:
    env.action_space.seed(seed)
    env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def _fast_highway_steps_per_second(steps: int, n_envs: int, seed: int) -> float:
    from dospcot.envs.fast_highway import FastHighwayVec

    env = FastHighwayVec(n_envs, seed=seed)
    actions = np.random.default_rng(seed).integers(0, 5, (steps, n_envs))
    env.reset(seed=seed)
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    return steps * n_envs / (time.perf_counter() - start)


def _highway_env_steps_per_second(steps: int, seed: int) -> float:
    from dospcot.envs.highway import make_highway

    return _random_steps_per_second(make_highway("highway-fast-v0"), steps, seed)


def bench_fast_highway(quick: bool, repeats: int) -> Row:
    """Env steps per second with random actions: our vectorised highway env against highway-fast-v0."""
    n_envs, vec_steps, peer_steps = 64, (50 if quick else 500), (60 if quick else 600)
    ours, peer = _alternating(
        repeats,
        lambda rep: _fast_highway_steps_per_second(vec_steps, n_envs, rep),
        lambda rep: _highway_env_steps_per_second(peer_steps, rep),
    )
    return Row.measured(
        "FastHighwayVec vs highway-env's highway-fast-v0: env steps per second",
        f"random actions, resets included; ours {n_envs} envs x {vec_steps} steps, "
        f"highway-fast-v0 {peer_steps} steps (its Kinematics observation)",
        "steps/s", ours, peer, higher_is_better=True, target=50.0,
    )  # fmt: skip


def bench_minigrid_wrappers(quick: bool, repeats: int) -> Row:
    """Env steps per second with random actions: MiniGrid through what the ``minigrid-lavagap-dospcot``
    preset adds to every training step (the keyed reward mask, the first view observed, the pool
    store, which reads every view on a pair's first visit) against the bare MiniGrid env."""
    from dospcot.envs.gym_sensors import make_masked_gym
    from dospcot.tasks.sensor_store import KeyedStepStore, SensorStoreWrapper

    steps = 2_000 if quick else 20_000
    cfg = load_config("minigrid-lavagap-dospcot")
    assert isinstance(cfg, TrainConfig)
    # "module:id": gymnasium imports minigrid, which registers its ids, for both envs alike.
    env_id = cfg.gym.env_id
    views = {name: cfg.gym.views[name] for name in cfg.views}

    def ours(rep: int) -> gym.Env:
        env = make_masked_gym(
            env_id, cfg.views[0], tuple(views), cfg.training.label_fraction, rep, view_specs=views,
            state_key=cfg.gym.state_key,
        )  # fmt: skip
        shapes = {v: env.get_wrapper_attr("view_space")(v).shape for v in views}
        return SensorStoreWrapper(env, KeyedStepStore(shapes))

    ours_rate, peer = _alternating(
        repeats,
        lambda rep: _random_steps_per_second(ours(rep), steps, rep),
        lambda rep: _random_steps_per_second(gym.make(env_id), steps, rep),
    )
    return Row.measured(
        f"{env_id.split(':')[-1]} through dospcot's wrappers vs bare: env steps per second",
        f"random actions, resets included, {steps} steps; ours: reward mask over (state key, action) "
        f"pairs ({cfg.training.label_fraction:.0%}), the {cfg.views[0]} view observed, a fresh keyed "
        f"pool store recording every view ({', '.join(f'{n}: {v}' for n, v in views.items())}) of each "
        "new pair",
        "steps/s", ours_rate, peer, higher_is_better=True, target=round(1 / 1.3, 3),
    )  # fmt: skip


def _filled_run(n: int, seed: int) -> CoTrainingRun:
    """A `grid16-dospcot` co-trainer whose shared store holds ``n`` steps of a uniform random policy
    from uniformly drawn states, revealed by the run's mask."""
    cfg = load_config("grid16-dospcot", [f"seed={seed}"])
    run = build_run(cfg)
    mdp, rng = run.task.mdp, np.random.default_rng(seed)
    labelled = StateActionMask(mdp.n_states, mdp.n_actions, cfg.training.label_fraction, seed).labelled
    states, actions = rng.integers(0, mdp.n_states, n), rng.integers(0, mdp.n_actions, n)
    for s, a in zip(states.tolist(), actions.tolist(), strict=True):
        reward = float(mdp.reward[s, a])
        run.store.add(s, a, int(mdp.next_state[s, a]), bool(labelled[s, a]), reward, reward)
    return run


def _store_bytes(run: CoTrainingRun) -> int:
    """Bytes the shared store and the reward table hold."""
    arrays = [*run.store.state_dict().values(), *run.table.state_dict().values()]
    return sum(a.nbytes for a in arrays if isinstance(a, np.ndarray))


def _raw_bytes(run: CoTrainingRun, n: int) -> int:
    """Bytes of the raw arrays of ``n`` steps: each view's observation and next observation
    (float32), the action, the reward and the done flag."""
    width = sum(run.task.mdp.views[v].shape[1] for v in run.cfg.views)
    return n * (2 * width * 4 + 8 + 4 + 1)


def bench_store_memory(quick: bool, repeats: int) -> Row:
    """Memory of the shared transition store per million steps against the raw arrays of those steps."""
    n = 100_000 if quick else 1_000_000
    ours, peer = [], []
    for rep in range(repeats):
        run = _filled_run(n, rep)
        ours.append(_store_bytes(run) / n * 1e6 / 2**20)
        peer.append(_raw_bytes(run, n) / n * 1e6 / 2**20)
    views = " + ".join(f"{v} ({run.task.mdp.views[v].shape[1]} floats)" for v in run.cfg.views)
    return Row.measured(
        "Shared transition store vs the raw arrays: memory per million steps",
        f"16 x 16 grid, views {views}, {n:,} steps measured",
        "MiB", ours, peer, higher_is_better=False, target=1.5,
    )  # fmt: skip


SCALING_SIZES = (10_000, 30_000, 100_000, 300_000, 1_000_000)


def bench_cotraining_scaling(quick: bool, repeats: int) -> Row:
    """Wall time of one co-training step (select, fit, score, relabel) as the store grows, against
    n log n growth from the smallest size."""
    sizes = SCALING_SIZES[:3] if quick else SCALING_SIZES
    seconds: dict[int, list[float]] = {n: [] for n in sizes}
    for rep in range(repeats):
        for n in sizes:
            run = _filled_run(n, rep)
            start = time.perf_counter()
            run.cotrain()
            seconds[n].append(time.perf_counter() - start)
    small, large = sizes[0], sizes[-1]
    growth = [seconds[large][r] / seconds[small][r] for r in range(repeats)]
    bound = large * math.log(large) / (small * math.log(small))
    curve = ", ".join(f"{n:,}: {statistics.median(seconds[n]):.3f} s" for n in sizes)
    return Row.measured(
        f"One co-training step, {large:,} vs {small:,} stored steps: growth against n log n",
        f"`grid16-dospcot`, median seconds per size: {curve}",
        "x", growth, [bound] * repeats, higher_is_better=False, target=1.0,
    )  # fmt: skip
