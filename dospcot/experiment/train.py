"""``dospcot train`` and ``dospcot evaluate``: one run of a config, with its run folder.

What a run is comes from its task (:mod:`dospcot.tasks`); this module writes the folder of a
co-training run of SB3 agents, the default of every task but the paper protocol's.

A run writes ``runs/<name>/<stamp>/`` (docs/design.md section 5):

- ``config.toml``: the resolved config (rerun it with ``dospcot train runs/<name>/<stamp>/config.toml``);
- ``tb/agent_<view>/``: TensorBoard events, SB3's ``rollout/`` and ``train/`` scalars plus ``dospcot/``
  scalars per round (pace, eps, lambda, coverage, pseudo-reward accuracy and its worst class,
  classifier loss, greedy return, agreement, ...), against the agent's env steps;
- ``metrics.csv``: one row per round and view; ``summary.json``: the last round, per view and averaged;
- ``agent_<view>.zip`` (loads with plain ``stable_baselines3.DQN.load``; a ``tabular`` agent's where
  dospcot is importable), ``classifier_<view>.pt``
  (:func:`dospcot.core.classifier.load_classifier`) and ``reward_classes.json`` (class index -> reward);
- ``learning_curves.png``; ``run_info.json`` (command, versions, wall time);
- ``summary.json`` is written last: a folder that has it holds a finished run;
- ``checkpoint.pkl``: the state after the last finished round, for ``dospcot train --resume``;
  removed when the run finishes (a finished run is not resumed).

``metrics.csv``, the agents, the classifiers and the checkpoint are rewritten at the end of every
round, the plot, ``run_info.json`` and ``summary.json`` when the run finishes; every file atomically,
so a killed run resumes from its last finished round and ends with the same ``summary.json`` as an
uninterrupted run. ``dospcot evaluate`` adds ``evaluation.json``.
"""

from __future__ import annotations

import csv
import math
import shutil
import time
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import stable_baselines3
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from torch.utils.tensorboard import SummaryWriter
from tqdm.auto import tqdm

from dospcot.config.loading import load_run_config
from dospcot.config.run_configs import RunConfig, TrainConfig
from dospcot.core.classifier import save_classifier
from dospcot.core.cotraining_run import CoTrainingRun
from dospcot.core.queries import LOG_COLUMNS, Rater
from dospcot.core.raters import FileRater, QueriesPending
from dospcot.experiment.interrupts import Interrupted
from dospcot.experiment.plots import plot_learning_curves
from dospcot.experiment.run_folder import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    REWARD_CLASSES_FILE,
    SUMMARY_FILE,
    RunFolderError,
    atomic_write,
    config_digest,
    new_run_dir,
    read_checkpoint,
    remove_stale_temporaries,
    run_lock,
    source_commit,
    write_checkpoint,
    write_csv,
    write_json,
    write_run_info,
    write_toml,
)

ROUND_SCALARS = (
    "pace", "eps", "lambda", "coverage", "view_coverage", "pseudo_accuracy", "view_pseudo_accuracy",
    "worst_class_recall", "worst_class_precision", "classifier_loss", "greedy_return", "success",
    "normalised_score", "agreement", "labelled_steps",
)  # fmt: skip
"""The per-round, per-view TensorBoard scalars, under ``dospcot/``."""
EVALUATION_FILE = "evaluation.json"
QUERIES_FILE = "queries.csv"
"""Every label a rater gave: round, sample, how it was chosen, answer (active label strategies)."""
QUERIES_FOLDER = "queries"
"""Where a file rater writes each round's queries, ``round_<r>.csv``, for a person to answer."""
SEGMENT_SCALARS = ("step_reward_error",)
"""The further per-round scalars of a run on segment labels."""
SUMMARY_METRICS = (
    "normalised_score", "agreement", "greedy_return", "success", "pseudo_accuracy",
    "worst_class_recall", "worst_class_precision", "coverage", "labelled_steps", "step_reward_error",
)  # fmt: skip


def build_run(cfg: TrainConfig, rater: Rater | None = None) -> CoTrainingRun:
    """The co-training run of a config, before its first round: its task's adapter
    (``cfg.task_definition.build``) driven by :class:`~dospcot.core.cotraining_run.CoTrainingRun`.

    :param rater: answers an active label strategy's queries; None: the simulated rater.
    :raises ConfigError: what the task's check step finds (files, imports, the env), as for ``train``.
    """
    check_config(cfg)
    return CoTrainingRun(cfg.task_definition.build(cfg), cfg, rater)


