"""What the machine can hold and finish, checked before anything starts: a config (or a batch of its
seeds, or a sweep of configs) whose work or memory is clearly beyond it is refused in one line naming
the estimate; one that would take long, or more workers than the cores, gets a one-line warning.

The estimates are rough, from measured rates (``BENCHMARKS.md``), and said to be estimates: they are
there to catch a slipped digit (``--seeds 100000000``, ``training.steps_per_round=1000000000000``), so
a refusal needs an estimate far beyond any study's, and the shipped presets and studies all pass.
Nothing here imports torch.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from dospcot.config.errors import ConfigError
from dospcot.config.run_configs import PaperConfig, RunConfig, TrainConfig
from dospcot.run.cores import usable_cores

DQN_STEPS_PER_CPU_SECOND = 2_500
"""Env steps one ``ExpectedSarsaDQN`` agent takes per CPU-second (BENCHMARKS.md: about 2,465 on
CliffWalking with a [64, 64] network, one torch thread); larger networks and envs are slower."""
GRADIENT_STEP_SECONDS = 1e-4
"""A lower bound on one gradient step of a neural agent (a replayed batch through the network and
back, and an optimiser step) beyond those the env-step rate already holds."""
CLASSIFIER_EPOCH_SECONDS = 1e-4
"""A lower bound on one full-batch epoch of a reward classifier (forward, backward, Adam)."""
FLOPS_PER_CPU_SECOND = 2e10
"""An upper bound on one core's multiply-adds per second: work counted in them is a lower bound on time."""
TABULAR_UPDATES_PER_SECOND = 2_000_000
"""An upper bound on a tabular agent's replayed sample updates per second."""
TABULAR_STEPS_PER_SECOND = 1_150_000
"""Agent steps per second of the paper protocol's batched tabular agents (BENCHMARKS.md)."""
PAPER_RUNS_PER_SEED = 26
"""The runs of the paper protocol per seed, two agents each (``dospcot/run/paper_protocol.py``)."""
PAPER_MIN_EPISODE_STEPS = 13
"""CliffWalking's shortest episode: a lower bound on an episode's steps."""
PAPER_KEYS = 48 * 4
"""CliffWalking's (state, action) keys: the paper protocol's pool and its replay sweeps' size."""
ACTIVATION_BYTES = 64
"""A reward classifier's bytes per sample and unit of its hidden and output layers while it fits
(float32 activations, their gradients and the copies of a batched ensemble)."""
TRANSITION_MIN_BYTES = 24
"""A lower bound on one replayed transition: two one-number observations, the action, the reward and
the end flag."""
MAX_SEEDS = 10_000
"""More seeds than this (a run folder each) is refused: no study uses more than a few dozen."""
REFUSE_RUN_CPU_SECONDS = 3 * 86_400
"""One seed's run estimated beyond 3 CPU-days is refused unless :data:`RUN_LIMIT_VARIABLE` raises the
bound: the longest run the record holds took under half a CPU-hour, so such an estimate is a slipped
digit far more often than a wish."""
RUN_LIMIT_VARIABLE = "DOSPCOT_MAX_RUN_CPU_DAYS"
"""The environment variable that sets the per-seed bound, in CPU-days, in place of
:data:`REFUSE_RUN_CPU_SECONDS`."""
REFUSE_CPU_SECONDS = 100 * 365 * 86_400
"""Work beyond 100 CPU-years, over all seeds, cannot finish: it is refused."""
WARN_CPU_SECONDS = 7 * 86_400
"""Work beyond a CPU-week is warned of: it starts, but the line says how long it may take."""


@dataclass(frozen=True)
class Cost:
    """One part of a seed's estimated CPU time: ``seconds``, the ``keys`` that scale it, and ``how``
    the estimate was made (words for a refusal)."""

    seconds: float
    keys: str
    how: str


def _mlp_multiply_adds(widths: Sequence[int]) -> int:
    """The multiply-adds of one sample through a network of layer widths ``widths``."""
    return sum(a * b for a, b in itertools.pairwise(widths))


