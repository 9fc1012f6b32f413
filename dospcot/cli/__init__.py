"""The ``dospcot`` command line: ``dospcot --help`` lists its commands (:mod:`dospcot.cli.parser`);
each has one handler (:mod:`dospcot.cli.commands`), whose bad inputs end in one line and exit status 2."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from collections.abc import Sequence

from dospcot.cli.commands import RUN_COMMANDS
from dospcot.cli.parser import build_parser

PIPE_CLOSED = 141
"""The exit status where the reader of stdout went away (``dospcot train --list | head -5``): the
shell's for a writer a closed pipe stopped (128 + SIGPIPE), without a word."""


INTERRUPTED = 130
"""The exit status of a command stopped by Ctrl-C or SIGTERM (128 + SIGINT)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``dospcot`` with ``argv`` (default: the process's arguments); return the exit status.

    Run as the program itself (``argv`` None), a stopped command ends the process at once once it has
    said what it kept: its children are stopped and its files closed, and unloading torch and the rest
    would take longer than the stop itself (over a second on a busy machine).
    """
    try:
        status = _main(argv)
        sys.stdout.flush()  # a closed pipe shows here at the latest, not as Python exits
        if argv is None and status == INTERRUPTED:
            sys.stderr.flush()
            os._exit(status)
    except BrokenPipeError:
        # The standard recipe: what is still buffered goes nowhere, and the process ends quietly.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return PIPE_CLOSED
    return status


LAB_COMMANDS = ("study", "bench")
"""Commands that live in the repository's lab (``dospcot-lab``), not in the library."""


def _main(argv: Sequence[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in LAB_COMMANDS:
        print(
            f"dospcot {argv[0]}: error: the studies and benchmarks are the repository's lab, not part of the "
            f"library: in a checkout of the dospcot repository, run `dospcot-lab {argv[0]} ...` "
            "(`make install` installs it)",
            file=sys.stderr,
        )
        return 2
    args = build_parser().parse_args(argv)
    command = shlex.join(["dospcot", *argv])
    if args.command == "train" and args.list:  # before any import of torch: a list answers at once
        from dospcot.config.presets import preset_names

        print("\n".join(preset_names()))
        return 0
    if args.command == "config":  # torch-free too: a config reads without the training stack
        from dospcot.config.errors import ConfigError

        try:
            return RUN_COMMANDS["config"](args, command)
        except ConfigError as err:
            print(f"dospcot config: error: {err}", file=sys.stderr)
            return 2
    from dospcot.run.interrupts import Interrupted, stop_on_signals

    try:
        with stop_on_signals():
            return _run(args, command)
    except Interrupted as stop:  # Ctrl-C or SIGTERM: what was kept, and how to go on
        print(f"dospcot {args.command}: interrupted; kept {stop}", file=sys.stderr)
        return INTERRUPTED
    except KeyboardInterrupt:  # before the command knew what it kept
        # A sweep goes on from its folder when the same command runs again.
        resume = f"; kept nothing new; resume with: {command}" if args.command == "sweep" else ""
        print(f"dospcot {args.command}: interrupted{resume}", file=sys.stderr)
        return INTERRUPTED


def _run(args: argparse.Namespace, command: str) -> int:
    """Run the parsed command; its bad inputs end in one line on stderr and exit status 2. Torch and the
    training stack load here only: past ``--help`` and usage errors."""
    from dospcot.config.errors import ConfigError, one_line
    from dospcot.envs import EnvRaisedError, NonFiniteError
    from dospcot.raters.file_rater import QueriesPending, RaterError
    from dospcot.run.run_folder import RunFolderError
    from dospcot.sweeps.sweep_spec import SweepError

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
        print(f"dospcot {args.command}: error: {one_line(str(err))}", file=sys.stderr)
        return 2
    except MemoryError as err:  # a buffer the size checks' lower bound let through (run/sizes.py)
        reason = str(err).strip() or "no detail"
        print(
            f"dospcot {args.command}: error: out of memory ({reason}); lower dqn.buffer_size or "
            "train fewer seeds at once",
            file=sys.stderr,
        )
        return 2
    except (NonFiniteError, EnvRaisedError) as err:  # the env's fault, not the command line's
        print(f"dospcot {args.command}: error: {err}", file=sys.stderr)
        return 1
