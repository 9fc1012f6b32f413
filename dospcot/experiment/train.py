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
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import stable_baselines3
import torch
from stable_baselines3.common.callbacks import BaseCallback
from tqdm.auto import tqdm

from dospcot.config.errors import ConfigError
from dospcot.config.loading import load_run_config
from dospcot.config.run_configs import RunConfig, TrainConfig
from dospcot.core.cotraining_run import CoTrainingRun
from dospcot.core.queries import Rater
from dospcot.core.raters import QueriesPending
from dospcot.experiment.interrupts import Interrupted
from dospcot.experiment.run_folder import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    RunFolderError,
    config_digest,
    new_run_dir,
    read_checkpoint,
    remove_stale_temporaries,
    run_lock,
    write_json,
    write_toml,
)
from dospcot.experiment.run_session import RunSession

EVALUATION_FILE = "evaluation.json"


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
    the env can tell, before any run folder is made; and that a GPU the ``[dqn]`` section names is there.
    """
    cfg.task_definition.check(cfg)
    if isinstance(cfg, TrainConfig) and set(cfg.agent_kinds) - {"tabular"}:
        device = cfg.dqn.device
        index = int(device.partition(":")[2] or 0)
        if device.startswith("cuda") and index >= torch.cuda.device_count():
            raise ConfigError(
                f"dqn.device = {device!r}, but torch sees {torch.cuda.device_count()} CUDA device(s) "
                f"(torch {torch.__version__}); set dqn.device = 'cpu'"
            )


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
    except Interrupted:  # its message names the folder to resume, which starts it again
        raise
    except Exception:
        if not any((run_dir / name).is_file() for name in (CHECKPOINT_FILE, METRICS_FILE)):
            shutil.rmtree(run_dir, ignore_errors=True)
        raise


def train_at(run_dir: Path, cfg: RunConfig, *, show_progress: bool = True, command: str = "") -> Path:
    """Train ``cfg`` in ``run_dir`` (created if missing, as ``dospcot sweep`` names its trials), holding
    the folder's lock."""
    run_dir.mkdir(parents=True, exist_ok=True)
    with run_lock(run_dir):
        try:
            return cfg.task_definition.train_at(run_dir, cfg, show_progress=show_progress, command=command)
        except KeyboardInterrupt:  # stopped while its task and agents were built: a round had not begun
            raise Interrupted(
                f"no finished round in {run_dir}", f"dospcot train --resume {run_dir}"
            ) from None


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
        try:
            return cfg.task_definition.resume(run_dir, cfg, show_progress=show_progress, command=command)
        except KeyboardInterrupt:  # stopped while the run was rebuilt from its checkpoint: nothing changed
            raise Interrupted(f"{run_dir} as it was", f"dospcot train --resume {run_dir}") from None


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
    session = RunSession(run_dir, cfg, state, command)
    run, rounds = session.run, cfg.training.rounds
    per_round = cfg.training.steps_per_round * len(run.agents)
    bar = tqdm(
        total=rounds * per_round, initial=run.round * per_round, unit="step",
        desc=f"{cfg.name} round {run.round + 1}/{rounds}", disable=not show_progress, dynamic_ncols=True,
    )  # fmt: skip

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