def _cotraining_costs(cfg: TrainConfig) -> list[Cost]:
    """Every part of one seed's CPU time that a key of ``cfg`` scales."""
    training, dqn = cfg.training, cfg.dqn
    agents = len(cfg.agent_kinds)
    neural = sum(kind != "tabular" for kind in cfg.agent_kinds)
    steps = training.total_steps * agents
    costs = [
        Cost(
            steps / DQN_STEPS_PER_CPU_SECOND,
            "training.rounds or training.steps_per_round",
            f"{steps:,} agent steps at about {DQN_STEPS_PER_CPU_SECOND:,}/CPU-s",
        )
    ]
    per_update = dqn.train_freq if dqn.gradient_steps == -1 else dqn.gradient_steps
    gradient_steps = neural * (
        training.total_steps // dqn.train_freq * per_update + training.rounds * training.update_steps
    )
    # A batch through the network and back, n-step windows read in full: about 3 passes of each sample.
    flops = 3 * dqn.batch_size * dqn.n_steps * _mlp_multiply_adds([1, *dqn.net_arch, 1])
    costs.append(
        Cost(
            gradient_steps * max(GRADIENT_STEP_SECONDS, flops / FLOPS_PER_CPU_SECOND),
            "dqn.gradient_steps, training.update_steps, dqn.batch_size or dqn.net_arch",
            f"{gradient_steps:,} gradient steps of a batch of {dqn.batch_size:,}",
        )
    )
    tab = cfg.tabular_agent
    tabular = agents - neural
    updates = tabular * training.total_steps // tab.train_freq * tab.gradient_steps
    updates *= tab.batch_size * tab.n_steps
    costs.append(
        Cost(
            updates / TABULAR_UPDATES_PER_SECOND,
            "tabular_agent.gradient_steps, tabular_agent.batch_size or tabular_agent.n_steps",
            f"{updates:,} tabular sample updates at {TABULAR_UPDATES_PER_SECOND:,}/s",
        )
    )
    if cfg.learns_rewards:
        members = cfg.cotraining.ensemble_size if cfg.method == "reward-model" else 1
        classifier = cfg.cotraining.classifier
        epochs = training.rounds * len(cfg.views) * members * classifier.epochs
        costs.append(
            Cost(
                epochs * max(CLASSIFIER_EPOCH_SECONDS, _classifier_multiply_adds(cfg) / FLOPS_PER_CPU_SECOND),
                "cotraining.classifier.epochs, cotraining.ensemble_size, cotraining.max_classes or "
                "cotraining.classifier.hidden",
                f"{epochs:,} classifier epochs",
            )
        )
    section, name = _task_section(cfg)
    # Evaluation episodes every round and agent (one greedy episode where the section sets no number),
    # and the demonstrations' episodes, each at most the section's episode length.
    eval_steps = training.rounds * agents * getattr(section, "eval_episodes", 1) * section.episode_steps
    costs.append(
        Cost(
            eval_steps / DQN_STEPS_PER_CPU_SECOND,
            f"{name}.eval_episodes or {name}.episode_steps",
            f"{eval_steps:,} evaluation steps",
        )
    )
    demo_steps = cfg.demonstrations.episodes * section.episode_steps
    costs.append(
        Cost(
            demo_steps / DQN_STEPS_PER_CPU_SECOND,
            "demonstrations.episodes",
            f"{demo_steps:,} demonstration steps",
        )
    )
    return costs


def _task_section(cfg: TrainConfig) -> tuple[Any, str]:
    """The section that sets up the run's task (``[env]``, ``[highway]``, ``[gym]``) and its name."""
    from dospcot.tasks import get_task

    name = get_task(cfg.task).section
    return getattr(cfg, name), name


def _classes(cfg: TrainConfig) -> int:
    """K, the reward classes a run's classifiers output: the task section's ``reward_classes`` where it
    sets them (quantile bins of a continuous reward), else ``cotraining.max_classes``."""
    return getattr(_task_section(cfg)[0], "reward_classes", cfg.cotraining.max_classes)


def _pool_samples(cfg: TrainConfig) -> int:
    """A lower bound on a classifier's samples after round 1: one round's steps of one agent, or the
    task's keys where fewer (:meth:`~dospcot.tasks.registry.Task.pool_keys`)."""
    from dospcot.tasks import get_task

    keys = get_task(cfg.task).pool_keys(cfg)
    samples = cfg.training.steps_per_round
    return samples if keys is None else min(samples, keys)


def _classifier_multiply_adds(cfg: TrainConfig) -> int:
    """A lower bound on one classifier epoch's multiply-adds: :func:`_pool_samples` through a net of
    one input."""
    samples = _pool_samples(cfg)
    hidden = cfg.cotraining.classifier.hidden if cfg.cotraining.classifier.model == "mlp" else 0
    return 3 * samples * _mlp_multiply_adds([1, hidden, _classes(cfg)] if hidden else [1, _classes(cfg)])


