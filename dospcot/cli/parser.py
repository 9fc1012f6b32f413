"""The ``dospcot`` command line's parser: building it imports neither torch nor stable-baselines3, so
that ``--help`` and usage errors answer at once."""

from __future__ import annotations

import argparse
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from dospcot.rating import add_rate_parser  # torch-free: rate imports its server when it runs
from dospcot.run.cores import usable_cores

SEED_MAX = 2**63 - 1
"""The largest seed: a config holds 64-bit integers (TOML's)."""


def parse_seeds(text: str) -> Sequence[int]:
    """``"10"`` -> seeds 0..9 (a ``range``: a huge count is refused by its size check, not built);
    ``"3,5,7"`` -> those seeds; ``"100-104"`` -> seeds 100 to 104, both ends included (a ``range``)."""
    try:
        if "-" in text.strip()[1:]:  # a range's dash follows its first seed
            first, last = (int(end) for end in text.split("-", 1))
            if first < 0 or last < first:
                raise argparse.ArgumentTypeError(
                    f"--seeds {text}: a range runs from a seed >= 0 up to a seed no smaller, as in 100-104"
                )
            if last > SEED_MAX:
                raise argparse.ArgumentTypeError(f"--seeds takes seeds up to {SEED_MAX:,}, got {last}")
            return range(first, last + 1)
        if "," in text:
            items = [s.strip() for s in text.split(",")]
            if "" in items:
                raise argparse.ArgumentTypeError(
                    f"--seeds {text}: an empty item between commas; write the seeds as 0,3,7"
                )
            seeds: Sequence[int] = [int(s) for s in items]
        else:
            seeds = range(int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--seeds takes a count (10), a list (0,3,7) or a range (100-104), got {text!r}"
        ) from None
    if not seeds:
        raise argparse.ArgumentTypeError(
            f"--seeds {text} gives no seed: give a count >= 1 (10) or a list of seeds (0,3,7)"
        )
    if isinstance(seeds, list) and (any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds)):
        raise argparse.ArgumentTypeError(f"--seeds takes distinct seeds >= 0, got {text!r}")
    if isinstance(seeds, list) and max(seeds) > SEED_MAX:  # a config's seed is a 64-bit integer
        raise argparse.ArgumentTypeError(f"--seeds takes seeds up to {SEED_MAX:,}, got {max(seeds)}")
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


def seed_value(text: str) -> int:
    """``--seed``: a config's seed, a 64-bit integer >= 0."""
    wanted = f"--seed takes a seed from 0 to {SEED_MAX:,}, got {{text}}"
    return _number(text, int, lambda v: 0 <= v <= SEED_MAX, wanted, wanted)


def folder_path(text: str) -> Path:
    """A folder option's path; an empty one is refused (``Path("")`` is the current folder, which
    no one means by typing nothing)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder, got an empty path (write . for this folder)")
    return Path(text)


def file_path(text: str) -> Path:
    """An output file option's path; an empty one is refused (it names no file)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a file, got an empty path")
    return Path(text)


def folder_name(text: str) -> str:
    """A name of one folder inside ``--runs-dir``: the rule every run's and sweep's name follows
    (:func:`~dospcot.config.run_configs.folder_name_problem`)."""
    from dospcot.config.run_configs import folder_name_problem

    problem = folder_name_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"expected one folder's name, got {text!r}: {problem}")
    return text


def thread_count(text: str) -> int:
    """``--threads``: from 1 to the machine's CPUs (torch fails to start more threads than it can map,
    and more than the CPUs only take turns)."""
    cpus = os.cpu_count() or 1
    wanted = f"expected a thread count from 1 to this machine's {cpus} CPUs, got {{text}}"
    return _number(text, int, lambda v: 1 <= v <= cpus, wanted, wanted)


