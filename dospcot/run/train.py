"""``dospcot train`` and ``dospcot evaluate``: one run of any config, with its run folder. How the
config trains in it is its runner's, chosen by the config's type (:mod:`dospcot.run.runners`); what a
co-training run's folder holds (every task's but the paper protocol's) is :mod:`dospcot.run.sb3_runs`'s.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from dospcot.config.run_configs import RunConfig
from dospcot.run.checks import check_config
from dospcot.run.interrupts import Interrupted
from dospcot.run.run_folder import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    RunFolderError,
    new_run_dir,
    remove_stale_temporaries,
    run_lock,
)
from dospcot.run.runners import runner_for
from dospcot.tasks import get_task, load_run_config


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
    run_dir = new_run_dir(runs_root, cfg.name, get_task(cfg.task).config_table(cfg))
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
            return runner_for(cfg).train_at(run_dir, cfg, show_progress=show_progress, command=command)
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
            return runner_for(cfg).resume(run_dir, cfg, show_progress=show_progress, command=command)
        except KeyboardInterrupt:  # stopped while the run was rebuilt from its checkpoint: nothing changed
            raise Interrupted(f"{run_dir} as it was", f"dospcot train --resume {run_dir}") from None


def evaluate(run_dir: Path) -> dict[str, Any]:
    """Re-evaluate a run's saved agents on its task.

    :return: per view and averaged: greedy return, success, normalised score and agreement.
    """
    cfg = run_config(run_dir)
    return runner_for(cfg).evaluate(run_dir, cfg)


def run_config(run_dir: Path) -> RunConfig:
    """The config a run folder holds."""
    config_path = run_dir / CONFIG_FILE
    if run_dir.is_file():  # --resume runs/x/<stamp>/config.toml: the folder was meant
        raise RunFolderError(
            f"{run_dir} is a file: give its run folder, {run_dir.parent}"
            if run_dir.name == CONFIG_FILE
            else f"{run_dir} is a file, not a run folder (runs/<name>/<stamp>)"
        )
    if config_path.exists() and not config_path.is_file():
        raise RunFolderError(f"{config_path} is not a file (a folder?): a run folder holds it as a file")
    if not config_path.is_file():
        raise RunFolderError(f"{run_dir} is not a run folder: it has no {CONFIG_FILE}")
    return load_run_config(config_path)


def result_line(run_dir: Path) -> str:
    """What ``dospcot train`` prints of a finished run folder."""
    summary = json.loads((run_dir / SUMMARY_FILE).read_text())
    return runner_for(run_config(run_dir)).result_line(run_dir, summary)
