"""The run folder's side of a co-training run being trained: what ``dospcot train`` writes after every
round and when the run finishes, for a run of its own and for each member of a batch alike
(:class:`RunSession`; the folder's files: :mod:`dospcot.run.train`)."""

from __future__ import annotations

import math
import time
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.logger import configure
from torch.utils.tensorboard import SummaryWriter

from dospcot.adapters import build_adapter
from dospcot.config.run_configs import TrainConfig
from dospcot.core.classifier import save_classifier
from dospcot.core.queries import LOG_COLUMNS, Rater
from dospcot.core.round_records import CLASS_COLUMNS, DEPENDENCE_STATS
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.raters.file_rater import FileRater, action_names
from dospcot.run.interrupts import Interrupted
from dospcot.run.run_folder import (
    CHECKPOINT_FILE,
    METRICS_FILE,
    PSEUDO_REWARDS_FILE,
    QUERIES_FILE,
    REWARD_CLASSES_FILE,
    SUMMARY_FILE,
    atomic_write,
    config_digest,
    source_commit,
    write_checkpoint,
    write_csv,
    write_json,
    write_run_info,
)

ROUND_SCALARS = (
    "pace",
    "eps",
    "lambda",
    "coverage",
    "view_coverage",
    "pseudo_accuracy",
    "view_pseudo_accuracy",
    "view_error",
    "worst_class_recall",
    "worst_class_precision",
    "classifier_loss",
    "greedy_return",
    "success",
    "normalised_score",
    "agreement",
    "labelled_steps",
    "step_reward_error",
)
"""The per-round, per-view TensorBoard scalars, under ``dospcot/`` (each where it is a number: a run
that learns no reward has no ``step_reward_error``)."""
QUERIES_FOLDER = "queries"
"""Where a file rater writes each round's queries, ``round_<r>.csv``, for a person to answer."""
SUMMARY_METRICS = (
    "normalised_score",
    "agreement",
    "greedy_return",
    "success",
    "pseudo_accuracy",
    "worst_class_recall",
    "worst_class_precision",
    "coverage",
    "labelled_steps",
    "step_reward_error",
)


def new_run(cfg: TrainConfig, rater: Rater | None = None) -> CoTrainingRun:
    """The co-training run of a config, before its first round: its task's adapter
    (:func:`~dospcot.adapters.build_adapter`) driven by :class:`~dospcot.core.sb3_round.CoTrainingRun`;
    the one place that builds it.

    :param rater: answers an active label strategy's queries; None: the simulated rater.
    """
    return CoTrainingRun(build_adapter(cfg), cfg, rater)


