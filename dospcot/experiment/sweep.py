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
A sweep runs paper-protocol configs or train configs, not both: ``dospcot report`` tables them apart.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import shutil
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from itertools import product
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import Any, Literal

from tqdm.auto import tqdm

from dospcot.config.errors import ConfigError
from dospcot.config.loading import load_config
from dospcot.experiment.run_folder import CONFIG_FILE, SUMMARY_FILE, write_json

SWEEP_FILE = "sweep.json"
TRIAL_FILE = "trial.json"
SWEEP_FORMAT = 1
Backend = Literal["local", "ray"]


class SweepError(ValueError):
    """A sweep that cannot run as asked (bad grid, a folder holding another sweep, failed trials)."""


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep runs: ``configs`` x the product of ``grid`` x ``seeds``.

    :param configs: preset names or paths to ``.toml`` files, as ``dospcot train`` takes them.
    :param grid: config key -> the values it takes, as text (each read as TOML, else as a string).
    :param seeds: the seeds every combination runs with.
    :param overrides: ``key=value`` settings applied to every trial before the grid's.
    """

    configs: tuple[str, ...]
    grid: dict[str, tuple[str, ...]] = field(default_factory=dict)
    seeds: tuple[int, ...] = (0,)
    overrides: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"format": SWEEP_FORMAT, **asdict(self)}  # tuples become JSON lists

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SweepSpec:
        if data.get("format") != SWEEP_FORMAT:
            raise SweepError(f"{SWEEP_FILE} is not a dospcot sweep of format {SWEEP_FORMAT}")
        return cls(
            tuple(data["configs"]),
            {k: tuple(v) for k, v in data["grid"].items()},
            tuple(data["seeds"]),
            tuple(data["overrides"]),
        )

    def trials(self) -> list[Trial]:
        """Every trial, each config's checked now so that a bad grid fails before anything runs: its
        fields, and once per combination of grid values its task's check step (files, imports, the env).

        :raises ConfigError: a combination the config rejects (naming the key).
        """
        keys = list(self.grid)
        trials, kinds = [], set()
        for config in self.configs:
            for values in product(*self.grid.values()):
                params = dict(zip(keys, values, strict=True))
                for index, seed in enumerate(self.seeds):
                    trial = Trial(config, "", params, seed, self.overrides)
                    cfg = load_config(config, trial.overrides())
                    if index == 0:  # the seed changes nothing the check step reads
                        cfg.task_definition.check(cfg)
                    trials.append(replace(trial, name=cfg.name))
                    kinds.add(type(cfg))
        ids = [t.trial_id for t in trials]
        if len(set(ids)) != len(ids):
            raise SweepError("two trials share a folder name: give each config its own `name`")
        if len(kinds) > 1:
            raise SweepError(
                'a sweep runs paper-protocol configs (task = "paper") or train configs, not both: '
                "sweep them apart"
            )
        return trials


@dataclass(frozen=True)
class Trial:
    """One run of a sweep: a config with some grid values and a seed."""

    config: str
    name: str
    params: dict[str, str]
    seed: int
    base_overrides: tuple[str, ...] = ()

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Trial:
        return cls(
            data["config"],
            data["name"],
            dict(data["params"]),
            int(data["seed"]),
            tuple(data["base_overrides"]),
        )

    def overrides(self) -> list[str]:
        """The ``--set`` list of this trial: the sweep's overrides, the grid values, the seed."""
        return [*self.base_overrides, *(f"{k}={v}" for k, v in self.params.items()), f"seed={self.seed}"]

    @property
    def trial_id(self) -> str:
        """``<config name>/<key=value>__...__seed=<s>``: the trial's folder under ``trials/``."""
        parts = [f"{key}={_folder_text(value)}" for key, value in self.params.items()]
        return f"{self.name}/{'__'.join([*parts, f'seed={self.seed}'])}"


def _folder_text(value: str) -> str:
    return re.sub(r"[^\w.+-]", "", value.replace(",", "+"))


