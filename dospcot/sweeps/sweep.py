"""``dospcot sweep``: every combination of a grid of config values, over seeds, each as its own run.

A sweep folder holds::

    sweep.json                      the sweep: configs, grid, seeds, overrides (a rerun must match it)
    trials/<name>/<params>__seed=<s>/
        trial.json                  the trial's config, grid values and seed
        config.toml ... summary.json  an ordinary ``dospcot train`` run folder

A trial whose folder has ``summary.json`` (written last) is finished and never runs again, so a killed
sweep resumes by running the same command again (or ``dospcot sweep --resume SWEEP_DIR``). A trial
killed part-way resumes from its last finished round's checkpoint, or starts again if it finished none
(as ``dospcot train --resume`` does).

Backends: ``local`` runs the trials in a pool of ``workers`` processes, which exit when the sweep's
process dies, even by SIGKILL; ``ray`` runs the same trials as
Ray Tune trials (the ``ray`` extra), one CPU each, on a local Ray instance or on a cluster by address.
On a cluster every node must see the sweep folder (a shared filesystem), since trials write there.

Paper-protocol configs (``task = "paper"``) vectorise over seeds: the local backend trains one cell's
unfinished seeds in ``workers`` batches, one batch per process, and each seed still writes its own
trial folder (the same folder it would write alone). The ray backend runs each seed as its own trial.
With ``batch_seeds`` K > 1 the local backend also batches a train cell's seeds, K at most per process
(:mod:`dospcot.run.train_batch`), where the config allows it.
A sweep runs paper-protocol configs or train configs, not both: ``dospcot report`` tables them apart.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass
from functools import partial
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from dospcot.run.interrupts import Interrupted, leave_interrupts_to_the_parent, worker_context
from dospcot.run.run_folder import CONFIG_FILE, SUMMARY_FILE, batch_members, run_lock, write_json
from dospcot.run.runners import seeds_trainer
from dospcot.sweeps.sweep_spec import (
    SWEEP_FILE,
    TRIAL_FILE,
    Backend,
    SweepError,
    SweepSpec,
    Trial,
    check_not_stale,
    is_finished,
    open_sweep,
    store_batch_seeds,
    stored_batch_seeds,
    trial_dir,
)


def _command(trial: Trial) -> str:
    return f"dospcot train {trial.config} " + " ".join(f"--set {o}" for o in trial.overrides())


def _fresh_trial_dir(sweep_dir: Path, trial: Trial) -> Path:
    run_dir = trial_dir(sweep_dir, trial)
    shutil.rmtree(run_dir, ignore_errors=True)
    run_dir.mkdir(parents=True)
    write_json(run_dir / TRIAL_FILE, asdict(trial) | {"trial_id": trial.trial_id})
    return run_dir


def run_trial(sweep_dir: Path, trial: Trial) -> dict[str, Any]:
    """Run (or finish) one trial in its folder; return its ``summary.json``."""
    import torch

    from dospcot.run.train import resume, train_at

    # One thread per trial: the pool's processes share the cores, and more threads oversubscribe them.
    torch.set_num_threads(1)
    run_dir = trial_dir(sweep_dir, trial)
    if not (run_dir / SUMMARY_FILE).is_file():
        if (run_dir / CONFIG_FILE).is_file():
            resume(run_dir, show_progress=False, command=_command(trial))
        else:
            cfg = trial.load_config()
            train_at(_fresh_trial_dir(sweep_dir, trial), cfg, show_progress=False, command=_command(trial))
    return json.loads((run_dir / SUMMARY_FILE).read_text())


def plan_jobs(
    trials: Sequence[Trial], workers: int, batch_seeds: int = 1, sweep_dir: Path | None = None
) -> list[list[Trial]]:
    """The local backend's jobs, one process each: a paper-protocol cell's trials (one config and grid
    values, over seeds) split into ``workers`` batches, since its runs vectorise over seeds and a batch
    of seeds costs little more than one; with ``batch_seeds`` K > 1, a train cell's seeds in batches of
    at most K (docs/batched_seeds.md) where its config can batch; every other trial alone.

    A trial already started in ``sweep_dir`` goes on as it started, whatever ``batch_seeds`` now says:
    the members of a killed batch together, a trial started alone alone (:func:`started_as`). So a
    resumed sweep's files are those of one never stopped, and none of its trials starts over.
    """
    jobs: list[list[Trial]] = []
    cells: dict[tuple[str, tuple[tuple[str, str], ...]], list[Trial]] = {}
    batches: dict[tuple[str, tuple[tuple[str, str], ...]], list[Trial]] = {}
    started: dict[tuple[str, ...], list[Trial]] = {}
    for trial in trials:
        cfg = trial.load_config()
        cell = (trial.config, tuple(trial.params.items()))
        how = None if sweep_dir is None else started_as(sweep_dir, trial)
        if seeds_trainer(cfg) is not None:
            cells.setdefault(cell, []).append(trial)
        elif isinstance(how, tuple):
            started.setdefault(how, []).append(trial)
        elif how == "alone" or batch_seeds == 1 or not _can_batch(cfg):
            jobs.append([trial])
        else:
            batches.setdefault(cell, []).append(trial)
    jobs += started.values()
    for members in cells.values():
        jobs += [members[i::workers] for i in range(min(workers, len(members)))]
    for members in batches.values():
        jobs += [members[i : i + batch_seeds] for i in range(0, len(members), batch_seeds)]
    return jobs


def started_as(sweep_dir: Path, trial: Trial) -> tuple[str, ...] | str | None:
    """How ``trial`` started in ``sweep_dir``: the folders of the unfinished batch it belongs to (its
    ``batch.json``), ``"alone"`` (a run folder of its own), or None (not started)."""
    run_dir = trial_dir(sweep_dir, trial)
    if not (run_dir / CONFIG_FILE).is_file():
        return None
    members = batch_members(run_dir)
    return "alone" if members is None else tuple(str(member) for member in members)


def _can_batch(cfg: Any) -> bool:
    """Whether ``--batch-seeds`` decides how a trial of ``cfg`` trains: a train config whose seeds can
    batch (not a paper config, whose cell's seeds train together whatever it says)."""
    if seeds_trainer(cfg) is not None:
        return False
    from dospcot.core.batched_runs import config_refusal  # torch: only where batches are asked for

    return config_refusal(cfg) is None


def run_job(
    sweep_dir: Path,
    trials: list[Trial],
    progress: Callable[[float], None] | None = None,
    batch_seeds: int = 1,
) -> None:
    """Run one job of :func:`plan_jobs`: a trial, or a batch of one cell's seeds trained together.

    :param progress: called with the share of a trial just done (a batch reports as it trains).
    :param batch_seeds: as :func:`plan_jobs`'s: above 1, a train cell's job that has not started is a
        batch even of one seed, so that no seed's result depends on how the cell's seeds were grouped.
    """
    cfg = trials[0].load_config()
    how = started_as(sweep_dir, trials[0])
    if how is None:
        batched = batch_seeds > 1 and _can_batch(cfg)
    else:
        batched = how != "alone"
    if len(trials) == 1 and not batched:
        run_trial(sweep_dir, trials[0])
        return
    import torch

    torch.set_num_threads(1)
    if batched:
        _run_batch(sweep_dir, trials, progress)
        return
    train_seeds = seeds_trainer(cfg)
    assert train_seeds is not None  # plan_jobs groups seeds only where they train together
    train_seeds(
        cfg,
        {trial.seed: _fresh_trial_dir(sweep_dir, trial) for trial in trials},
        {trial.seed: _command(trial) for trial in trials},
        progress,
    )


def _run_batch(sweep_dir: Path, trials: list[Trial], progress: Callable[[float], None] | None) -> None:
    """Train a batch of one train cell's seeds in one process, each in its trial folder: resumed where
    the same batch was killed, else from the start (members are independent, so a batch's grouping
    changes none of its members' results)."""
    from dospcot.run.train_batch import resume_batch, train_batch_at

    run_dirs = [trial_dir(sweep_dir, trial) for trial in trials]
    commands = [_command(trial) for trial in trials]
    if batch_members(run_dirs[0]) == [d.resolve() for d in run_dirs]:
        resume_batch(run_dirs[0], show_progress=False, commands=commands, progress=progress)
        return
    cfgs = [trial.load_config() for trial in trials]
    fresh = [_fresh_trial_dir(sweep_dir, trial) for trial in trials]
    train_batch_at(fresh, cfgs, commands=commands, progress=progress)


@dataclass
class SweepResult:
    """What one ``run_sweep`` call did."""

    sweep_dir: Path
    trials: list[Trial]
    skipped: list[Trial]
    ran: list[Trial]
    failed: dict[str, str]


def run_sweep(
    sweep_dir: Path,
    spec: SweepSpec | None = None,
    *,
    backend: Backend = "local",
    workers: int = 2,
    ray_address: str | None = None,
    show_progress: bool = True,
    batch_seeds: int | None = None,
) -> SweepResult:
    """Run every unfinished trial of a sweep (``spec=None``: resume the sweep stored in ``sweep_dir``).

    :param workers: trials at once (processes for ``local``, concurrent Ray trials for ``ray``).
    :param batch_seeds: K > 1: the local backend trains each train cell's seeds in batches of at most
        K, one batch per process (docs/batched_seeds.md); 1: every trial alone; None: the value the
        sweep was started with (1 for a new one). Kept in ``sweep.json``.
    :param ray_address: an existing Ray cluster (``ray``); ``None`` starts a local instance with
        ``workers`` CPUs.
    :raises SweepError: ``batch_seeds`` differs from the sweep's own while some of its trials have
        started and others have not: the rest would train another way than the first.
    """
    if workers < 1:
        raise SweepError(f"--workers must be at least 1, got {workers}")
    if batch_seeds is not None and (batch_seeds < 1 or (batch_seeds > 1 and backend != "local")):
        raise SweepError(
            f"--batch-seeds takes a count >= 1, and more than 1 on the local backend only; got {batch_seeds} "
            f"on {backend}"
        )
    new = spec is not None and not (sweep_dir / SWEEP_FILE).is_file()
    existed = sweep_dir.exists()
    if spec is None:
        spec = open_sweep(sweep_dir, None)
        trials = spec.trials()
    else:
        trials = spec.trials()  # checked before the folder is made: a bad grid leaves nothing behind
        open_sweep(sweep_dir, spec)
    try:
        # Two sweeps on one folder would fail each other's trials on their run locks, one by one.
        with run_lock(sweep_dir, "run", SweepError):
            return _run_trials(sweep_dir, trials, backend, workers, ray_address, show_progress, batch_seeds)
    except RayStartError:
        if new:  # no trial began: what this call wrote would only refuse the next sweep of the name
            if existed:
                (sweep_dir / SWEEP_FILE).unlink(missing_ok=True)
            else:
                shutil.rmtree(sweep_dir, ignore_errors=True)
        raise


class RayStartError(SweepError):
    """Ray did not start (a bad ``--ray-address``, a cluster out of reach): no trial began."""


def _run_trials(
    sweep_dir: Path,
    trials: list[Trial],
    backend: Backend,
    workers: int,
    ray_address: str | None,
    show_progress: bool,
    batch_seeds: int | None,
) -> SweepResult:
    """:func:`run_sweep`'s work once it holds the sweep's lock."""
    check_not_stale(sweep_dir, trials)
    todo = [t for t in trials if not is_finished(sweep_dir, t)]
    skipped = [t for t in trials if t not in todo]
    batch_seeds = _batch_seeds(sweep_dir, batch_seeds, trials, todo)
    if batch_seeds > 1 and backend != "local" and todo:
        raise SweepError(
            f"{sweep_dir} batches its seeds (--batch-seeds {batch_seeds}): only the local backend can"
        )
    if backend == "local":
        jobs = plan_jobs(todo, workers, batch_seeds, sweep_dir)
        failed = _run_local(sweep_dir, jobs, workers, show_progress, batch_seeds)
    elif backend == "ray":
        failed = _run_ray(sweep_dir, todo, workers, ray_address)
    else:
        raise SweepError(f"--backend: {backend!r} is not allowed; allowed: local, ray")
    return SweepResult(sweep_dir, trials, skipped, todo, failed)


def _batch_seeds(sweep_dir: Path, given: int | None, trials: list[Trial], todo: list[Trial]) -> int:
    """The ``--batch-seeds`` to run the sweep's ``todo`` trials with, ``given`` stored where it is new."""
    stored = stored_batch_seeds(sweep_dir)
    if given is None or given == stored or not todo:
        return stored
    started = sum(started_as(sweep_dir, trial) is not None for trial in trials)
    if started and not any(_can_batch(t.load_config()) for t in trials):
        return stored  # no trial of it can batch (a paper sweep's run their cells' seeds together)
    if started:
        raise SweepError(
            f"{sweep_dir} trains its trials with --batch-seeds {stored} and {started} of its {len(trials)} "
            f"have started: under --batch-seeds {given} the rest would train another way; omit "
            f"--batch-seeds to go on, or start the sweep in a new folder"
        )
    store_batch_seeds(sweep_dir, given)
    return given


def _run_local(
    sweep_dir: Path, jobs: list[list[Trial]], workers: int, show_progress: bool, batch_seeds: int = 1
) -> dict[str, str]:
    failed: dict[str, str] = {}
    if not jobs:
        return failed
    context = worker_context()  # spawned, and deaf to Ctrl-C from the start
    # Workers stopped by Ctrl-C leave the pool's queue locks to the resource tracker, which would warn of
    # them in lines of its own after the one that says what was kept; they are freed all the same.
    if "ignore::UserWarning:multiprocessing.resource_tracker" not in sys.warnoptions:
        sys.warnoptions.append("ignore::UserWarning:multiprocessing.resource_tracker")
    total = sum(len(job) for job in jobs)
    manager = SyncManager(ctx=context)
    pool: ProcessPoolExecutor | None = None
    bar = tqdm(
        total=total,
        unit="trial",
        disable=not show_progress,
        dynamic_ncols=True,
        bar_format="{l_bar}{bar}| {n:.1f}/{total} trials [{elapsed}<{remaining}{postfix}]",
    )
    try:
        manager.start(_worker_start, (os.getpid(),))
        pool = ProcessPoolExecutor(
            min(workers, len(jobs)), mp_context=context, initializer=_worker_start, initargs=(os.getpid(),)
        )
        reports = manager.Queue()  # (job index, share of a trial done) from the workers
        futures = {
            pool.submit(
                run_job, sweep_dir, job, partial(_report_progress, reports, index), batch_seeds
            ): index
            for index, job in enumerate(jobs)
        }
        shown = [0.0] * len(jobs)
        pending = set(futures)
        while pending:
            done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            while not reports.empty():
                index, share = reports.get()
                shown[index] = min(shown[index] + share, len(jobs[index]))
            for future in done:
                index = futures[future]
                shown[index] = len(jobs[index])  # the rest, and all of a trial that reports nothing
                error = future.exception()
                if error is not None:
                    for trial in jobs[index]:
                        failed[trial.trial_id] = f"{type(error).__name__}: {error}"
            bar.n = sum(shown)
            bar.set_postfix(failed=len(failed))  # refreshes the bar
    except KeyboardInterrupt:
        # The workers and the manager ignore Ctrl-C (worker_context): the sweep stops every one, those
        # still starting too (a worker that has not begun would take a job and run it to its end, a
        # manager would wait to report to a sweep that is gone); their trials resume from their last
        # finished rounds.
        for child in multiprocessing.active_children():
            with contextlib.suppress(ProcessLookupError, TypeError):  # ended, or never started
                os.kill(child.pid, signal.SIGTERM)
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        raise _interrupted(sweep_dir, jobs) from None
    finally:
        # A stop as the sweep closes (its trials have ended, or were stopped) still closes the rest.
        stop = False
        closes = [bar.close, *([partial(pool.shutdown, wait=True)] if pool is not None else [])]
        for close in [*closes, getattr(manager, "shutdown", lambda: None)]:  # none: never started
            try:
                close()
            except KeyboardInterrupt:
                stop = True
        if stop:
            raise _interrupted(sweep_dir, jobs) from None
    return failed


def _interrupted(sweep_dir: Path, jobs: list[list[Trial]]) -> Interrupted:
    """What a stopped sweep kept, counted on disk, and the command that goes on."""
    trials = [trial for job in jobs for trial in job]
    finished = sum(is_finished(sweep_dir, trial) for trial in trials)
    started = [t for t in trials if (trial_dir(sweep_dir, t) / CONFIG_FILE).is_file()]
    stopped = [t.trial_id for t in started if not is_finished(sweep_dir, t)]
    mid_run = (
        f"{len(stopped)} stopped mid-run ({', '.join(stopped)}), which resume from their last finished round"
        if stopped
        else "none stopped mid-run"
    )
    return Interrupted(
        f"{finished} finished trial(s) of the {len(trials)} to run; {mid_run}",
        f"dospcot sweep --resume {sweep_dir}",
    )


def _worker_start(parent: int, worker_ids: Any = None) -> None:
    """A worker of the local backend (or its manager): exits with the sweep, and leaves Ctrl-C to it.

    :param worker_ids: a manager's list to which a pool worker adds its process id (None: the manager).
    """
    leave_interrupts_to_the_parent()
    exit_with_parent(parent)
    if worker_ids is not None:
        worker_ids.append(os.getpid())


def exit_with_parent(parent: int, interval: float = 1.0) -> None:
    """Start a daemon thread that ends this process once ``parent`` is no longer its parent. A sweep
    killed by a signal it cannot catch (``kill``, a scheduler's SIGKILL) would otherwise leave its
    workers training on, unseen, beside a resumed sweep; a half-trained trial resumes from its last
    checkpoint.

    :param parent: the process id of the sweep.
    :param interval: seconds between checks.
    """

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(interval)
        os._exit(1)  # no cleanup: the trial's folder holds what a resume needs

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _report_progress(reports: Any, index: int, share: float) -> None:
    reports.put((index, share))


def _ray_trial(config: dict[str, Any], sweep_dir: str) -> None:
    from ray import tune

    trial = Trial.from_dict(config["trial"])
    summary = run_trial(Path(sweep_dir), trial)
    tune.report({key: value for key, value in summary["mean"].items() if value == value})


def _run_ray(sweep_dir: Path, trials: list[Trial], workers: int, address: str | None) -> dict[str, str]:
    try:
        import ray
        from ray import tune
    except ImportError:
        raise SweepError("--backend ray needs the ray extra: pip install 'dospcot[ray]'") from None
    if not trials:
        return {}
    started_here = not ray.is_initialized()
    if started_here:
        kwargs = {"address": address} if address else {"num_cpus": workers}
        try:
            ray.init(**kwargs, include_dashboard=False, log_to_driver=False, configure_logging=False)
        except Exception as err:  # a bad address, an unreachable cluster: Ray's own types vary
            where = f"at --ray-address {address}" if address else "on this machine"
            reason = (str(err).strip().splitlines() or [""])[0]
            raise RayStartError(f"Ray did not start {where} ({type(err).__name__}: {reason})") from None
    try:
        trainable = tune.with_resources(
            tune.with_parameters(_ray_trial, sweep_dir=str(sweep_dir.resolve())), {"cpu": 1}
        )
        tuner = tune.Tuner(
            trainable,
            param_space={"trial": tune.grid_search([asdict(t) for t in trials])},
            tune_config=tune.TuneConfig(max_concurrent_trials=workers),
            run_config=tune.RunConfig(name="ray", storage_path=str((sweep_dir / "ray").resolve()), verbose=0),
        )
        results = tuner.fit()
        failed = {}
        for result in results:
            if result.error is not None:
                trial_id = Trial.from_dict(result.config["trial"]).trial_id
                failed[trial_id] = f"{type(result.error).__name__}: {result.error}"
        return failed
    finally:
        if started_here:
            ray.shutdown()


def default_sweep_dir(configs: Sequence[str], root: Path = Path("runs/sweeps")) -> Path:
    """``runs/sweeps/<first config's stem>[+N]``: the same command always names the same folder."""
    first = Path(configs[0]).stem
    return root / (first if len(configs) == 1 else f"{first}+{len(configs) - 1}")