class RunSession:
    """One session of training in a run folder: the run built (and continued from a checkpoint), its
    agents' TensorBoard loggers, the files every finished round rewrites and the checkpoint, and the
    files the finished run adds.

    :param run_dir: the run folder, holding at least its ``config.toml``.
    :param cfg: the run's config.
    :param state: the checkpoint to continue from, or None for a new run.
    :param command: the command line, for ``run_info.json``.
    :param batch: the members of the batch this run trains in (1: a run of its own); a member's CPU
        time is its share of its process's.
    """

    def __init__(
        self, run_dir: Path, cfg: TrainConfig, state: dict[str, Any] | None, command: str, batch: int = 1
    ) -> None:
        self.started, self.started_cpu = time.perf_counter(), time.process_time()
        self.run_dir, self.cfg, self.command, self.batch = run_dir, cfg, command, batch
        # Checked before the folder was made (train) or the sweep began (its trials): built at once here.
        rater = FileRater(run_dir / QUERIES_FOLDER, cfg.views) if cfg.training.rater == "file" else None
        self.run = new_run(cfg, rater)
        if rater is not None:
            rater.actions = action_names(self.run.task)
        self.records: list[dict] = []
        self.elapsed, self.cpu, self.sessions, self.commits = 0.0, 0.0, 1, [source_commit()]
        self.extra: dict[str, Any] = {}
        """What the driver keeps in the checkpoint beside the run (a batch: its members' draws)."""
        if state is not None:
            self.run.load_state_dict(state["run"])
            self.records, self.elapsed = state["records"], state["elapsed_s"]
            self.sessions = state["sessions"] + 1
            self.cpu = state["cpu_s"]
            # A resumed run may have been trained by other code before: each session's commit is kept.
            self.commits = state["commits"] + self.commits
            self.extra = state["extra"]
        for agent, name in zip(self.run.agents, cfg.agent_names, strict=True):
            folder = str(run_dir / "tb" / f"agent_{name}")
            if state is not None:
                # The killed session logged part of the round resumed now: TensorBoard drops every event
                # from this step on in the files before this marker, so each step appears once.
                SummaryWriter(folder, purge_step=agent.num_timesteps).close()
            agent.set_logger(configure(folder, ["tensorboard"]))
        self.digest = config_digest(run_dir)

    def _cpu_now(self) -> float:
        return self.cpu + (time.process_time() - self.started_cpu) / self.batch

    def checkpoint_state(self) -> dict[str, Any]:
        """The state after the last finished round (or a collected round awaiting answers): what
        :meth:`checkpoint` writes, and what a new session continues from. Pickle it at once."""
        return {
            "run": self.run.state_dict(),
            "records": self.records,
            "elapsed_s": self.elapsed + time.perf_counter() - self.started,
            "cpu_s": self._cpu_now(),
            "sessions": self.sessions,
            "commits": self.commits,
            "config_sha256": self.digest,
            "extra": self.extra,
        }

    def checkpoint(self) -> None:
        """Write :meth:`checkpoint_state` to the folder's checkpoint."""
        write_checkpoint(self.run_dir, self.checkpoint_state())

    def after_round(self, rows: list[dict], checkpoint: bool = True) -> None:
        """Checkpoint the round just finished (unless its batch checkpoints every member at once:
        :meth:`add_round` and :meth:`write_round` then), then log it and write its files.

        The checkpoint comes first: a process killed while it writes the round's files (a sweep's stop
        ends its workers at once) leaves a folder that resumes from this round, never round files
        ahead of the checkpoint, which no resume could go on from."""
        self.add_round(rows)
        if checkpoint:
            self.checkpoint()
        self.write_round(rows)

    def add_round(self, rows: list[dict]) -> None:
        """Add the rows of the round just finished to the records a checkpoint holds."""
        self.records.extend(rows)

    def write_round(self, rows: list[dict]) -> None:
        """Log the round just finished (TensorBoard) and write its files."""
        self._log_round(rows)
        self._write_round_files()

    def interrupted(self) -> Interrupted:
        """The one-line stop of a session interrupted by Ctrl-C or SIGTERM: what was kept, how to resume."""
        done = len({row["round"] for row in self.records})
        rounds, run_dir = self.cfg.training.rounds, self.run_dir
        kept = f"{done} of {rounds} rounds in {run_dir}" if done else f"no finished round in {run_dir}"
        return Interrupted(kept, f"dospcot train --resume {run_dir}")

    def finish(self) -> Path:
        """Write what a finished run adds (the plot, ``run_info.json``, ``summary.json`` last) and drop
        the checkpoint; returns the run folder."""
        run, run_dir, cfg = self.run, self.run_dir, self.cfg
        for agent in run.agents:
            agent.logger.close()
        summary = run_summary(self.records, run)
        # matplotlib (some 40 MB resident) loads here, after the fits, and once the replay buffers (the
        # largest arrays a run holds, saved with no agent) are dropped: the memory they give back then
        # holds the plotting stack, rather than the stack adding to the run's peak.
        for agent in run.agents:
            agent.replay_buffer = None
        title = f"{cfg.name} (seed {cfg.seed})"
        from dospcot.run.plots import plot_learning_curves

        plot_learning_curves(self.records, run_dir / "learning_curves.png", self.cfg.agent_names, title=title)
        resumed = {"session_commits": self.commits} if self.sessions > 1 else {}
        cpu = self._cpu_now()
        times = {} if np.isnan(cpu) else {"cpu_time_s": round(cpu, 2)}  # NaN: a session's CPU time unknown
        batched = {"batch_members": self.batch} if self.batch > 1 else {}
        elapsed = self.elapsed + time.perf_counter() - self.started
        write_run_info(
            run_dir,
            self.command,
            elapsed,
            numerics=cfg.cotraining.numerics,
            sessions=self.sessions,
            **times,
            **resumed,
            **batched,
        )
        # Last, so that its presence marks a finished run (``dospcot sweep`` skips those on resume).
        write_json(run_dir / SUMMARY_FILE, summary)
        # A finished run is never resumed, and its checkpoint holds every replay buffer (about a GB on
        # a 32 x 32 grid): a sweep of finished runs would fill a disk.
        (run_dir / CHECKPOINT_FILE).unlink(missing_ok=True)
        return run_dir

    def _log_round(self, rows: list[dict]) -> None:
        run = self.run
        bought = {} if run.queries is None else _queries_per_class(run)
        for agent, row in zip(run.agents, rows, strict=True):
            # The dependence figures (NaN, so not logged, with one predictor) under dospcot/ too.
            for key in (*ROUND_SCALARS, *DEPENDENCE_STATS):
                if math.isfinite(row[key]):
                    agent.logger.record(f"dospcot/{key}", row[key])
            for key, count in bought.items():
                agent.logger.record(f"queries/{key}", count)
            agent.logger.record("dospcot/round", run.round)
            agent.logger.dump(step=agent.num_timesteps)

    def _write_round_files(self) -> None:
        run, run_dir, cfg = self.run, self.run_dir, self.cfg
        write_csv(run_dir / METRICS_FILE, self.records)
        if run.queries is not None:
            write_csv(run_dir / QUERIES_FILE, run.queries.log, LOG_COLUMNS)
        for agent, name in zip(run.agents, cfg.agent_names, strict=True):
            atomic_write(run_dir / f"agent_{name}.zip", agent.save)
        if run.class_records:
            write_csv(run_dir / PSEUDO_REWARDS_FILE, run.class_records, CLASS_COLUMNS)
        if run.trainer is not None:
            for clf, name in zip(run.trainer.classifiers, cfg.agent_names, strict=True):
                atomic_write(run_dir / f"classifier_{name}.pt", partial(save_classifier, clf))
            rewards = run.classes.values[run.classes.mask]
            write_json(run_dir / REWARD_CLASSES_FILE, {"rewards": [float(v) for v in rewards]})