def _paper_costs(cfg: PaperConfig) -> list[Cost]:
    tab = cfg.tabular
    steps = tab.rounds * tab.episodes_per_round * PAPER_RUNS_PER_SEED * 2 * PAPER_MIN_EPISODE_STEPS
    sweeps = tab.rounds * tab.replay_sweeps * PAPER_RUNS_PER_SEED * 2 * PAPER_KEYS
    epochs = tab.rounds * PAPER_RUNS_PER_SEED * 2 * tab.cotraining.classifier.epochs
    return [
        Cost(
            steps / TABULAR_STEPS_PER_SECOND,
            "tabular.rounds or tabular.episodes_per_round",
            f"at least {TABULAR_STEPS_PER_SECOND:,} agent steps/s",
        ),
        Cost(
            sweeps / TABULAR_UPDATES_PER_SECOND,
            "tabular.replay_sweeps",
            f"{sweeps:,} replayed key updates at {TABULAR_UPDATES_PER_SECOND:,}/s",
        ),
        Cost(
            epochs * CLASSIFIER_EPOCH_SECONDS,
            "tabular.cotraining.classifier.epochs",
            f"{epochs:,} classifier epochs",
        ),
    ]


@dataclass(frozen=True)
class SizeRule:
    """How one kind of config is weighed (the run layer's choice by the config's type, as its runner).

    :param costs: every part of one seed's estimated CPU time, each with the keys that scale it.
    :param memory: refuses (``ConfigError``) what a batch of this many seeds cannot hold in memory.
    """

    costs: Callable[[Any], list[Cost]]
    memory: Callable[[Any, int], None]


def cpu_seconds(cfg: RunConfig) -> tuple[float, str]:
    """The estimated CPU-seconds of one seed of ``cfg``, and how its largest part was estimated."""
    costs = RULES[type(cfg)].costs(cfg)
    return sum(c.seconds for c in costs), max(costs, key=lambda c: c.seconds).how


def run_limit_seconds() -> float:
    """The most CPU-seconds one seed's run may be estimated at: :data:`RUN_LIMIT_VARIABLE`'s CPU-days,
    where set, else :data:`REFUSE_RUN_CPU_SECONDS`.

    :raises ConfigError: the variable is set to no positive number.
    """
    text = os.environ.get(RUN_LIMIT_VARIABLE, "").strip()
    if not text:
        return REFUSE_RUN_CPU_SECONDS
    try:
        days = float(text)
    except ValueError:
        days = float("nan")
    if not 0 < days < float("inf"):
        raise ConfigError(f"{RUN_LIMIT_VARIABLE}={text}: give the most CPU-days one seed may take, e.g. 30")
    return days * 86_400


def duration(seconds: float) -> str:
    """``seconds`` of CPU time in the largest unit that keeps it above 1, e.g. ``"3.2 CPU-days"``."""
    for unit, size in (("CPU-years", 365 * 86_400), ("CPU-days", 86_400), ("CPU-hours", 3_600)):
        if seconds >= size:
            return (
                f"{seconds / size:,.0f} {unit}" if seconds >= 100 * size else f"{seconds / size:.1f} {unit}"
            )
    return f"{seconds / 60:.1f} CPU-minutes"


def memory_bytes() -> int:
    """The machine's memory."""
    return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def check_sizes(
    cfgs: Sequence[RunConfig], seeds: int = 1, workers: int | None = None, batch: int = 1
) -> list[str]:
    """Refuse what the machine cannot finish or hold; return the warnings (one line each).

    Every key that scales a run's time or memory enters an estimate (:func:`cpu_seconds`, the rules'
    memory checks), so a slipped digit in any of them is refused before anything is written.

    :param cfgs: the configs that train (a sweep's cells), each over ``seeds`` seeds.
    :param workers: processes at once (``--workers``), warned of above the cores this process may use.
    :param batch: seeds trained together in one process (``--seeds`` of train, ``--batch-seeds``).
    :raises ConfigError: more than :data:`MAX_SEEDS` seeds, a run beyond :func:`run_limit_seconds`,
        work beyond :data:`REFUSE_CPU_SECONDS`, or what a batch of seeds needs beyond the machine's memory.
    """
    if seeds > MAX_SEEDS:
        total = sum(cpu_seconds(cfg)[0] for cfg in cfgs) * seeds
        cost = f"would take about {duration(total)} (an estimate) and make" if cfgs else "would make"
        raise ConfigError(f"{seeds:,} seeds {cost} a run folder each; give at most {MAX_SEEDS:,}")
    warnings = []
    total = 0.0
    limit = run_limit_seconds() if cfgs else REFUSE_RUN_CPU_SECONDS
    for cfg in cfgs:
        RULES[type(cfg)].memory(cfg, batch)  # what cannot be held is refused whatever it would cost
        costs = RULES[type(cfg)].costs(cfg)
        each = sum(c.seconds for c in costs)
        total += each * seeds
        if each > limit:
            top = max(costs, key=lambda c: c.seconds)
            raise ConfigError(
                f"{cfg.name}: one seed would take about {duration(each)} (an estimate: {top.how}), more "
                f"than the {duration(limit)} a run may; lower {top.keys}, or allow more: "
                f"{RUN_LIMIT_VARIABLE}=<CPU-days> in the environment"
            )
    if total > REFUSE_CPU_SECONDS:
        raise ConfigError(f"{seeds:,} seeds would take about {duration(total)} (an estimate); give fewer")
    if total > WARN_CPU_SECONDS:
        warnings.append(
            f"this would take about {duration(total)} of CPU time (an estimate from BENCHMARKS.md's rates); "
            "it starts anyway"
        )
    cores = usable_cores()
    if workers is not None and workers > cores:
        warnings.append(
            f"--workers {workers} is above the {cores} cores this process may use: the workers share them"
        )
    return warnings


