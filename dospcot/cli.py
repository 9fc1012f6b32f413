"""The ``dospcot`` command line."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path


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
    if not seeds or any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"--seeds needs at least one distinct seed >= 0, got {text!r}")
    return seeds


def parse_fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--label-fraction takes a number in (0, 1], got {text!r}") from None
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"--label-fraction must lie in (0, 1], got {text}")
    return value


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from dospcot.paper import PRESETS

    parser = argparse.ArgumentParser(prog="dospcot", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    paper = commands.add_parser(
        "reproduce-paper",
        help="the seed paper's CliffWalking protocol (Tables 1-4) with real reward masking",
        description="Train every run of the seed paper's protocol and write tables.md / tables.csv.",
    )
    paper.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default="paper-text",
        help="paper-text: the paper's stated hyperparameters; published-code: its code's",
    )
    paper.add_argument(
        "--label-fraction",
        type=parse_fraction,
        default=0.1,
        help="share of (state, action) keys whose reward is revealed (default 0.1)",
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
        default=500,
        help="episodes per agent per round (default 500, the paper's; fewer for a quick look)",
    )
    paper.add_argument("--workers", type=positive_int, default=2, help="processes (default 2)")
    paper.add_argument(
        "--out", type=Path, default=Path("runs/paper"), help="output folder (default runs/paper)"
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
        "--out", type=Path, default=Path("BENCHMARKS.md"), help="output file (default BENCHMARKS.md)"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    if args.command == "reproduce-paper":
        from dospcot.paper import reproduce_paper

        run_dir = reproduce_paper(
            preset=args.preset,
            label_fraction=args.label_fraction,
            seeds=args.seeds,
            episodes=args.episodes,
            workers=args.workers,
            out_dir=args.out,
            command=shlex.join(["dospcot", *argv]),
            show_progress=not args.no_progress,
        )
        summary = (run_dir / "summary.json").read_text()
        print(f"wrote {run_dir}/tables.md and tables.csv")
        print(f"wall time: {json.loads(summary)['wall_time_s']:.1f} s")
    elif args.command == "bench":
        from dospcot.bench import run_benchmarks

        rows = run_benchmarks(args.out, args.quick, args.repeats, shlex.join(["dospcot", *argv]))
        for row in rows:
            print(
                f"{row.name}: ratio {row.ratio:.3f} (target {row.target}, {'met' if row.met else 'not met'})"
            )
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