class _StepBar(BaseCallback):
    """Advance a tqdm bar by every env step an agent takes."""

    def __init__(self, bar: tqdm) -> None:
        super().__init__()
        self.bar = bar

    def _on_step(self) -> bool:
        self.bar.update(1)
        return True


def check_config(cfg: RunConfig) -> None:
    """The task's check step (:meth:`~dospcot.tasks.registry.Task.check`): what only files, imports or
    the env can tell, before any run folder is made."""
    cfg.task_definition.check(cfg)


def train(
    cfg: RunConfig,
    runs_root: Path = Path("runs"),
    *,
    show_progress: bool = True,
    command: str = "",
) -> Path:
    """Train ``cfg`` in a new folder ``runs_root/<name>/<stamp>/``; return that folder.

    The folder is made only once every check has passed, with its ``config.toml``; a failure before the
    run's first round ends (a task that cannot be built) removes it again, as nothing in it can resume.
    """
    check_config(cfg)
    run_dir = new_run_dir(runs_root, cfg.name, cfg.to_dict())
    try:
        return train_at(run_dir, cfg, show_progress=show_progress, command=command)
    except Exception:
        if not any((run_dir / name).is_file() for name in (CHECKPOINT_FILE, METRICS_FILE)):
            shutil.rmtree(run_dir, ignore_errors=True)
        raise


def train_at(run_dir: Path, cfg: RunConfig, *, show_progress: bool = True, command: str = "") -> Path:
    """Train ``cfg`` in ``run_dir`` (created if missing, as ``dospcot sweep`` names its trials), holding
    the folder's lock."""
    run_dir.mkdir(parents=True, exist_ok=True)
    with run_lock(run_dir):
        return cfg.task_definition.train_at(run_dir, cfg, show_progress=show_progress, command=command)


def resume(run_dir: Path, *, show_progress: bool = True, command: str = "") -> Path:
    """Continue a killed run from the checkpoint of its last finished round, or from the start if it
    finished none (a paper-protocol run always starts again: it keeps no checkpoint)."""
    cfg = run_config(run_dir)
    if (run_dir / SUMMARY_FILE).is_file():  # resuming it would train past its last round
        raise RunFolderError(
            f"{run_dir} is a finished run (it has {SUMMARY_FILE}): nothing to resume; to train its "
            f"config again: dospcot train {run_dir / CONFIG_FILE}"
        )
    with run_lock(run_dir):
        remove_stale_temporaries(run_dir)
        return cfg.task_definition.resume(run_dir, cfg, show_progress=show_progress, command=command)


def evaluate(run_dir: Path) -> dict[str, Any]:
    """Re-evaluate a run's saved agents on its task (:meth:`~dospcot.tasks.registry.Task.evaluate`).

    :return: per view and averaged: greedy return, success, normalised score and agreement.
    """
    cfg = run_config(run_dir)
    return cfg.task_definition.evaluate(run_dir, cfg)


def run_config(run_dir: Path) -> RunConfig:
    """The config a run folder holds."""
    config_path = run_dir / CONFIG_FILE
    if not config_path.is_file():
        raise RunFolderError(f"{run_dir} is not a run folder: it has no {CONFIG_FILE}")
    return load_run_config(config_path)


def train_cotraining_run(run_dir: Path, cfg: TrainConfig, *, show_progress: bool, command: str) -> Path:
    """Train a co-training run of SB3 agents in ``run_dir``, which holds at most its config yet."""
    if not (run_dir / CONFIG_FILE).is_file():
        write_toml(run_dir / CONFIG_FILE, cfg.to_dict())
    return _train_in(run_dir, cfg, None, show_progress, command)


def resume_cotraining_run(run_dir: Path, cfg: TrainConfig, *, show_progress: bool, command: str) -> Path:
    """Continue a co-training run from the checkpoint of its last finished round.

    :raises RunFolderError: the checkpoint is gone though rounds finished (a restart would silently
        redo them), or ``config.toml`` changed since the checkpoint was written.
    """
    if not (run_dir / CHECKPOINT_FILE).is_file():
        if (run_dir / METRICS_FILE).is_file():
            raise RunFolderError(
                f"{run_dir} finished rounds ({METRICS_FILE}) but has no {CHECKPOINT_FILE}: it cannot go on "
                f"from them; train its config anew: dospcot train {run_dir / CONFIG_FILE}"
            )
        # Killed in its first round: only the config is worth keeping, and old events would repeat.
        shutil.rmtree(run_dir / "tb", ignore_errors=True)
        return _train_in(run_dir, cfg, None, show_progress, command)
    state = read_checkpoint(run_dir)
    trained = state.get("config_sha256")  # a checkpoint older than this field was not checked
    if trained is not None and trained != config_digest(run_dir):
        raise RunFolderError(
            f"{run_dir / CONFIG_FILE} changed since its checkpoint was written: its rounds were trained "
            f"under another config; restore the file, or train the new config in a new folder: "
            f"dospcot train {run_dir / CONFIG_FILE}"
        )
    return _train_in(run_dir, cfg, state, show_progress, command)