def _refuse_memory(cfg: RunConfig, what: str, need: float, how: str, lower: str) -> None:
    memory = memory_bytes()
    if need > memory:
        raise ConfigError(
            f"{cfg.name}: {what} would need at least {need / 2**30:,.0f} GiB (an estimate: {how}), and this "
            f"machine has {memory / 2**30:,.0f} GiB; lower {lower}"
        )


def _cotraining_memory(cfg: TrainConfig, batch: int) -> None:
    neural = sum(kind != "tabular" for kind in cfg.agent_kinds)
    tabular = len(cfg.agent_kinds) - neural
    capacity = neural * cfg.buffer_size + tabular * min(
        cfg.tabular_agent.buffer_size, cfg.training.total_steps
    )
    _refuse_memory(
        cfg,
        "the replay buffers",
        capacity * TRANSITION_MIN_BYTES * batch,
        f"{capacity:,} transitions x {batch} seeds x {TRANSITION_MIN_BYTES} bytes",
        "dqn.buffer_size",
    )
    width = sum(cfg.dqn.net_arch) or 1
    batch_bytes = cfg.dqn.batch_size * width * 4 * 2 * batch * max(neural, 1)
    if neural:
        _refuse_memory(
            cfg,
            f"a batch of dqn.batch_size = {cfg.dqn.batch_size:,}",
            batch_bytes,
            "its activations",
            "dqn.batch_size",
        )
        # Weights, gradients and Adam's two moments, of the Q-network and its target.
        params = _mlp_multiply_adds([1, *cfg.dqn.net_arch, 1])
        _refuse_memory(
            cfg,
            f"the Q-networks of dqn.net_arch = {list(cfg.dqn.net_arch)}",
            params * 4 * 5 * neural * batch,
            f"{params:,} weights x {neural} agents x {batch} seeds, 20 bytes each",
            "dqn.net_arch",
        )
    if cfg.learns_rewards:
        members = cfg.cotraining.ensemble_size if cfg.method == "reward-model" else 1
        classifier = cfg.cotraining.classifier
        hidden = classifier.hidden if classifier.model == "mlp" else 0
        params = _mlp_multiply_adds([1, hidden, _classes(cfg)] if hidden else [1, _classes(cfg)])
        classifiers = len(cfg.views) * members * batch
        lower = "cotraining.max_classes, cotraining.classifier.hidden or cotraining.ensemble_size"
        _refuse_memory(
            cfg,
            "the reward classifiers",
            params * 4 * 4 * classifiers,
            f"{classifiers:,} classifiers of {params:,} weights, 16 bytes each (Adam's moments included)",
            lower,
        )
        # Each classifier's activations over the pool: measured at about 3 KiB a sample of a [32] net.
        width = hidden + _classes(cfg)
        samples = _pool_samples(cfg)
        _refuse_memory(
            cfg,
            "the reward classifiers' activations",
            classifiers * samples * width * ACTIVATION_BYTES,
            f"{classifiers:,} classifiers x {samples:,} samples x {width:,} units x {ACTIVATION_BYTES} bytes",
            lower,
        )


def _paper_memory(cfg: PaperConfig, batch: int) -> None:
    classifier = cfg.tabular.cotraining.classifier
    hidden = classifier.hidden if classifier.model == "mlp" else 0
    classes = cfg.tabular.cotraining.max_classes
    params = _mlp_multiply_adds([1, hidden, classes] if hidden else [1, classes])
    classifiers = PAPER_RUNS_PER_SEED * 2 * batch
    _refuse_memory(
        cfg,
        "the reward classifiers",
        params * 4 * 4 * classifiers,
        f"{classifiers:,} classifiers of {params:,} weights, 16 bytes each (Adam's moments included)",
        "tabular.cotraining.max_classes or tabular.cotraining.classifier.hidden",
    )


RULES: dict[type, SizeRule] = {
    TrainConfig: SizeRule(_cotraining_costs, _cotraining_memory),
    PaperConfig: SizeRule(_paper_costs, _paper_memory),
}
"""How each kind of config is weighed, by its type."""
