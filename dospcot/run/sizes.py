"""What the machine can hold and finish, checked before anything starts: a config (or a batch of its
seeds, or a sweep of configs) whose work or memory is clearly beyond it is refused in one line naming
the estimate; one that would take long, or more workers than the cores, gets a one-line warning.

The estimates are rough, from measured rates (``BENCHMARKS.md``), and said to be estimates: they are
there to catch a slipped digit (``--seeds 100000000``, ``training.steps_per_round=1000000000000``), so
a refusal needs an estimate far beyond any study's, and the shipped presets and studies all pass.
Nothing here imports torch.
"""

from __future__ import annotations

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
TABULAR_STEPS_PER_SECOND = 1_150_000
"""Agent steps per second of the paper protocol's batched tabular agents (BENCHMARKS.md)."""
PAPER_RUNS_PER_SEED = 26
"""The runs of the paper protocol per seed, two agents each (``dospcot/run/paper_protocol.py``)."""
PAPER_MIN_EPISODE_STEPS = 13
"""CliffWalking's shortest episode: a lower bound on an episode's steps."""
TRANSITION_MIN_BYTES = 24
"""A lower bound on one replayed transition: two one-number observations, the action, the reward and
the end flag."""
MAX_SEEDS = 10_000
"""More seeds than this (a run folder each) is refused: no study uses more than a few dozen."""
REFUSE_RUN_CPU_SECONDS = 365 * 86_400
"""One seed's run beyond a CPU-year (one process, mostly one core) cannot finish: it is refused."""
REFUSE_CPU_SECONDS = 100 * 365 * 86_400
"""Work beyond 100 CPU-years, over all seeds, cannot finish: it is refused."""
WARN_CPU_SECONDS = 7 * 86_400
"""Work beyond a CPU-week is warned of: it starts, but the line says how long it may take."""


def _cotraining_seconds(cfg: TrainConfig) -> tuple[float, str]:
    steps = cfg.training.total_steps * len(cfg.agent_kinds)
    how = f"{steps:,} agent steps at about {DQN_STEPS_PER_CPU_SECOND:,}/CPU-s"
    return steps / DQN_STEPS_PER_CPU_SECOND, how


def _paper_seconds(cfg: PaperConfig) -> tuple[float, str]:
    tab = cfg.tabular
    steps = tab.rounds * tab.episodes_per_round * PAPER_RUNS_PER_SEED * 2 * PAPER_MIN_EPISODE_STEPS
    return steps / TABULAR_STEPS_PER_SECOND, f"at least {TABULAR_STEPS_PER_SECOND:,} agent steps/s"


@dataclass(frozen=True)
class SizeRule:
    """How one kind of config is weighed (the run layer's choice by the config's type, as its runner).

    :param cpu_seconds: the estimated CPU-seconds of one seed, and how the estimate was made.
    :param lower: the keys a refusal says to lower.
    :param memory: refuses (``ConfigError``) what a batch of this many seeds cannot hold in memory
        (None: nothing to weigh).
    """

    cpu_seconds: Callable[[Any], tuple[float, str]]
    lower: str
    memory: Callable[[Any, int], None] | None = None


def cpu_seconds(cfg: RunConfig) -> tuple[float, str]:
    """The estimated CPU-seconds of one seed of ``cfg``, and how the estimate was made."""
    return RULES[type(cfg)].cpu_seconds(cfg)


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

    :param cfgs: the configs that train (a sweep's cells), each over ``seeds`` seeds.
    :param workers: processes at once (``--workers``), warned of above the cores this process may use.
    :param batch: seeds trained together in one process (``--seeds`` of train, ``--batch-seeds``).
    :raises ConfigError: more than :data:`MAX_SEEDS` seeds, a run beyond :data:`REFUSE_RUN_CPU_SECONDS`,
        work beyond :data:`REFUSE_CPU_SECONDS`,
        or replay buffers or a batch beyond the machine's memory.
    """
    if seeds > MAX_SEEDS:
        total = sum(cpu_seconds(cfg)[0] for cfg in cfgs) * seeds
        cost = f"would take about {duration(total)} (an estimate) and make" if cfgs else "would make"
        raise ConfigError(f"{seeds:,} seeds {cost} a run folder each; give at most {MAX_SEEDS:,}")
    warnings = []
    total = 0.0
    for cfg in cfgs:
        each, how = cpu_seconds(cfg)
        total += each * seeds
        if each > REFUSE_RUN_CPU_SECONDS:
            raise ConfigError(
                f"{cfg.name}: one seed would take about {duration(each)} (an estimate: {how}); "
                f"lower {RULES[type(cfg)].lower}"
            )
        memory = RULES[type(cfg)].memory
        if memory is not None:
            memory(cfg, batch)
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


def _cotraining_memory(cfg: TrainConfig, batch: int) -> None:
    memory = memory_bytes()
    neural = sum(kind != "tabular" for kind in cfg.agent_kinds)
    tabular = len(cfg.agent_kinds) - neural
    capacity = neural * cfg.buffer_size + tabular * min(
        cfg.tabular_agent.buffer_size, cfg.training.total_steps
    )
    need = capacity * TRANSITION_MIN_BYTES * batch
    if need > memory:
        raise ConfigError(
            f"{cfg.name}: the replay buffers would need at least {need / 2**30:,.0f} GiB (an estimate: "
            f"{capacity:,} transitions x {batch} seeds x {TRANSITION_MIN_BYTES} bytes), and this machine has "
            f"{memory / 2**30:,.0f} GiB; lower dqn.buffer_size"
        )
    width = sum(cfg.dqn.net_arch) or 1
    batch_bytes = cfg.dqn.batch_size * width * 4 * 2 * batch * max(neural, 1)
    if neural and batch_bytes > memory:
        raise ConfigError(
            f"{cfg.name}: a batch of dqn.batch_size = {cfg.dqn.batch_size:,} would need at least "
            f"{batch_bytes / 2**30:,.0f} GiB (an estimate: its activations), and this machine has "
            f"{memory / 2**30:,.0f} GiB; lower dqn.batch_size"
        )


RULES: dict[type, SizeRule] = {
    TrainConfig: SizeRule(
        _cotraining_seconds, "training.rounds or training.steps_per_round", _cotraining_memory
    ),
    PaperConfig: SizeRule(_paper_seconds, "tabular.rounds or tabular.episodes_per_round"),
}
"""How each kind of config is weighed, by its type."""