def _train_in(
    run_dir: Path, cfg: TrainConfig, state: dict[str, Any] | None, show_progress: bool, command: str
) -> Path:
    started, started_cpu = time.perf_counter(), time.process_time()
    # Checked before the folder was made (train) or the sweep began (its trials): built at once here.
    rater = FileRater(run_dir / QUERIES_FOLDER) if cfg.training.rater == "file" else None
    run = CoTrainingRun(cfg.task_definition.build(cfg), cfg, rater)
    records: list[dict] = []
    elapsed, cpu, sessions, commits = 0.0, 0.0, 1, [source_commit()]
    if state is not None:
        run.load_state_dict(state["run"])
        records, elapsed, sessions = state["records"], state["elapsed_s"], state["sessions"] + 1
        cpu = state.get("cpu_s", float("nan"))  # a checkpoint older than this field: unknown
        # A resumed run may have been trained by other code before: each session's commit is kept (a
        # checkpoint older than this field names none for its sessions).
        commits = state.get("commits", [None] * (sessions - 1)) + commits
    for agent, view in zip(run.agents, cfg.views, strict=True):
        folder = str(run_dir / "tb" / f"agent_{view}")
        if state is not None:
            # The killed session logged part of the round resumed now: TensorBoard drops every event
            # from this step on in the files before this marker, so each step appears once.
            SummaryWriter(folder, purge_step=agent.num_timesteps).close()
        agent.set_logger(configure(folder, ["tensorboard"]))
    rounds = cfg.training.rounds
    digest = config_digest(run_dir)
    per_round = cfg.training.steps_per_round * len(run.agents)
    bar = tqdm(
        total=rounds * per_round, initial=run.round * per_round, unit="step",
        desc=f"{cfg.name} round {run.round + 1}/{rounds}", disable=not show_progress, dynamic_ncols=True,
    )  # fmt: skip

    def checkpoint() -> None:
        write_checkpoint(
            run_dir,
            {
                "run": run.state_dict(),
                "records": records,
                "elapsed_s": elapsed + time.perf_counter() - started,
                "cpu_s": cpu + time.process_time() - started_cpu,
                "sessions": sessions,
                "commits": commits,
                "config_sha256": digest,
            },
        )

    def after_round(run: CoTrainingRun, rows: list[dict]) -> None:
        """Log the round, write its files and checkpoint it."""
        records.extend(rows)
        _log_round(run, rows)
        score = np.mean([r["normalised_score"] for r in rows])
        bar.set_postfix(score=f"{score:.2f}", pace=f"{rows[0]['pace']:.2f}")
        bar.set_description(f"{cfg.name} round {min(run.round + 1, rounds)}/{rounds}")
        _write_round_files(run_dir, run, cfg, records)
        checkpoint()

    try:
        run.run(on_round=after_round, callback=_StepBar(bar))
    except QueriesPending:  # a person answers the queries: keep the collected round, stop until then
        checkpoint()
        raise
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the checkpoint of the last finished round stays
        done = len({row["round"] for row in records})
        kept = f"{done} of {rounds} rounds in {run_dir}" if done else f"no finished round in {run_dir}"
        raise Interrupted(kept, f"dospcot train --resume {run_dir}") from None
    finally:
        bar.close()
    for agent in run.agents:
        agent.logger.close()
    plot_learning_curves(records, run_dir / "learning_curves.png", title=f"{cfg.name} (seed {cfg.seed})")
    resumed = {"session_commits": commits} if sessions > 1 else {}
    cpu += time.process_time() - started_cpu
    times = {} if np.isnan(cpu) else {"cpu_time_s": round(cpu, 2)}  # NaN: a session's CPU time unknown
    write_run_info(
        run_dir, command, elapsed + time.perf_counter() - started, sessions=sessions, **times, **resumed
    )
    # Last, so that its presence marks a finished run (``dospcot sweep`` skips those on resume).
    write_json(run_dir / SUMMARY_FILE, run_summary(records, run))
    # A finished run is never resumed, and its checkpoint holds every replay buffer (about a GB on
    # a 32 x 32 grid): a sweep of finished runs would fill a disk.
    (run_dir / CHECKPOINT_FILE).unlink(missing_ok=True)
    return run_dir