def add_overrides(parser: argparse.ArgumentParser, help: str) -> None:
    """The ``--set KEY=VALUE`` option (repeatable) of a command that reads configs."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=help
    )


def add_workers(parser: argparse.ArgumentParser, help: str) -> None:
    """The ``--workers N`` option of a command that runs trials in processes: by default every core this
    process may use (:func:`~dospcot.run.cores.usable_cores`), since no run's numbers depend on N."""
    cores = usable_cores()
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=cores,
        help=f"{help} (default: the cores this process may use, {cores} here)",
    )


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line (and exit status 2), as every other
    error of the CLI, and which takes no abbreviated option: argparse would read ``--seed 3`` as
    ``--seeds 3``, a batch of seeds 0-2 where one run of seed 3 was meant."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        wrong = re.match(r"argument (\S+): invalid choice: '([^']*)' \(choose from (.*)\)$", message)
        if wrong:  # a misspelt command or choice: the name meant, not the whole list
            from dospcot.config.presets import did_you_mean

            choices = re.findall(r"'([^']*)'", wrong.group(3))
            hint = did_you_mean(wrong.group(2), choices, "choose from", shown=None)
            message = f"argument {wrong.group(1)}: invalid choice: {wrong.group(2)!r}{hint}"
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class CommandParser(OneLineParser):
    """A command's parser (``dospcot train``, ...): it names what it does not take itself, with the
    option meant where one is close, rather than leaving the top parser to say it of ``dospcot``."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, extras = super().parse_known_args(args, namespace)
        if extras:
            from dospcot.config.presets import did_you_mean

            options = [o for o in self._option_string_actions if o.startswith("--")]
            hints = (did_you_mean(e.partition("=")[0], options, None) for e in extras if e.startswith("--"))
            hint = next((h for h in hints if h), "")
            self.error(f"unrecognized arguments: {' '.join(extras)}{hint}")
        return parsed, extras


DESCRIPTION = (
    "Train reinforcement-learning agents on mostly hidden rewards: agents with different views "
    "co-train on the labelled rewards and on the pseudo-rewards their reward classifiers agree on. "
    "Start with `dospcot train tiny`; `dospcot COMMAND --help` explains each command."
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command; building it imports neither torch nor stable-baselines3, so that
    ``--help`` and usage errors answer at once."""
    from dospcot import __version__
    from dospcot.config.presets import PAPER_PRESETS

    parser = OneLineParser(prog="dospcot", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"dospcot {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=CommandParser)
    train = commands.add_parser(
        "train",
        help="train one run of a config (a shipped preset or a .toml path)",
        description="Train one neural run and write runs/<name>/<stamp>/ (config, TensorBoard, "
        "metrics.csv, summary.json, agents, classifiers, plots, checkpoint).",
    )
    train.add_argument("config", nargs="?", help="a preset name (see --list) or a path to a .toml")
    add_overrides(train, "override a config key, e.g. --set training.rounds=3 --set seed=2 (repeatable)")
    train.add_argument(
        "--resume", type=folder_path, metavar="RUN_DIR", help="continue a killed run from its checkpoint"
    )
    train.add_argument(
        "--runs-dir", type=folder_path, default=Path("runs"), help="where runs write (default runs)"
    )
    train.add_argument("--seed", type=seed_value, help="the run's seed (the same as --set seed=N)")
    train.add_argument(
        "--seeds",
        type=parse_seeds,
        help="train these seeds of the config as one batch in one process, a run folder each: a count "
        "(10 means seeds 0-9), a comma list (0,3,7) or a range (100-104) (docs/batched_seeds.md)",
    )
    train.add_argument("--list", action="store_true", help="list the shipped presets and exit")
    train.add_argument(
        "--threads",
        type=thread_count,
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
    evaluate.add_argument("run_dir", type=folder_path, help="a run folder, runs/<name>/<stamp>")
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
    add_workers(sweep, "trials at once")
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
        "--name",
        type=folder_name,
        help="the sweep folder's name under --runs-dir (default: from the first config's name)",
    )
    sweep.add_argument(
        "--runs-dir",
        type=folder_path,
        default=Path("runs/sweeps"),
        help="where sweeps write (default runs/sweeps)",
    )
    sweep.add_argument(
        "--resume", type=folder_path, metavar="SWEEP_DIR", help="run the unfinished trials of a sweep"
    )
    sweep.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    report = commands.add_parser(
        "report",
        help="aggregate a sweep's runs: tables (mean, 95%% bootstrap interval, IQM) and plots",
        description="Write report.md, report.csv and PNG plots from the finished trials of a sweep.",
    )
    report.add_argument("sweep_dir", type=folder_path, help="a sweep folder, runs/sweeps/<name>")
    report.add_argument("--out", type=folder_path, help="output folder (default: the sweep folder)")
    paper = commands.add_parser(
        "reproduce-paper",
        help="the seed paper's CliffWalking protocol (Tables 1-4) with real reward masking",
        description="Sweep a paper-protocol preset over seeds and report it: dospcot sweep PRESET --seeds "
        "... --runs-dir OUT --name <stamp>, then dospcot report on that folder (report.md, report.csv, "
        "paper_agreement.png).",
    )
    paper.add_argument(
        "--preset",
        choices=sorted({*PAPER_PRESETS, *PAPER_PRESETS.values()}),
        default="paper-text",
        help="paper-text: the paper's stated hyperparameters; published-code (or paper-published-code, "
        "the config preset's own name): its code's",
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
    add_workers(paper, "processes")
    paper.add_argument(
        "--out",
        type=folder_path,
        default=Path("runs/paper"),
        help="where the sweep folder goes (default runs/paper)",
    )
    paper.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_rate_parser(commands)
    config = commands.add_parser(
        "config",
        help="print a config as TOML, resolved, each key with its default and meaning",
        description="Read a preset or a .toml (its extends chain and --set overrides applied), check it as "
        "dospcot train would, and print it as TOML: every key the run reads, with a comment giving the "
        "key's default and one-line meaning (docs/guide/configuration.md holds the same table).",
    )
    config.add_argument(
        "config", metavar="CONFIG", help="a preset name (see train --list) or a path to a .toml"
    )
    add_overrides(config, "override a key, as dospcot train's --set (repeatable)")
    return parser
