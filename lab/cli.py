"""``dospcot-lab``: the repository's lab on the command line. ``study`` runs a published study and
renders its page, ``bench`` measures the benchmark rows, ``record`` counts what the record holds.
Each finds the checkout it writes into from the working folder, or from ``--repo``."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from dospcot.cli.parser import (
    CommandParser,
    OneLineParser,
    add_overrides,
    add_workers,
    file_path,
    folder_path,
    positive_int,
)
from dospcot_lab.repository import NotARepository, Repository, find_repository, repository_at

QUICK_BENCH_OUT = Path("runs/bench-quick.md")
"""Where ``dospcot-lab bench --quick`` writes its smoke-test figures (under the working folder)."""
DESCRIPTION = (
    "The lab of the dospcot repository: the published studies, the benchmarks and the record. Run it "
    "from a checkout of the repository (or give --repo); it writes into that checkout's docs/, "
    "README.md, BENCHMARKS.md and runs/ only where a command says so."
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``dospcot-lab`` and its three commands."""
    parser = OneLineParser(prog="dospcot-lab", description=DESCRIPTION)
    parser.add_argument(
        "--repo",
        type=folder_path,
        metavar="DIR",
        help="the checkout to read and write (default: the one holding the working folder)",
    )
    commands = parser.add_subparsers(dest="command", required=True, parser_class=CommandParser)
    study = commands.add_parser(
        "study",
        description="Run a study's sweeps (only the trials not yet finished), then print its tables from "
        "every finished run; with --docs also write docs/results/<study>.md and its row of the results "
        "at a glance.",
        help="one of the published studies: its sweeps, then its tables (with --docs, its docs page)",
    )
    add_overrides(study, "override a key in every trial (repeatable; the study then writes its own sweeps)")
    study.add_argument("study", metavar="STUDY", help="the study, e.g. grid16 (a wrong name lists them)")
    study.add_argument(
        "--seeds",
        type=positive_int,
        help="seeds 0..N-1 (default: the study's); another count, or any --set, trains into sweep folders of "
        "its own (<sweep>-<N>seeds-<k>sets), apart from the study's",
    )
    add_workers(study, "trials at once")
    study.add_argument(
        "--batch-seeds",
        type=positive_int,
        metavar="K",
        help="as dospcot sweep's (default: each sweep's own, 1 for a new one)",
    )
    study.add_argument("--backend", choices=["local", "ray"], default="local", help="default local")
    study.add_argument(
        "--runs-dir",
        type=folder_path,
        help="where the study's sweeps are (default: the checkout's runs/sweeps)",
    )
    study.add_argument("--docs", action="store_true", help="also write docs/results/<study>.md (and its row)")
    study.add_argument("--render-only", action="store_true", help="train nothing: tables from finished runs")
    study.add_argument(
        "--sweep",
        action="append",
        default=[],
        dest="sweeps",
        metavar="NAME",
        help="train this sweep of the study alone (repeatable; default: every one); the tables still read "
        "every finished run of the study",
    )
    bench = commands.add_parser(
        "bench",
        help="measure performance claims against their peers and write BENCHMARKS.md",
        description="Run every benchmark (ours and a peer in the same run) and write the checkout's "
        "BENCHMARKS.md.",
    )
    bench.add_argument("--quick", action="store_true", help="short runs: a smoke test, not a measurement")
    bench.add_argument("--repeats", type=positive_int, default=3, help="repetitions per figure (default 3)")
    bench.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="NAME",
        help="run this benchmark alone (repeatable) and replace its row in --out, which a full run "
        "wrote; a line above the table says when",
    )
    bench.add_argument(
        "--out",
        type=file_path,
        help="output file (default: the checkout's BENCHMARKS.md; with --quick "
        f"{QUICK_BENCH_OUT}, never BENCHMARKS.md)",
    )
    bench.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default="cpu",
        help="cuda: measure the rows that have a GPU form on the GPU, into the GPU column of --out's "
        "table (default cpu)",
    )
    record = commands.add_parser(
        "record",
        help="the record's size (sweeps, runs, files, bytes); --write puts it into runs/README.md",
        description="Count the record of the checkout (runs/sweeps/) and print its size paragraph.",
    )
    record.add_argument("--write", action="store_true", help="write the paragraph into runs/README.md")
    return parser