def _queries_per_class(run: CoTrainingRun) -> dict[str, int]:
    """This round's answers in all and per reward class of the run (``class_<c>``; ``unknown`` for a
    value no class holds yet)."""
    answers = run.queries.answers_of(run.round)
    classes = run.classes.encode(answers) if answers.size else np.zeros(0, dtype=np.int64)
    counts = {"total": int(answers.size)}
    for c in np.unique(classes):
        counts["unknown" if c < 0 else f"class_{c}"] = int((classes == c).sum())
    return counts


def run_summary(records: list[dict], run: CoTrainingRun) -> dict[str, Any]:
    """The last round's metrics per view and averaged over the views (no timings: a resumed run
    ends with the summary of the uninterrupted one)."""
    last = [r for r in records if r["round"] == run.round]
    cfg = run.cfg
    return {
        "method": cfg.method,
        "views": list(cfg.views),
        "agents": list(cfg.agent_kinds),
        "m": len(cfg.views),
        "seed": cfg.seed,
        "rounds": run.round,
        "stopped_early": run.stopped,
        "stopped_because": run.stop_reason or f"its last round (training.rounds = {cfg.training.rounds})",
        "env_steps_per_agent": int(last[0]["env_steps"]),
        **run.reference_returns(),
        "mean": {key: float(np.mean([r[key] for r in last])) for key in SUMMARY_METRICS},
        "per_view": {
            cfg.agent_names[r["agent"]]: {key: r[key] for key in (*SUMMARY_METRICS, "eps", "pace")}
            for r in last
        },
    }