def _log_round(run: CoTrainingRun, rows: list[dict]) -> None:
    bought = {} if run.queries is None else _queries_per_class(run)
    for agent, row in zip(run.agents, rows, strict=True):
        for key in (*ROUND_SCALARS, *SEGMENT_SCALARS):
            if math.isfinite(row[key]):
                agent.logger.record(f"dospcot/{key}", row[key])
        for key, count in bought.items():
            agent.logger.record(f"queries/{key}", count)
        agent.logger.record("dospcot/round", run.round)
        agent.logger.dump(step=agent.num_timesteps)


def _queries_per_class(run: CoTrainingRun) -> dict[str, int]:
    """This round's answers in all and per reward class of the run (``class_<c>``; ``unknown`` for a
    value no class holds yet)."""
    answers = run.queries.answers_of(run.round)
    classes = run.classes.encode(answers) if answers.size else np.zeros(0, dtype=np.int64)
    counts = {"total": int(answers.size)}
    for c in np.unique(classes):
        counts["unknown" if c < 0 else f"class_{c}"] = int((classes == c).sum())
    return counts


def _write_round_files(run_dir: Path, run: CoTrainingRun, cfg: TrainConfig, records: list[dict]) -> None:
    write_csv(run_dir / METRICS_FILE, records)
    if run.queries is not None:
        write_csv(run_dir / QUERIES_FILE, run.queries.log, LOG_COLUMNS)
    for agent, view in zip(run.agents, cfg.views, strict=True):
        atomic_write(run_dir / f"agent_{view}.zip", agent.save)
    if run.trainer is not None:
        for clf, view in zip(run.trainer.classifiers, cfg.views, strict=True):
            atomic_write(run_dir / f"classifier_{view}.pt", partial(save_classifier, clf))
        rewards = run.classes.values[run.classes.mask]
        write_json(run_dir / REWARD_CLASSES_FILE, {"rewards": [float(v) for v in rewards]})


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
        "env_steps_per_agent": int(last[0]["env_steps"]),
        **run.reference_returns(),
        "mean": {key: float(np.mean([r[key] for r in last])) for key in SUMMARY_METRICS},
        "per_view": {r["view"]: {key: r[key] for key in (*SUMMARY_METRICS, "eps", "pace")} for r in last},
    }


def evaluate_cotraining_run(run_dir: Path, cfg: TrainConfig) -> dict[str, Any]:
    """Re-evaluate a co-training run's saved agents (loaded with plain ``stable_baselines3.DQN.load``)
    with its task adapter's evaluator, as during training (no training run, no fresh agents).

    :return: the round whose agents were scored, whether the run is finished, and per view and averaged
        the figures; a finished run's are written to ``evaluation.json``, an unfinished one's nowhere
        (a later resume would leave the file stale).
    """
    agents = [_load_agent(run_dir, f"agent_{v}.zip") for v in cfg.views]
    policy = cfg.task_definition.build(cfg).evaluate(agents)
    per_view = {v: {key: float(value[k]) for key, value in policy.items()} for k, v in enumerate(cfg.views)}
    finished = (run_dir / SUMMARY_FILE).is_file()
    result = {
        "round": _rounds_done(run_dir), "rounds": cfg.training.rounds, "finished": finished,
        "per_view": per_view, "mean": {key: float(np.mean(value)) for key, value in policy.items()},
    }  # fmt: skip
    if finished:
        write_json(run_dir / EVALUATION_FILE, result)
    return result


def _rounds_done(run_dir: Path) -> int:
    """The last round ``metrics.csv`` records (0: none)."""
    if not (run_dir / METRICS_FILE).is_file():
        return 0
    with (run_dir / METRICS_FILE).open() as rows:
        return max((int(row["round"]) for row in csv.DictReader(rows)), default=0)


def _load_agent(run_dir: Path, name: str) -> stable_baselines3.DQN:
    path = run_dir / name
    if not path.is_file():
        rounds = _rounds_done(run_dir)
        if not rounds:
            raise RunFolderError(f"{path} does not exist: the run finished no round")
        raise RunFolderError(
            f"{path} is missing, though the run finished {rounds} round(s): the folder is incomplete"
        )
    try:
        return stable_baselines3.DQN.load(path, device="cpu")
    except Exception as err:  # zipfile, pickle and torch raise many types for a damaged file
        raise RunFolderError(f"{path} is not a readable SB3 agent ({type(err).__name__}: {err})") from None
