"""How each kind of config trains in its run folder: the run layer's choice by the config's type, so a
task spec never says how its runs train.

- a :class:`~dospcot.config.run_configs.TrainConfig` (every task but the paper's): a co-training run
  of SB3 agents, checkpointed every round (:mod:`dospcot.run.sb3_runs`);
- a :class:`~dospcot.config.run_configs.PaperConfig`: one seed of the seed paper's tabular protocol,
  several seeds of which a sweep trains together in one process (:mod:`dospcot.run.paper_protocol`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from dospcot.config.run_configs import PaperConfig, RunConfig, TrainConfig
from dospcot.run.paper_protocol import PaperProtocolRunner
from dospcot.run.sb3_runs import CoTrainingRunner


class Runner(Protocol):
    """How one kind of config trains, resumes and evaluates in its run folder."""

    def train_at(self, run_dir: Path, cfg: Any, *, show_progress: bool, command: str) -> Path:
        """Train ``cfg`` in ``run_dir``, which holds at most its config yet."""

    def resume(self, run_dir: Path, cfg: Any, *, show_progress: bool, command: str) -> Path:
        """Continue the unfinished run of ``cfg`` in ``run_dir``."""

    def evaluate(self, run_dir: Path, cfg: Any) -> dict[str, Any]:
        """Re-evaluate the saved agents of a run folder."""

    def result_line(self, run_dir: Path, summary: dict[str, Any]) -> str:
        """What ``dospcot train`` prints of a finished run's ``summary.json``."""


RUNNERS: dict[type, Runner] = {TrainConfig: CoTrainingRunner(), PaperConfig: PaperProtocolRunner()}


def runner_for(cfg: RunConfig) -> Runner:
    """How ``cfg`` trains."""
    return RUNNERS[type(cfg)]


SeedsTrainer = Callable[[Any, dict[int, Path], dict[int, str], Callable[[float], None] | None], None]


def seeds_trainer(cfg: RunConfig) -> SeedsTrainer | None:
    """How several seeds of ``cfg`` train together in one process, each in its folder
    (``train_seeds_at(cfg, run_dirs, commands, progress)``, ``progress`` getting the share of one seed
    just done); None where each seed trains alone (a sweep may still batch them: ``--batch-seeds``)."""
    return getattr(runner_for(cfg), "train_seeds_at", None)
