"""The rating page: ``dospcot rate RUN_DIR`` serves a run's waiting reward queries in the browser
(docs/guide/rating.md).

This module builds the command's parser and nothing else, so that ``dospcot --help`` imports neither
the web server (:mod:`dospcot.rating.server`, the ``rate`` extra) nor torch.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path


def _values(text: str) -> list[float]:
    """``--accept`` values: a number or a comma list of numbers."""
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--accept takes a reward or a comma list of rewards, got {text!r} (write --accept=-1 for -1)"
        ) from None


def _run_dir(text: str) -> Path:
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a run folder, got an empty path")
    return Path(text)


def _port(text: str) -> int:
    """``--port``: a TCP port, 1 to 65535, or 0 for a free one."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65_535:
        raise argparse.ArgumentTypeError(f"expected a port from 1 to 65535 (0: a free one), got {text!r}")
    return port


def add_rate_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``rate`` command to the CLI's sub-parsers; returns its parser."""
    rate = commands.add_parser(
        "rate",
        help="answer a run's waiting reward queries on a local page in the browser",
        description='Serve the reward queries a run with training.rater = "file" waits on '
        "(queries/round_<r>.csv) on a page at 127.0.0.1 and print its address, which carries a random "
        "token. Every answer is written to the round's CSV as it is given; then resume with dospcot "
        "train --resume RUN_DIR, or give --then-train. Needs the rate extra (pip install 'dospcot[rate]').",
    )
    rate.add_argument("run_dir", type=_run_dir, metavar="RUN_DIR", help="a run folder, runs/<name>/<stamp>")
    rate.add_argument(
        "--host",
        default="127.0.0.1",
        help="the address to listen on (default 127.0.0.1: this machine only; the token is needed on any)",
    )
    rate.add_argument("--port", type=_port, default=0, help="the port (default: a free one)")
    rate.add_argument(
        "--then-train",
        action="store_true",
        help="when every query is answered and you press Resume on the page, resume the run here",
    )
    rate.add_argument(
        "--accept",
        type=_values,
        action="extend",
        default=[],
        metavar="VALUE",
        help="serve nothing: confirm VALUE (a comma list) as a new reward value on every row of the round's "
        "CSV that answers it, for people who answer in the file (--accept=-1 for a negative value)",
    )
    rate.add_argument("--no-progress", action="store_true", help="with --then-train: hide the progress bar")
    return rate


def rate_command(
    args: argparse.Namespace, command: str, train: Callable[[argparse.Namespace, str], int]
) -> int:
    """The handler of ``dospcot rate``: serve the page (:func:`dospcot.rating.server.rate`) and, where
    ``--then-train`` was given and the page asked to resume, resume the run; when the run stops again for
    its next round's queries, serve those, until the run finishes or the page is left (Ctrl-C).

    :param train: the CLI's ``train`` handler, which resumes the run as ``dospcot train --resume`` does.
    """
    from dospcot.raters.file_rater import QueriesPending
    from dospcot.rating.server import rate  # the web server, imported only when the command runs

    options = {"config": None, "overrides": [], "seed": None, "seeds": None, "threads": 1}
    while rate(args) and args.then_train:  # every query answered, and the page asked to resume
        try:
            return train(
                argparse.Namespace(resume=args.run_dir, no_progress=args.no_progress, **options), command
            )
        except QueriesPending as pending:  # the next round asks: served as this one was, not an exit
            print(f"{args.run_dir}: the run stopped for {pending.count} new reward queries ({pending.path})")
    return 0