def parse_grid(items: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """``["training.label_fraction=0.01,0.1", 'views=["patch"],["rays"]']`` -> key -> values.

    Commas inside brackets or quotes belong to a value, so lists (agent pairs, view sets) can be swept.

    :raises ConfigError: an item without ``=``, without values, or with a key given twice.
    """
    grid: dict[str, tuple[str, ...]] = {}
    for item in items:
        name, _, text = item.partition("=")
        name = name.strip()
        values = tuple(v.strip() for v in _split_top_level(text))
        if not re.fullmatch(r"[A-Za-z_][\w.]*", name) or not text or any(not v for v in values):
            raise ConfigError(
                f"--grid takes key=v1,v2,... (e.g. training.label_fraction=0.05,0.1), got {item!r}"
            )
        if name in grid or name == "seed":
            raise ConfigError(
                f"--grid {name}: " + ("use --seeds for seeds" if name == "seed" else "given twice")
            )
        grid[name] = values
    return grid


def _split_top_level(text: str) -> list[str]:
    parts, depth, quote, start = [], 0, "", 0
    for i, char in enumerate(text):
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    return [*parts, text[start:]]


def open_sweep(sweep_dir: Path, spec: SweepSpec | None) -> SweepSpec:
    """Create ``sweep_dir`` for ``spec``, or reopen it (``spec=None`` or the same spec) to resume.

    :raises SweepError: the folder holds a different sweep, or (to resume) no sweep at all.
    """
    path = sweep_dir / SWEEP_FILE
    if path.is_file():
        try:
            stored = SweepSpec.from_dict(json.loads(path.read_text()))
        except (ValueError, KeyError, TypeError) as err:
            raise SweepError(
                f"{path} is damaged ({type(err).__name__}); start the sweep in a new folder"
            ) from None
        if spec is not None and spec != stored:
            if replace(spec, seeds=stored.seeds) == stored and set(stored.seeds) <= set(spec.seeds):
                raise SweepError(
                    f"{sweep_dir} holds another sweep (these configs and grid, with seeds "
                    f"{', '.join(map(str, stored.seeds))}); to add seeds to it: dospcot sweep --resume "
                    f"{sweep_dir} --seeds {','.join(map(str, spec.seeds))}"
                )
            raise SweepError(
                f"{sweep_dir} holds another sweep ({', '.join(stored.configs)}, grid "
                f"{_grid_text(stored.grid)}, {len(stored.seeds)} seeds); pick another --name or resume "
                f"it with --resume {sweep_dir}"
            )
        return stored
    if spec is None:
        raise SweepError(f"{sweep_dir} is not a sweep folder: it has no {SWEEP_FILE}")
    try:
        sweep_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:  # a file on the way, or a folder that cannot be created
        raise SweepError(f"cannot make the sweep folder {sweep_dir}: {err.strerror}") from None
    write_json(path, spec.to_dict())
    return spec


def add_seeds(sweep_dir: Path, seeds: Sequence[int]) -> SweepSpec:
    """Give the sweep in ``sweep_dir`` the seeds ``seeds``, a superset of its own, keeping its finished
    trials: its ``sweep.json`` is rewritten, and a resume then runs only the new seeds' trials.

    :raises SweepError: no sweep there, or ``seeds`` lacks some of the sweep's seeds.
    """
    stored = open_sweep(sweep_dir, None)
    dropped = [seed for seed in stored.seeds if seed not in seeds]
    if dropped:
        raise SweepError(
            f"--seeds would drop seed(s) {', '.join(map(str, dropped))} of the sweep in {sweep_dir}: "
            f"give all of its seeds ({', '.join(map(str, stored.seeds))}) and the new ones"
        )
    spec = replace(stored, seeds=tuple(stored.seeds) + tuple(s for s in seeds if s not in stored.seeds))
    write_json(sweep_dir / SWEEP_FILE, spec.to_dict())
    return spec


def _grid_text(grid: dict[str, tuple[str, ...]]) -> str:
    return " ".join(f"{key}={','.join(values)}" for key, values in grid.items()) or "none"


def trial_dir(sweep_dir: Path, trial: Trial) -> Path:
    return sweep_dir / "trials" / trial.trial_id


def is_finished(sweep_dir: Path, trial: Trial) -> bool:
    return (trial_dir(sweep_dir, trial) / SUMMARY_FILE).is_file()


def stale_trials(sweep_dir: Path, trials: Sequence[Trial]) -> list[tuple[str, str]]:
    """The trials whose folder holds a config other than the one their config name and overrides
    resolve to now (a preset changed since they ran), each with the first key that differs.

    A sweep folder can outlive its code (the README's studies keep theirs in the repository), and
    without this check a finished trial would be counted, and an unfinished one resumed, under
    settings the sweep no longer means.
    """
    stale = []
    for trial in trials:
        path = trial_dir(sweep_dir, trial) / CONFIG_FILE
        if not path.is_file():
            continue
        stored, current = load_config(str(path)), load_config(trial.config, trial.overrides())
        if stored != current:
            old, new = _flat(stored.to_dict()), _flat(current.to_dict())
            key = next(k for k in sorted(old.keys() | new.keys()) if old.get(k) != new.get(k))
            stale.append((trial.trial_id, f"{key} was {old.get(key)!r}, is {new.get(key)!r}"))
    return stale


def check_not_stale(sweep_dir: Path, trials: Sequence[Trial]) -> None:
    """:raises SweepError: one line naming the stale trials' count and the first one's changed key."""
    stale = stale_trials(sweep_dir, trials)
    if stale:
        trial_id, key = stale[0]
        raise SweepError(
            f"{len(stale)} trial(s) in {sweep_dir} were trained with another config than their preset "
            f"and overrides give now (e.g. {trial_id}: {key}); move the sweep folder away, or delete "
            "those trials' folders, to run them again"
        )


def _flat(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            flat |= _flat(value, f"{prefix}{key}.")
        else:
            flat[f"{prefix}{key}"] = value
    return flat


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

    from dospcot.experiment.train import resume, train_at

    # One thread per trial: the pool's processes share the cores, and more threads oversubscribe them.
    torch.set_num_threads(1)
    run_dir = trial_dir(sweep_dir, trial)
    if not (run_dir / SUMMARY_FILE).is_file():
        if (run_dir / CONFIG_FILE).is_file():
            resume(run_dir, show_progress=False, command=_command(trial))
        else:
            cfg = load_config(trial.config, trial.overrides())
            train_at(_fresh_trial_dir(sweep_dir, trial), cfg, show_progress=False, command=_command(trial))
    return json.loads((run_dir / SUMMARY_FILE).read_text())


def plan_jobs(trials: Sequence[Trial], workers: int) -> list[list[Trial]]:
    """The local backend's jobs, one process each: every train trial alone; a paper-protocol cell's
    trials (one config and grid values, over seeds) split into ``workers`` batches, since its runs
    vectorise over seeds and a batch of seeds costs little more than one."""
    jobs: list[list[Trial]] = []
    cells: dict[tuple[str, tuple[tuple[str, str], ...]], list[Trial]] = {}
    for trial in trials:
        if load_config(trial.config, trial.overrides()).task_definition.seeds_train_together:
            cells.setdefault((trial.config, tuple(trial.params.items())), []).append(trial)
        else:
            jobs.append([trial])
    for members in cells.values():
        jobs += [members[i::workers] for i in range(min(workers, len(members)))]
    return jobs


def run_job(sweep_dir: Path, trials: list[Trial], progress: Callable[[float], None] | None = None) -> None:
    """Run one job of :func:`plan_jobs`: a trial, or a batch of one cell's seeds trained together.

    :param progress: called with the share of a trial just done (a batch reports as it trains).
    """
    if len(trials) == 1:
        run_trial(sweep_dir, trials[0])
        return
    import torch

    torch.set_num_threads(1)
    cfg = load_config(trials[0].config, trials[0].overrides())
    cfg.task_definition.train_seeds_at(
        cfg,
        {trial.seed: _fresh_trial_dir(sweep_dir, trial) for trial in trials},
        {trial.seed: _command(trial) for trial in trials},
        progress,
    )


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
) -> SweepResult:
    """Run every unfinished trial of a sweep (``spec=None``: resume the sweep stored in ``sweep_dir``).

    :param workers: trials at once (processes for ``local``, concurrent Ray trials for ``ray``).
    :param ray_address: an existing Ray cluster (``ray``); ``None`` starts a local instance with
        ``workers`` CPUs.
    """
    if workers < 1:
        raise SweepError(f"--workers must be at least 1, got {workers}")
    if spec is None:
        spec = open_sweep(sweep_dir, None)
        trials = spec.trials()
    else:
        trials = spec.trials()  # checked before the folder is made: a bad grid leaves nothing behind
        open_sweep(sweep_dir, spec)
    check_not_stale(sweep_dir, trials)
    todo = [t for t in trials if not is_finished(sweep_dir, t)]
    skipped = [t for t in trials if t not in todo]
    if backend == "local":
        failed = _run_local(sweep_dir, plan_jobs(todo, workers), workers, show_progress)
    elif backend == "ray":
        failed = _run_ray(sweep_dir, todo, workers, ray_address)
    else:
        raise SweepError(f"--backend: {backend!r} is not allowed; allowed: local, ray")
    return SweepResult(sweep_dir, trials, skipped, todo, failed)


def _run_local(sweep_dir: Path, jobs: list[list[Trial]], workers: int, show_progress: bool) -> dict[str, str]:
    failed: dict[str, str] = {}
    if not jobs:
        return failed
    # spawn, not fork: a forked child inherits torch's thread pools and locks from the parent.
    context = multiprocessing.get_context("spawn")
    total = sum(len(job) for job in jobs)
    manager = SyncManager(ctx=context)
    manager.start(exit_with_parent, (os.getpid(),))
    with (
        manager,
        ProcessPoolExecutor(
            min(workers, len(jobs)), mp_context=context, initializer=exit_with_parent, initargs=(os.getpid(),)
        ) as pool,
        tqdm(
            total=total,
            unit="trial",
            disable=not show_progress,
            dynamic_ncols=True,
            bar_format="{l_bar}{bar}| {n:.1f}/{total} trials [{elapsed}<{remaining}{postfix}]",
        ) as bar,
    ):
        reports = manager.Queue()  # (job index, share of a trial done) from the workers
        futures = {
            pool.submit(run_job, sweep_dir, job, partial(_report_progress, reports, index)): index
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
    return failed


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
        ray.init(**kwargs, include_dashboard=False, log_to_driver=False, configure_logging=False)
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
