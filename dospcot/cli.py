"""The ``dospcot`` command line."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from dospcot.rating import add_rate_parser, rate_command  # torch-free: rate imports its server when it runs

QUICK_BENCH_OUT = Path("runs/bench-quick.md")
"""Where ``dospcot bench --quick`` writes its smoke-test figures."""


def parse_seeds(text: str) -> list[int]:
    """``"10"`` -> seeds 0..9; ``"3,5,7"`` -> those seeds."""
    try:
        if "," in text:
            seeds = [int(s) for s in text.split(",") if s.strip()]
        else:
            seeds = list(range(int(text)))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--seeds takes a count (10) or a list (0,3,7), got {text!r}"
        ) from None
    if not seeds:
        raise argparse.ArgumentTypeError(
            f"--seeds {text} gives no seed: give a count >= 1 (10) or a list of seeds (0,3,7)"
        )
    if any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"--seeds takes distinct seeds >= 0, got {text!r}")
    return seeds


def _number(text: str, kind: type, allowed: Callable[[Any], bool], unreadable: str, outside: str) -> Any:
    """``text`` read as a ``kind`` that ``allowed`` accepts; otherwise an argparse error, ``unreadable``
    or ``outside`` with ``{text}`` filled in."""
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(unreadable.format(text=repr(text))) from None
    if not allowed(value):
        raise argparse.ArgumentTypeError(outside.format(text=value))
    return value


def parse_fraction(text: str) -> float:
    unreadable = "--label-fraction takes a number in (0, 1], got {text}"
    outside = "--label-fraction must lie in (0, 1], got {text}"
    return _number(text, float, lambda v: 0 < v <= 1, unreadable, outside)


def positive_int(text: str) -> int:
    wanted = "expected a positive integer, got {text}"
    return _number(text, int, lambda v: v >= 1, wanted, wanted)


def add_overrides(parser: argparse.ArgumentParser, help: str) -> None:
    """The ``--set KEY=VALUE`` option (repeatable) of a command that reads configs."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=help
    )


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line (and exit status 2), as every other
    error of the CLI."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command; building it imports neither torch nor stable-baselines3, so that
    ``--help`` and usage errors answer at once."""
    from dospcot.config.presets import PAPER_PRESETS

    parser = OneLineParser(prog="dospcot", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    train = commands.add_parser(
        "train",
        help="train one run of a config (a shipped preset or a .toml path)",
        description="Train one neural run and write runs/<name>/<stamp>/ (config, TensorBoard, "
        "metrics.csv, summary.json, agents, classifiers, plots, checkpoint).",
    )
    train.add_argument("config", nargs="?", help="a preset name (see --list) or a path to a .toml")
    add_overrides(train, "override a config key, e.g. --set training.rounds=3 --set seed=2 (repeatable)")
    train.add_argument(
        "--resume", type=Path, metavar="RUN_DIR", help="continue a killed run from its checkpoint"
    )
    train.add_argument("--runs-dir", type=Path, default=Path("runs"), help="where runs write (default runs)")
    train.add_argument(
        "--seeds",
        type=parse_seeds,
        help="train these seeds of the config as one batch in one process, a run folder each: a count "
        "(10 means seeds 0-9) or a comma list (docs/batched_seeds.md)",
    )
    train.add_argument("--list", action="store_true", help="list the shipped presets and exit")
    train.add_argument(
        "--threads",
        type=positive_int,
        default=1,
        help="torch threads (default 1: small networks run fastest on one, and parallel runs do not "
        "oversubscribe the cores)",
    )
    train.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    evaluate = commands.add_parser(
        "evaluate",
        help="re-evaluate the saved agents of a run folder",
        description="Load agent_<view>.zip with plain stable_baselines3.DQN.load and evaluate them "
        "greedily on the run's task; writes evaluation.json.",
    )
    evaluate.add_argument("run_dir", type=Path, help="a run folder, runs/<name>/<stamp>")
    sweep = commands.add_parser(
        "sweep",
        help="train every combination of a grid of config values over seeds, each as its own run",
        description="Train every config x grid combination x seed as a run folder under "
        "SWEEP_DIR/trials/. Running the same command again (or --resume) runs only the unfinished trials.",
    )
    sweep.add_argument("configs", nargs="*", metavar="CONFIG", help="one or more presets or .toml paths")
    sweep.add_argument(
        "--grid",
        action="extend",
        nargs="+",
        default=[],
        metavar="KEY=V1,V2",
        help="a config key and its values, e.g. training.label_fraction=0.01,0.1 "
        "cotraining.consensus_weight=0,0.3",
    )
    sweep.add_argument(
        "--seeds",
        type=parse_seeds,
        help="a count (5 means seeds 0-4) or a comma list (default 1); with --resume, seeds to add "
        "to the sweep (a count or list that holds its own seeds): only the new seeds' trials run",
    )
    add_overrides(sweep, "override a key in every trial (repeatable)")
    sweep.add_argument("--backend", choices=["local", "ray"], default="local", help="default local")
    sweep.add_argument("--workers", type=positive_int, default=2, help="trials at once (default 2)")
    sweep.add_argument(
        "--batch-seeds",
        type=positive_int,
        metavar="K",
        help="train each cell's seeds in batches of at most K per process (local backend; "
        "docs/batched_seeds.md); default: the sweep's own, kept in its sweep.json, and 1 (every trial "
        "alone) for a new sweep",
    )
    sweep.add_argument(
        "--ray-address", metavar="ADDRESS", help="an existing Ray cluster (default: start a local instance)"
    )
    sweep.add_argument(
        "--name", help="the sweep folder's name under --runs-dir (default: from the first config's name)"
    )
    sweep.add_argument(
        "--runs-dir", type=Path, default=Path("runs/sweeps"), help="where sweeps write (default runs/sweeps)"
    )
    sweep.add_argument(
        "--resume", type=Path, metavar="SWEEP_DIR", help="run the unfinished trials of a sweep"
    )
    sweep.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    report = commands.add_parser(
        "report",
        help="aggregate a sweep's runs: tables (mean, 95%% bootstrap interval, IQM) and plots",
        description="Write report.md, report.csv and PNG plots from the finished trials of a sweep.",
    )
    report.add_argument("sweep_dir", type=Path, help="a sweep folder, runs/sweeps/<name>")
    report.add_argument("--out", type=Path, help="output folder (default: the sweep folder)")
    paper = commands.add_parser(
        "reproduce-paper",
        help="the seed paper's CliffWalking protocol (Tables 1-4) with real reward masking",
        description="Sweep a paper-protocol preset over seeds and report it: dospcot sweep PRESET --seeds "
        "... --runs-dir OUT --name <stamp>, then dospcot report on that folder (report.md, report.csv, "
        "paper_agreement.png).",
    )
    paper.add_argument(
        "--preset",
        choices=sorted(PAPER_PRESETS),
        default="paper-text",
        help="paper-text: the paper's stated hyperparameters; published-code: its code's "
        "(the config presets paper-text and paper-published-code)",
    )
    paper.add_argument(
        "--label-fraction",
        type=parse_fraction,
        help="share of (state, action) keys whose reward is revealed (default: the preset's, 0.1)",
    )
    paper.add_argument(
        "--seeds",
        type=parse_seeds,
        default=list(range(10)),
        help="a count (10 means seeds 0-9) or a comma list (default 10)",
    )
    paper.add_argument(
        "--episodes",
        type=positive_int,
        help="episodes per agent per round (default: the preset's, 500, the paper's; fewer for a quick look)",
    )
    add_overrides(paper, "override a key of the preset, e.g. --set tabular.replay_sweeps=0 (repeatable)")
    paper.add_argument("--workers", type=positive_int, default=2, help="processes (default 2)")
    paper.add_argument(
        "--out",
        type=Path,
        default=Path("runs/paper"),
        help="where the sweep folder goes (default runs/paper)",
    )
    paper.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    bench = commands.add_parser(
        "bench",
        help="measure performance claims against their peers and write BENCHMARKS.md",
        description="Run every benchmark (ours and a peer in the same run) and write BENCHMARKS.md.",
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
        type=Path,
        help=f"output file (default BENCHMARKS.md; with --quick {QUICK_BENCH_OUT}, never BENCHMARKS.md)",
    )
    bench.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default="cpu",
        help="cuda: measure the rows that have a GPU form on the GPU, into the GPU column of --out's "
        "table (default cpu)",
    )
    study = commands.add_parser(
        "study",
        description="Run a study's sweeps (only the trials not yet finished), then print its tables from "
        "every finished run; with --docs also write docs/results/<study>.md and its row of the results "
        "at a glance.",
        help="one of the published studies: its sweeps, then its tables (with --docs, its docs page)",
    )
    add_overrides(study, "override a key in every trial (repeatable; the study then writes its own sweeps)")
    # No choices: the studies' names live with their declarations, which import torch.
    study.add_argument("study", metavar="STUDY", help="the study, e.g. grid16 (a wrong name lists them)")
    study.add_argument("--seeds", type=int, help="seeds 0..N-1 (default: the study's)")
    study.add_argument("--workers", type=positive_int, default=2, help="trials at once (default 2)")
    study.add_argument(
        "--batch-seeds",
        type=positive_int,
        metavar="K",
        help="as dospcot sweep's (default: each sweep's own, 1 for a new one)",
    )
    study.add_argument("--backend", choices=["local", "ray"], default="local", help="default local")
    study.add_argument("--runs-dir", type=Path, default=Path("runs/sweeps"), help="default runs/sweeps")
    study.add_argument("--docs", action="store_true", help="also write docs/results/<study>.md (and its row)")
    study.add_argument("--render-only", action="store_true", help="train nothing: tables from finished runs")
    add_rate_parser(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    command = shlex.join(["dospcot", *argv])
    if args.command == "train" and args.list:  # before any import of torch: a list answers at once
        from dospcot.config.presets import preset_names

        print("\n".join(preset_names()))
        return 0
    from dospcot.experiment.interrupts import Interrupted, stop_on_signals

    try:
        with stop_on_signals():
            return _run(args, command)
    except Interrupted as stop:  # Ctrl-C or SIGTERM: what was kept, and how to go on
        print(f"dospcot {args.command}: interrupted; kept {stop}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print(f"dospcot {args.command}: interrupted", file=sys.stderr)
        return 130


def _run(args: argparse.Namespace, command: str) -> int:
    """Run the parsed command; its bad inputs end in one line on stderr and exit status 2."""
    if args.command in RUN_COMMANDS:
        from dospcot.config.errors import ConfigError
        from dospcot.core.raters import QueriesPending, RaterError
        from dospcot.envs import EnvRaisedError, NonFiniteError
        from dospcot.experiment.run_folder import RunFolderError
        from dospcot.experiment.sweep_spec import SweepError

        try:
            return RUN_COMMANDS[args.command](args, command)
        except QueriesPending as pending:  # not an error: the run waits for a person's answers
            run_dir = pending.path.parent.parent
            print(
                f"{run_dir}: {pending.count} reward queries wait in {pending.path}; write each answer in its "
                f"reward column, then: dospcot train --resume {run_dir}"
            )
            return 0
        except (ConfigError, RunFolderError, SweepError, RaterError) as err:
            print(f"dospcot {args.command}: error: {err}", file=sys.stderr)
            return 2
        except (NonFiniteError, EnvRaisedError) as err:  # the env's fault, not the command line's
            print(f"dospcot {args.command}: error: {err}", file=sys.stderr)
            return 1
    if args.command == "bench":
        from dospcot.experiment.bench import run_benchmarks

        if args.out is None:
            args.out = QUICK_BENCH_OUT if args.quick else Path("BENCHMARKS.md")
        elif args.quick and args.out.name == "BENCHMARKS.md":
            print(
                "dospcot bench: error: --quick figures are a smoke test and never go into BENCHMARKS.md; "
                f"leave out --out (they go to {QUICK_BENCH_OUT}) or name another file",
                file=sys.stderr,
            )
            return 2
        try:
            rows = run_benchmarks(args.out, args.quick, args.repeats, command, args.only, args.device)
        except ValueError as err:
            print(f"dospcot bench: error: {err}", file=sys.stderr)
            return 2
        for row in rows:
            print(
                f"{row.name}: ratio {row.ratio:.3f} (target {row.target}, {'met' if row.met else 'not met'})"
            )
        print(f"wrote {args.out}")
    return 0


def _train(args: argparse.Namespace, command: str) -> int:
    import torch

    from dospcot.config.errors import ConfigError
    from dospcot.config.loading import load_config
    from dospcot.config.presets import preset_names
    from dospcot.experiment.run_folder import batch_members
    from dospcot.experiment.train import resume, run_config, train
    from dospcot.experiment.train_batch import resume_batch, train_seeds

    torch.set_num_threads(args.threads)
    progress = not args.no_progress
    if args.resume is not None:
        if args.config or args.overrides or args.seeds:
            raise ConfigError(
                "--resume RUN_DIR takes no CONFIG, --set or --seeds: the run folder holds its config"
            )
        if batch_members(args.resume) is not None:
            run_dirs = resume_batch(args.resume, show_progress=progress, command=command)
        else:
            run_dirs = [resume(args.resume, show_progress=progress, command=command)]
    else:
        if not args.config:
            raise ConfigError(f"give a CONFIG: a preset ({', '.join(preset_names())}) or a path to a .toml")
        cfg = load_config(args.config, args.overrides)
        if args.seeds is not None:
            run_dirs = train_seeds(cfg, args.seeds, args.runs_dir, show_progress=progress, command=command)
        else:
            run_dirs = [train(cfg, args.runs_dir, show_progress=progress, command=command)]
    for run_dir in run_dirs:
        summary = json.loads((run_dir / "summary.json").read_text())
        print(run_config(run_dir).task_definition.result_line(run_dir, summary))
    return 0


def _evaluate(args: argparse.Namespace, command: str) -> int:
    from dospcot.experiment.train import evaluate

    result = evaluate(args.run_dir)
    state = "finished" if result["finished"] else "unfinished"
    print(f"{args.run_dir}: the agents of round {result['round']} of {result['rounds']} ({state})")
    for view, row in result["per_view"].items():
        print(
            f"{view:>8}: return {row['greedy_return']:8.1f}  success {row['success']:.0f}  "
            f"normalised score {row['normalised_score']:.3f}  agreement {row['agreement']:.3f}"
        )
    if result["finished"]:
        print(f"wrote {args.run_dir / 'evaluation.json'}")
    else:
        print("nothing written: the run is unfinished, and a resume would make a file of it stale")
    return 0


def _sweep(args: argparse.Namespace, command: str) -> int:
    from dospcot.config.errors import ConfigError
    from dospcot.experiment.sweep import default_sweep_dir, run_sweep
    from dospcot.experiment.sweep_spec import SweepSpec, add_seeds, parse_grid

    if args.ray_address and args.backend != "ray":
        raise ConfigError("--ray-address names a Ray cluster: it needs --backend ray")
    if args.resume is not None:
        if args.configs or args.grid or args.overrides or args.name:
            raise ConfigError(
                "--resume SWEEP_DIR takes no CONFIG, --grid, --set or --name: the folder holds them"
            )
        sweep_dir, spec = args.resume, None
        if args.seeds is not None:
            spec = add_seeds(sweep_dir, args.seeds)
    else:
        if not args.configs:
            raise ConfigError("give at least one CONFIG: a preset (see dospcot train --list) or a .toml path")
        seeds = tuple(args.seeds or (0,))
        spec = SweepSpec(tuple(args.configs), parse_grid(args.grid), seeds, tuple(args.overrides))
        sweep_dir = args.runs_dir / args.name if args.name else default_sweep_dir(args.configs, args.runs_dir)
    result = run_sweep(
        sweep_dir, spec, backend=args.backend, workers=args.workers, ray_address=args.ray_address,
        show_progress=not args.no_progress, batch_seeds=args.batch_seeds,
    )  # fmt: skip
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


def _report(args: argparse.Namespace, command: str) -> int:
    from dospcot.experiment.report import write_report

    paths = write_report(args.sweep_dir, args.out)
    print(paths[0].read_text())
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _reproduce_paper(args: argparse.Namespace, command: str) -> int:
    import time

    from dospcot.config.errors import ConfigError
    from dospcot.config.presets import PAPER_PRESETS
    from dospcot.experiment.report import write_report
    from dospcot.experiment.run_folder import new_run_dir
    from dospcot.experiment.sweep import run_sweep
    from dospcot.experiment.sweep_spec import SweepError, SweepSpec

    for option, key in (("--label-fraction", "label_fraction"), ("--episodes", "episodes_per_round")):
        given = [o for o in args.overrides if o.partition("=")[0].strip() == f"tabular.{key}"]
        if given and getattr(args, option[2:].replace("-", "_")) is not None:
            raise ConfigError(f"{option} and --set {given[0]} both set tabular.{key}: give it once")
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
    spec = SweepSpec((PAPER_PRESETS[args.preset],), {}, tuple(args.seeds), tuple(overrides))
    spec.trials()  # a bad --set fails here, before the folder is made
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


def _study(args: argparse.Namespace, command: str) -> int:
    from dospcot.config.errors import ConfigError
    from dospcot.experiment.studies import get_study, header_command, run_study

    try:
        get_study(args.study)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    options = shlex.split(command)[3:]  # what follows "dospcot study STUDY"
    run_study(args, header_command(("dospcot", "study"), args.study, options), prog="dospcot study: error")
    return 0


RUN_COMMANDS = {
    "train": _train,
    "evaluate": _evaluate,
    "sweep": _sweep,
    "report": _report,
    "reproduce-paper": _reproduce_paper,
    "study": _study,
    "rate": lambda args, command: rate_command(args, command, train=_train),  # --then-train: _train resumes
}
"""Commands whose bad configs and folders end in one line on stderr and exit status 2."""


if __name__ == "__main__":
    raise SystemExit(main())
