"""One handler per command of the ``dospcot`` command line: each reads its parsed arguments, imports
what it needs (torch only where it trains) and returns the exit status."""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from dospcot.rating import rate_command

if TYPE_CHECKING:
    from dospcot.sweeps.sweep_spec import SweepSpec


def _train(args: argparse.Namespace, command: str) -> int:
    import torch

    from dospcot.config.errors import ConfigError
    from dospcot.config.loading import check_overrides
    from dospcot.config.presets import preset_names
    from dospcot.run.run_folder import batch_members
    from dospcot.run.sizes import check_sizes
    from dospcot.run.train import result_line, resume, train
    from dospcot.run.train_batch import resume_batch, train_seeds
    from dospcot.tasks import load_config

    torch.set_num_threads(args.threads)
    progress = not args.no_progress
    if args.resume is not None:
        if args.config or args.overrides or args.seeds or args.seed is not None:
            raise ConfigError(
                "--resume RUN_DIR takes no CONFIG, --set, --seed or --seeds: the run folder holds its config"
            )
        if batch_members(args.resume) is not None:
            run_dirs = resume_batch(args.resume, show_progress=progress, command=command)
        else:
            run_dirs = [resume(args.resume, show_progress=progress, command=command)]
    else:
        if not args.config:
            raise ConfigError(f"give a CONFIG: a preset ({', '.join(preset_names())}) or a path to a .toml")
        if args.seed is not None and args.seeds is not None:
            raise ConfigError("--seed and --seeds: give one (--seed trains one run, --seeds a batch)")
        option = "--seeds" if args.seeds is not None else "--seed" if args.seed is not None else None
        check_overrides(args.overrides, seeds_option=option)
        overrides = args.overrides if args.seed is None else [*args.overrides, f"seed={args.seed}"]
        cfg = load_config(args.config, overrides)
        seeds = len(args.seeds) if args.seeds is not None else 1
        warn("train", check_sizes([cfg], seeds, batch=seeds))
        if args.seeds is not None:
            run_dirs = train_seeds(
                cfg, list(args.seeds), args.runs_dir, show_progress=progress, command=command
            )
        else:
            run_dirs = [train(cfg, args.runs_dir, show_progress=progress, command=command)]
    for run_dir in run_dirs:
        print(result_line(run_dir))
    return 0


def _evaluate(args: argparse.Namespace, command: str) -> int:
    from dospcot.run.train import evaluate

    result = evaluate(args.run_dir)
    state = "finished" if result["finished"] else "unfinished"
    print(f"{args.run_dir}: the agents of round {result['round']} of {result['rounds']} ({state})")
    width = max(map(len, result["per_view"])) + 1  # the agents' names, left-aligned, colons in a column
    for view, row in result["per_view"].items():
        print(
            f"{view + ':':<{width}} return {row['greedy_return']:8.1f}  success {row['success']:.3f}  "
            f"normalised score {row['normalised_score']:.3f}  agreement {row['agreement']:.3f}"
        )
    if result["finished"]:
        print(f"wrote {args.run_dir / 'evaluation.json'}")
    else:
        print("nothing written: the run is unfinished, and a resume would make a file of it stale")
    return 0


