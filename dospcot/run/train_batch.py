"""``dospcot train CONFIG --seeds N``: the seeds of one config trained as one batch in one process
(:class:`~dospcot.core.batched_runs.BatchedRuns`), each seed writing the run folder a run of its own
writes (:mod:`dospcot.run.train`), so that ``evaluate``, ``report`` and the studies read them
as they read any run.

Each member's checkpoint is a run's checkpoint plus the batch's part of it: its members' folders and
its own draw streams. ``dospcot train --resume`` of any member's folder resumes the whole batch.
"""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from dospcot.config.run_configs import TrainConfig
from dospcot.core.batched_runs import BatchedRuns, config_refusal
from dospcot.run.checks import check_config
from dospcot.run.interrupts import Interrupted
from dospcot.run.migrations import upgrade_run_state
from dospcot.run.run_folder import (
    BATCH_FILE,
    CHECKPOINT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    RunFolderError,
    batch_members,
    config_digest,
    new_run_dir,
    read_checkpoint,
    run_lock,
    write_checkpoint,
    write_json,
    write_toml,
)
from dospcot.run.run_session import RunSession
from dospcot.run.train import run_config, train
from dospcot.tasks import get_task

BATCH_STATES = "batch_states"
"""The batch's checkpoint (in its first member's folder): every member's checkpoint state, in order."""
DRAWS_KEY = "batched_draws"
"""The checkpoint's ``extra`` entry of a batch member: the state of its draw streams, one per view."""


def train_seeds(
    cfg: TrainConfig, seeds: Sequence[int], runs_root: Path, *, show_progress: bool = True, command: str = ""
) -> list[Path]:
    """Train ``cfg`` under each of ``seeds``, one new folder per seed; as one batch where the config
    allows it, else one run after another, saying why in one line.

    :return: the run folders, in the order of ``seeds``.
    """
    cfgs = [dataclasses.replace(cfg, seed=int(seed)) for seed in seeds]
    refusal = config_refusal(cfg) if len(cfgs) > 1 else "one seed is a run of its own"
    if refusal is not None:
        if len(cfgs) > 1:
            print(f"training the {len(cfgs)} seeds one after another, not as a batch: {refusal}")
        return [train(c, runs_root, show_progress=show_progress, command=command) for c in cfgs]
    check_config(cfgs[0])  # the seeds differ in nothing the check step reads
    run_dirs = [new_run_dir(runs_root, c.name, get_task(c.task).config_table(c)) for c in cfgs]
    try:
        return train_batch_at(run_dirs, cfgs, commands=[command] * len(cfgs), show_progress=show_progress)
    except Interrupted:  # its message names a folder to resume, which starts the batch again
        raise
    except Exception:
        if not (run_dirs[0] / CHECKPOINT_FILE).is_file():  # nothing of a batch without a round can resume
            for run_dir in run_dirs:
                shutil.rmtree(run_dir, ignore_errors=True)
        raise


def train_batch_at(
    run_dirs: list[Path],
    cfgs: list[TrainConfig],
    *,
    commands: list[str],
    show_progress: bool = False,
    progress: Callable[[float], None] | None = None,
) -> list[Path]:
    """Train ``cfgs`` (one config's seeds) as one batch in ``run_dirs`` (created if missing, as
    ``dospcot sweep`` names its trials), each holding its lock.

    :param commands: each member's command line, for its ``run_info.json``.
    :param progress: called with the trials' worth of work done since its last call, summed over the
        members (a sweep's bar counts trials).
    """
    members = {"members": [str(d.resolve()) for d in run_dirs]}
    for run_dir, cfg in zip(run_dirs, cfgs, strict=True):
        run_dir.mkdir(parents=True, exist_ok=True)
        if not (run_dir / CONFIG_FILE).is_file():
            write_toml(run_dir / CONFIG_FILE, get_task(cfg.task).config_table(cfg))
        write_json(run_dir / BATCH_FILE, members)
    with contextlib.ExitStack() as locks:
        for run_dir in run_dirs:
            locks.enter_context(run_lock(run_dir))
        return _train_batch(run_dirs, cfgs, None, show_progress, commands, progress)


