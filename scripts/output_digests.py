"""Guard what a user measures across refactors: the SHA-256 of ``metrics.csv`` and ``summary.json`` of
four presets (seed 0), shortened with ``--set`` so that each trains in seconds.

    python scripts/output_digests.py --write   # store the digests of the code as it is now
    python scripts/output_digests.py           # train again and compare (exit 1 on a difference)
    python scripts/output_digests.py --case grid16-dospcot

The stored digests live in ``scripts/output_digests.json`` beside this file; ``tests/test_output_digests.py``
runs the check, so a change that moves a number fails the tests. A deliberate change of the numbers
rewrites the file with ``--write`` in the commit that explains it.

Renamed keys: ``cotraining.gamma`` became ``cotraining.consensus_weight``; the ``gamma`` column of
``metrics.csv`` keeps its name (the record's reports read it), so no column changed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

DIGESTS = Path(__file__).with_name("output_digests.json")
FILES = ("metrics.csv", "summary.json")
CASES: dict[str, tuple[str, ...]] = {
    "grid16-dospcot": (
        "training.rounds=2",
        "training.steps_per_round=400",
        "dqn.learning_starts=100",
    ),
    "fasthighway-dospcot": (
        "training.rounds=2",
        "training.steps_per_round=200",
        "dqn.learning_starts=50",
        "highway.eval_episodes=2",
    ),
    "minigrid-doorkey-dospcot": (
        "training.rounds=2",
        "training.steps_per_round=300",
        "dqn.learning_starts=50",
        "gym.eval_episodes=2",
    ),
    "paper-text": ("tabular.rounds=2", "tabular.episodes_per_round=20"),
}
"""Each preset and the ``--set`` overrides that shorten it (seed 0, the presets' own)."""


def run_case(name: str, runs_dir: Path) -> dict[str, str]:
    """Train case ``name`` in a fresh folder under ``runs_dir``; the SHA-256 of each of :data:`FILES`."""
    sets = [arg for override in CASES[name] for arg in ("--set", override)]
    command = [sys.executable, "-m", "dospcot.cli", "train", name, *sets, "--runs-dir", str(runs_dir)]
    subprocess.run([*command, "--no-progress"], check=True, stdout=subprocess.DEVNULL)
    (run_dir,) = (path.parent for path in runs_dir.glob("*/*/summary.json"))
    return {file: hashlib.sha256((run_dir / file).read_bytes()).hexdigest() for file in FILES}


def digests(names: list[str]) -> dict[str, dict[str, str]]:
    """Every named case's digests, each trained in its own temporary folder."""
    out = {}
    for name in names:
        with tempfile.TemporaryDirectory() as tmp:
            out[name] = run_case(name, Path(tmp))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--write", action="store_true", help="store the digests instead of checking them")
    parser.add_argument("--case", action="append", choices=sorted(CASES), help="only this case (repeatable)")
    args = parser.parse_args(argv)
    names = args.case or list(CASES)
    found = digests(names)
    if args.write:
        stored = json.loads(DIGESTS.read_text()) if DIGESTS.is_file() else {}
        DIGESTS.write_text(json.dumps({**stored, **found}, indent=2, sort_keys=True) + "\n")
        print(f"wrote {DIGESTS} ({', '.join(names)})")
        return 0
    stored = json.loads(DIGESTS.read_text())
    differ = [f"{name}/{file}" for name in names for file in FILES if stored[name][file] != found[name][file]]
    for name in names:
        print(f"{name}: {'differs' if any(d.startswith(name + '/') for d in differ) else 'identical'}")
    if differ:
        print(f"changed: {', '.join(differ)}", file=sys.stderr)
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