def _sweep(args: argparse.Namespace, command: str) -> int:
    from dataclasses import replace

    from dospcot.config.errors import ConfigError
    from dospcot.run.sizes import check_sizes
    from dospcot.sweeps.sweep import default_sweep_dir, run_sweep
    from dospcot.sweeps.sweep_spec import SweepSpec

    if args.ray_address and args.backend != "ray":
        raise ConfigError("--ray-address names a Ray cluster: it needs --backend ray")
    if args.ray_address:
        check_ray_address(args.ray_address)
    if args.resume is not None:
        if args.configs or args.grid or args.overrides or args.name:
            raise ConfigError(
                "--resume SWEEP_DIR takes no CONFIG, --grid, --set or --name: the folder holds them"
            )
        sweep_dir, spec = args.resume, None
        warn("sweep", check_sizes([], len(args.seeds or ()), args.workers))
        if args.seeds is not None:
            from dospcot.sweeps.sweep_spec import add_seeds

            spec = add_seeds(sweep_dir, list(args.seeds))
    else:
        if not args.configs:
            raise ConfigError("give at least one CONFIG: a preset (see dospcot train --list) or a .toml path")
        from dospcot.config.loading import check_overrides
        from dospcot.sweeps.sweep_spec import parse_grid

        seeds = args.seeds or (0,)
        grid = parse_grid(args.grid)
        check_overrides(args.overrides, list(grid), seeds_option="--seeds")
        spec = SweepSpec(tuple(args.configs), grid, (0,), tuple(args.overrides))
        warn("sweep", _sweep_sizes(spec, seeds, args.workers, args.batch_seeds or 1))
        spec = replace(spec, seeds=tuple(seeds))
        sweep_dir = args.runs_dir / args.name if args.name else default_sweep_dir(args.configs, args.runs_dir)
    try:
        result = run_sweep(
            sweep_dir,
            spec,
            backend=args.backend,
            workers=args.workers,
            ray_address=args.ray_address,
            show_progress=not args.no_progress,
            batch_seeds=args.batch_seeds,
        )
    except KeyboardInterrupt:  # before any trial ran (a stop while they run says what they kept)
        raise _stopped_before_trials(sweep_dir, command) from None
    print(
        f"{sweep_dir}: {len(result.trials)} trials; {len(result.skipped)} already finished, "
        f"{len(result.ran) - len(result.failed)} run now, {len(result.failed)} failed "
        f"({args.backend} backend)"
    )
    for trial_id, error in result.failed.items():
        print(f"dospcot sweep: trial {trial_id} failed: {error}", file=sys.stderr)
    if not result.failed:
        print(f"next: dospcot report {sweep_dir}")
    return 1 if result.failed else 0


def _stopped_before_trials(sweep_dir: Path, command: str) -> Exception:
    """The stop of a sweep before its trials ran: what it kept, and the command that goes on."""
    from dospcot.run.interrupts import Interrupted
    from dospcot.sweeps.sweep_spec import SWEEP_FILE

    if (sweep_dir / SWEEP_FILE).is_file():
        return Interrupted(
            f"the sweep in {sweep_dir}, no trial run yet", f"dospcot sweep --resume {sweep_dir}"
        )
    return Interrupted("nothing written yet", command)


RAY_CONNECT_SECONDS = 3.0
"""How long ``--ray-address`` may take to answer before the sweep is refused (Ray itself retries for
more than a minute)."""


def check_ray_address(address: str) -> None:
    """Refuse a ``--ray-address`` that nothing answers at, before any folder is written.

    ``auto`` and ``local`` are Ray's own words and are left to it; ``host:port`` and
    ``ray://host:port`` must accept a TCP connection within :data:`RAY_CONNECT_SECONDS`.

    :raises ConfigError: one line naming the address and why.
    """
    import socket

    from dospcot.config.errors import ConfigError

    if address in ("auto", "local"):
        return
    where = address.removeprefix("ray://")
    host, sep, port_text = where.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port_text.isdigit() or not 0 < int(port_text) < 65_536:
        raise ConfigError(
            f"--ray-address {address}: expected HOST:PORT (e.g. 10.0.0.1:6379), ray://HOST:PORT or auto"
        )
    try:
        socket.create_connection((host, int(port_text)), timeout=RAY_CONNECT_SECONDS).close()
    except OSError as err:
        reason = err.strerror or str(err) or type(err).__name__
        raise ConfigError(
            f"--ray-address {address}: nothing answers there ({reason}); start the cluster (ray start "
            "--head) or give its address"
        ) from None


def _sweep_sizes(spec: SweepSpec, seeds: Sequence[int], workers: int, batch: int) -> list[str]:
    """:func:`~dospcot.run.sizes.check_sizes` of a sweep's cells (``spec``'s trials of its first seed)
    over ``seeds`` (a ``range`` for a count: a huge one is refused before it is built)."""
    from dospcot.run.sizes import check_sizes

    cfgs = spec.cell_configs()  # a bad --set or grid fails here, before a folder
    return check_sizes(cfgs, len(seeds), workers, min(batch, len(seeds)))


def warn(command: str, warnings: list[str]) -> None:
    """Print each warning of a size check as one line on stderr."""
    for line in warnings:
        print(f"dospcot {command}: warning: {line}", file=sys.stderr)