def resume_batch(
    run_dir: Path,
    *,
    show_progress: bool = True,
    command: str = "",
    commands: list[str] | None = None,
    progress: Callable[[float], None] | None = None,
) -> list[Path]:
    """Continue the batch ``run_dir`` belongs to from its members' checkpoints (a batch killed in its
    first round starts again).

    :raises RunFolderError: a member's checkpoint is lost though rounds finished, or its config changed.
    """
    run_dirs = batch_members(run_dir) or [run_dir]
    cfgs = [run_config(d) for d in run_dirs]
    commands = commands or [command] * len(run_dirs)
    with contextlib.ExitStack() as locks:
        for member in run_dirs:
            locks.enter_context(run_lock(member))
        checkpoint = run_dirs[0] / CHECKPOINT_FILE
        if not checkpoint.is_file():
            if any((d / METRICS_FILE).is_file() for d in run_dirs):
                raise RunFolderError(
                    f"{run_dirs[0]} finished rounds ({METRICS_FILE}) but its batch has no {CHECKPOINT_FILE}: "
                    f"it cannot go on from them; train the config anew: dospcot train "
                    f"{run_dirs[0] / CONFIG_FILE} --seeds {','.join(str(c.seed) for c in cfgs)}"
                )
            for member in run_dirs:  # killed in the first round: old events would repeat
                shutil.rmtree(member / "tb", ignore_errors=True)
            return _train_batch(run_dirs, cfgs, None, show_progress, commands, progress)
        states = [upgrade_run_state(state) for state in read_checkpoint(run_dirs[0])[BATCH_STATES]]
        for member, state in zip(run_dirs, states, strict=True):
            if state["config_sha256"] != config_digest(member):
                raise RunFolderError(
                    f"{member / CONFIG_FILE} changed since its batch's checkpoint was written: its rounds "
                    "were trained under another config"
                )
        return _train_batch(run_dirs, cfgs, states, show_progress, commands, progress)


def _train_batch(
    run_dirs: list[Path],
    cfgs: list[TrainConfig],
    states: list[dict[str, Any]] | None,
    show_progress: bool,
    commands: list[str],
    progress: Callable[[float], None] | None = None,
) -> list[Path]:
    """Train the batch of ``run_dirs`` (each holding its config and lock), from its members'
    checkpoints ``states`` or from the start."""
    try:
        sessions = [
            RunSession(run_dir, cfg, None if states is None else states[s], commands[s], batch=len(cfgs))
            for s, (run_dir, cfg) in enumerate(zip(run_dirs, cfgs, strict=True))
        ]
    except KeyboardInterrupt:  # stopped while the members were built: no round of this session began
        kept = "no finished round" if states is None else "the batch's rounds as they were"
        raise Interrupted(
            f"{kept} in {run_dirs[0]} and its batch", f"dospcot train --resume {run_dirs[0]}"
        ) from None
    batch = BatchedRuns([session.run for session in sessions])
    if states is not None:
        batch.set_draws([session.extra[DRAWS_KEY] for session in sessions])
    cfg, first = cfgs[0], sessions[0].run
    per_round = cfg.training.steps_per_round * len(cfg.views) * len(cfgs)
    rounds = cfg.training.rounds
    bar = tqdm(
        total=rounds * per_round,
        initial=first.round * per_round,
        unit="member-step",
        desc=f"{cfg.name} x {len(cfgs)} seeds",
        disable=not show_progress,
        dynamic_ncols=True,
    )

    def after_round(rows: list[list[dict]]) -> None:
        for member, (session, member_rows) in enumerate(zip(sessions, rows, strict=True)):
            session.extra = {DRAWS_KEY: batch.draws_of(member)}
            session.add_round(member_rows)
        # One file for the whole batch, written at once, before any member's round files (as
        # RunSession.after_round): a kill never leaves members at different rounds, nor files ahead of it.
        write_checkpoint(run_dirs[0], {BATCH_STATES: [session.checkpoint_state() for session in sessions]})
        for session, member_rows in zip(sessions, rows, strict=True):
            session.write_round(member_rows)

    member_steps = rounds * cfg.training.steps_per_round * len(cfg.views)
    unreported = [0.0]

    def on_steps(steps: int) -> None:
        bar.update(steps)
        unreported[0] += steps / member_steps  # each member-step is this share of its member's trial
        if progress is not None and unreported[0] >= 0.01:  # a sweep's queue needs no report per step
            progress(unreported[0])
            unreported[0] = 0.0

    try:
        batch.run(on_round=after_round, on_steps=on_steps)
    except KeyboardInterrupt:  # the checkpoints of the last finished round stay
        raise sessions[0].interrupted() from None
    finally:
        bar.close()
    finished = [session.finish() for session in sessions]
    for run_dir in run_dirs:  # a finished member is a run like any other
        (run_dir / BATCH_FILE).unlink(missing_ok=True)
    return finished