def _repository(args: argparse.Namespace, needed: bool) -> Repository | None:
    """The checkout of ``--repo``, or the one holding the working folder; None where there is none and
    the command does not need one."""
    if args.repo is not None:
        return repository_at(args.repo)
    try:
        return find_repository()
    except NotARepository:
        if needed:
            raise
        return None


def _study(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from dospcot.config.errors import ConfigError
    from dospcot.config.loading import check_overrides
    from dospcot.config.presets import did_you_mean
    from dospcot.run.sizes import check_sizes
    from dospcot_lab.studies import get_study, header_command, run_study, sweep_spec

    repo = _repository(args, needed=args.docs)
    try:
        study = get_study(args.study)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    if args.runs_dir is None:  # relative, as the pages' headers name it
        args.runs_dir = Path(os.path.relpath(repo.root / "runs" / "sweeps")) if repo else Path("runs/sweeps")
    names = [sweep.name for sweep in study.sweeps]
    for name in args.sweeps:
        if name not in names:
            raise ConfigError(
                f"{args.study} has no sweep {name!r}{did_you_mean(name, names, 'its sweeps', None)}"
            )
    specs = [sweep_spec(sweep, 1, args.overrides) for sweep in study.sweeps]
    for spec in specs:  # a --set of a key a sweep's grid varies would lose to it
        check_overrides(args.overrides, list(spec.grid), "--seeds", f"the study's grid of {spec.configs[0]}:")
    # Its sweeps' cells, read with the overrides (a bad key is named, --render-only or not), then
    # weighed over its seeds before any sweep starts.
    cells = [cfg for spec in specs for cfg in spec.cell_configs()]
    if not args.render_only:
        seeds = args.seeds or study.seeds
        for line in check_sizes(cells, seeds, args.workers, min(args.batch_seeds or 1, max(seeds, 1))):
            print(f"dospcot-lab study: warning: {line}", file=sys.stderr)
    options = list(argv)[list(argv).index(args.study) + 1 :]
    header = header_command(("dospcot-lab", "study"), args.study, options)
    run_study(args, header, repo, prog="dospcot-lab study: error")
    return 0


def _bench(args: argparse.Namespace, command: str) -> int:
    from dospcot_lab.bench import run_benchmarks

    if args.out is None:
        args.out = QUICK_BENCH_OUT if args.quick else _repository(args, needed=True).benchmarks
    elif args.quick and args.out.name == "BENCHMARKS.md":
        raise ValueError(
            "--quick figures are a smoke test and never go into BENCHMARKS.md; leave out --out (they go "
            f"to {QUICK_BENCH_OUT}) or name another file"
        )
    rows = run_benchmarks(args.out, args.quick, args.repeats, command, args.only, args.device)
    for row in rows:
        verdict = "met" if row.met else "not met"
        print(f"{row.name}: ratio {row.ratio:.3f} (target {row.target_text}, {verdict})")
    print(f"wrote {args.out}")
    return 0


def _record(args: argparse.Namespace) -> int:
    from dospcot_lab.record import Record, write_size

    repo = _repository(args, needed=True)
    record = Record(repo.root)
    if args.write:
        write_size(record, repo.runs_readme)
        print(f"wrote {repo.runs_readme}")
    else:
        print(record.size_paragraph())
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``dospcot-lab`` with ``argv`` (default: the process's arguments); return the exit status."""
    from dospcot.config.errors import ConfigError
    from dospcot.run.interrupts import Interrupted, stop_on_signals
    from dospcot.sweeps.sweep_spec import SweepError

    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    command = shlex.join(["dospcot-lab", *argv])
    try:
        with stop_on_signals():
            if args.command == "study":
                return _study(args, argv)
            if args.command == "bench":
                return _bench(args, command)
            return _record(args)
    except (ConfigError, SweepError, ValueError) as err:  # NotARepository is a ValueError
        print(f"dospcot-lab {args.command}: error: {err}", file=sys.stderr)
        return 2
    except Interrupted as stop:
        print(f"dospcot-lab {args.command}: interrupted; kept {stop}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"dospcot-lab {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