def _config(args: argparse.Namespace, command: str) -> int:
    """``dospcot config``: the resolved config as TOML, each key with its default and meaning."""
    from dospcot.config.loading import config_table
    from dospcot.config.reference import annotated_toml, config_rows, sb3_dqn_docs
    from dospcot.config.run_configs import TrainConfig
    from dospcot.config.version_defaults import moved_keys, versions_text
    from dospcot.tasks import get_task, load_config
    from dospcot.tasks.loading import task_section

    cfg = load_config(args.config, args.overrides)
    given = config_table(args.config, args.overrides)
    moved = {}
    if isinstance(cfg, TrainConfig):  # no version moves a paper-protocol key
        section = task_section(get_task(cfg.task).section)
        moved = {key: value for key, (value, _) in moved_keys(given, section).items()}
    table = get_task(cfg.task).config_table(cfg)
    rows = config_rows(type(cfg))
    if any(row.section == "dqn" and not row.meaning for row in rows.values()):  # SB3's words (imports torch)
        rows = config_rows(type(cfg), sb3_dqn_docs())
    heading = shlex.join(
        ["dospcot", "config", args.config, *(a for o in args.overrides for a in ("--set", o))]
    )
    heading += (
        f": the resolved config under version {cfg.defaults} of the defaults ({versions_text()}); "
        "each comment gives the key's default and meaning"
    )
    print(annotated_toml(type(cfg), table, rows, heading, moved), end="")
    return 0


def _report(args: argparse.Namespace, command: str) -> int:
    from dospcot.sweeps.report import write_report

    skipped: list[str] = []
    paths = write_report(args.sweep_dir, args.out, skipped)
    warn("report", [f"left out trial {line}" for line in skipped])
    print(paths[0].read_text())
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _reproduce_paper(args: argparse.Namespace, command: str) -> int:
    import time
    from dataclasses import replace

    from dospcot.config.errors import ConfigError
    from dospcot.config.loading import check_overrides
    from dospcot.config.presets import PAPER_PRESETS
    from dospcot.run.run_folder import new_run_dir
    from dospcot.sweeps.report import write_report
    from dospcot.sweeps.sweep import run_sweep
    from dospcot.sweeps.sweep_spec import SweepError, SweepSpec

    for option, key in (("--label-fraction", "label_fraction"), ("--episodes", "episodes_per_round")):
        given = [o for o in args.overrides if o.partition("=")[0].strip() == f"tabular.{key}"]
        if given and getattr(args, option[2:].replace("-", "_")) is not None:
            raise ConfigError(f"{option} and --set {given[0]} both set tabular.{key}: give it once")
    check_overrides(args.overrides, seeds_option="--seeds")
    if len(args.seeds) < 2:
        raise ConfigError(
            f"--seeds gives one seed ({args.seeds[0]}): the protocol's verdicts are intervals over seeds, "
            "which one seed cannot give; give 2 or more (default 10)"
        )
    overrides = [
        *([f"tabular.label_fraction={args.label_fraction}"] if args.label_fraction is not None else []),
        *([f"tabular.episodes_per_round={args.episodes}"] if args.episodes is not None else []),
        *args.overrides,
    ]
    spec = SweepSpec((PAPER_PRESETS.get(args.preset, args.preset),), {}, (0,), tuple(overrides))
    warn("reproduce-paper", _sweep_sizes(spec, args.seeds, args.workers, 1))
    spec = replace(spec, seeds=tuple(args.seeds))
    sweep_dir = new_run_dir(args.out, "")
    started = time.perf_counter()
    result = run_sweep(sweep_dir, spec, workers=args.workers, show_progress=not args.no_progress)
    wall = time.perf_counter() - started
    if result.failed:
        raise SweepError(f"{len(result.failed)} trials failed: {'; '.join(result.failed.values())}")
    paths = write_report(sweep_dir)
    target = next(line for line in paths[0].read_text().splitlines() if line.startswith("**Target**"))
    print(target.replace("**", ""))
    print(f"wrote {', '.join(str(p) for p in paths)}")
    print(f"wall time: {wall:.1f} s ({len(args.seeds)} seeds, {args.workers} workers)")
    print(f"the sweep behind it: dospcot sweep --resume {sweep_dir}; its tables: dospcot report {sweep_dir}")
    return 0


RUN_COMMANDS = {
    "train": _train,
    "evaluate": _evaluate,
    "sweep": _sweep,
    "report": _report,
    "reproduce-paper": _reproduce_paper,
    "config": _config,
    "rate": lambda args, command: rate_command(args, command, train=_train),  # --then-train: _train resumes
}
"""Commands whose bad configs and folders end in one line on stderr and exit status 2."""
