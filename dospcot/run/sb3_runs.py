"""How a co-training run of SB3 agents (a :class:`~dospcot.config.run_configs.TrainConfig`, every task
but the paper protocol) trains, resumes and evaluates in its run folder.

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
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import stable_baselines3
from stable_baselines3.common.callbacks import BaseCallback
from tqdm.auto import tqdm

from dospcot.adapters import build_adapter
from dospcot.config.run_configs import TrainConfig
from dospcot.core.queries import Rater
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.raters.file_rater import QueriesPending
from dospcot.run.checks import check_config
from dospcot.run.migrations import upgrade_run_state
from dospcot.run.run_folder import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    RunFolderError,
    config_digest,
    read_checkpoint,
    write_json,
    write_toml,
)
from dospcot.run.run_session import RunSession, new_run
from dospcot.tasks import get_task

EVALUATION_FILE = "evaluation.json"


def build_run(cfg: TrainConfig, rater: Rater | None = None) -> CoTrainingRun:
    """The co-training run of a config, checked first as ``train`` checks it (:func:`new_run` builds
    it), for a user who drives its rounds from Python.

    :param rater: answers an active label strategy's queries; None: the simulated rater.
    :raises ConfigError: what the config's check step finds (files, imports, the env), as for ``train``.
    """
    check_config(cfg)
    return new_run(cfg, rater)


class _StepBar(BaseCallback):
    """Advance a tqdm bar by every env step an agent takes."""

    def __init__(self, bar: tqdm) -> None:
        super().__init__()
        self.bar = bar

    def _on_step(self) -> bool:
        self.bar.update(1)
        return True


def train_cotraining_run(run_dir: Path, cfg: TrainConfig, *, show_progress: bool, command: str) -> Path:
    """Train a co-training run of SB3 agents in ``run_dir``, which holds at most its config yet."""
    if not (run_dir / CONFIG_FILE).is_file():
        write_toml(run_dir / CONFIG_FILE, get_task(cfg.task).config_table(cfg))
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
    state = upgrade_run_state(read_checkpoint(run_dir))
    trained = state["config_sha256"]  # None: a checkpoint written before it was checked
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
    session = RunSession(run_dir, cfg, state, command)
    run, rounds = session.run, cfg.training.rounds
    per_round = cfg.training.steps_per_round * len(run.agents)
    bar = tqdm(
        total=rounds * per_round,
        initial=run.round * per_round,
        unit="step",
        desc=f"{cfg.name} round {run.round + 1}/{rounds}",
        disable=not show_progress,
        dynamic_ncols=True,
    )

    def after_round(run: CoTrainingRun, rows: list[dict]) -> None:
        session.after_round(rows)
        score = np.mean([r["normalised_score"] for r in rows])
        bar.set_postfix(score=f"{score:.2f}", pace=f"{rows[0]['pace']:.2f}")
        bar.set_description(f"{cfg.name} round {min(run.round + 1, rounds)}/{rounds}")

    try:
        run.run(on_round=after_round, callback=_StepBar(bar))
    except QueriesPending:  # a person answers the queries: keep the collected round, stop until then
        session.checkpoint()
        raise
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the checkpoint of the last finished round stays
        raise session.interrupted() from None
    finally:
        bar.close()
    return session.finish()


def evaluate_cotraining_run(run_dir: Path, cfg: TrainConfig) -> dict[str, Any]:
    """Re-evaluate a co-training run's saved agents (loaded with plain ``stable_baselines3.DQN.load``)
    with its task adapter's evaluator, as during training (no training run, no fresh agents).

    :return: the round whose agents were scored, whether the run is finished, and per view and averaged
        the figures; a finished run's are written to ``evaluation.json``, an unfinished one's nowhere
        (a later resume would leave the file stale).
    """
    agents = [_load_agent(run_dir, f"agent_{name}.zip") for name in cfg.agent_names]
    policy = build_adapter(cfg).evaluate(agents)
    per_view = {
        name: {key: float(value[k]) for key, value in policy.items()}
        for k, name in enumerate(cfg.agent_names)
    }
    finished = (run_dir / SUMMARY_FILE).is_file()
    result = {
        "round": _rounds_done(run_dir),
        "rounds": cfg.training.rounds,
        "finished": finished,
        "per_view": per_view,
        "mean": {key: float(np.mean(value)) for key, value in policy.items()},
    }
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


class CoTrainingRunner:
    """How a :class:`~dospcot.config.run_configs.TrainConfig` trains (:mod:`dospcot.run.runners`)."""

    train_at = staticmethod(train_cotraining_run)
    resume = staticmethod(resume_cotraining_run)
    evaluate = staticmethod(evaluate_cotraining_run)

    @staticmethod
    def result_line(run_dir: Path, summary: dict[str, Any]) -> str:
        """What ``dospcot train`` prints of a finished run's ``summary.json``."""
        mean = summary["mean"]
        figures = ", ".join(
            f"{name.replace('_', ' ')} {mean[name]:.{digits}f}"
            for name, digits in (("normalised_score", 3), ("agreement", 3), ("success", 2))
        )
        return f"{run_dir}: {figures} (mean over {summary['m']} agent(s), round {summary['rounds']})"
