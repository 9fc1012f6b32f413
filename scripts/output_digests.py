"""Guard what a user measures across refactors: ``metrics.csv`` and ``summary.json`` of four presets
(seed 0), shortened with ``--set`` so that each trains in seconds, against the files stored here.

    python scripts/output_digests.py --write   # store the outputs of the code as it is now
    python scripts/output_digests.py           # train again and compare (exit 1 on a difference)
    python scripts/output_digests.py --case grid16-dospcot

The stored outputs live in ``scripts/output_digests.json`` beside this file, with the SHA-256 of each
file as it was written. ``tests/test_output_digests.py`` runs the check, so a change that moves a
number fails the tests; a deliberate change of the numbers rewrites the file with ``--write`` in the
commit that explains it.

The comparison reads every number to :data:`REL_TOL`, not to the last bit: torch picks its CPU
kernels per machine (AVX-512, AVX2 or none, and ``ATEN_CPU_CAPABILITY``), and two kernels may round a
float sum differently in its last digits. Text, integers, column names and row counts must match
exactly, and a change of the science moves numbers far beyond the tolerance.

The co-trained cases train under the first version of the defaults, whose classifiers fit under
numerics 1 (float64) rather than numerics 2 (float32), as version 3 and every version built on it
do: a float32 fit's last-digit rounding differs between kernels by enough to flip which samples a
round admits, so the same seed trains to other numbers on another CPU (the fast highway's case does,
between AVX2 and the portable kernels), and no stored file could hold for every machine. They guard
the code's numbers, not the adopted version's choices, so adopting a later version leaves them as
they are.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

DIGESTS = Path(__file__).with_name("output_digests.json")
FILES = ("metrics.csv", "summary.json")
REL_TOL = 1e-6
"""Relative tolerance of a float (absolute below 1e-9): far above the last-digit rounding of two CPU
kernels (about 1e-12 on a float64 loss), far below any change of what a run learns."""
CASES: dict[str, tuple[str, ...]] = {
    "grid16-dospcot": (
        "defaults=1",
        "training.rounds=2",
        "training.steps_per_round=400",
        "dqn.learning_starts=100",
    ),
    "fasthighway-dospcot": (
        "defaults=1",
        "training.rounds=2",
        "training.steps_per_round=200",
        "dqn.learning_starts=50",
        "highway.eval_episodes=2",
    ),
    "minigrid-doorkey-dospcot": (
        "defaults=1",
        "training.rounds=2",
        "training.steps_per_round=300",
        "dqn.learning_starts=50",
        "gym.eval_episodes=2",
    ),
    "paper-text": ("tabular.rounds=2", "tabular.episodes_per_round=20"),
}
"""Each preset and the ``--set`` overrides that shorten it (seed 0, the presets' own) and, for the
co-trained ones, pin version 1 of the defaults (see the module docstring)."""


def run_case(name: str, runs_dir: Path) -> dict[str, str]:
    """Train case ``name`` in a fresh folder under ``runs_dir``; the text of each of :data:`FILES`."""
    sets = [arg for override in CASES[name] for arg in ("--set", override)]
    command = [sys.executable, "-m", "dospcot.cli", "train", name, *sets, "--runs-dir", str(runs_dir)]
    subprocess.run([*command, "--no-progress"], check=True, stdout=subprocess.DEVNULL)
    (run_dir,) = (path.parent for path in runs_dir.glob("*/*/summary.json"))
    return {file: (run_dir / file).read_text() for file in FILES}


def _parsed(file: str, text: str) -> Any:
    """``text`` as rows of cells (a CSV, each cell a float where it reads as one) or as JSON."""
    if file.endswith(".json"):
        return json.loads(text)
    rows = list(csv.reader(io.StringIO(text)))
    return [rows[0], *([_number_or_text(cell) for cell in row] for row in rows[1:])]


def _number_or_text(cell: str) -> float | str:
    try:
        return float(cell)
    except ValueError:
        return cell


def differences(stored: Any, found: Any, where: str = "") -> list[str]:
    """Where ``found`` differs from ``stored``: floats beyond :data:`REL_TOL`, anything else at all."""
    if isinstance(stored, dict) and isinstance(found, dict):
        if stored.keys() != found.keys():
            return [f"{where}: keys {sorted(stored)} != {sorted(found)}"]
        return [d for key in stored for d in differences(stored[key], found[key], f"{where}/{key}")]
    if isinstance(stored, list) and isinstance(found, list):
        if len(stored) != len(found):
            return [f"{where}: {len(stored)} items != {len(found)}"]
        pairs = enumerate(zip(stored, found, strict=True))
        return [d for i, (a, b) in pairs for d in differences(a, b, f"{where}[{i}]")]
    floats = isinstance(stored, float) and isinstance(found, float)
    if floats and math.isclose(stored, found, rel_tol=REL_TOL, abs_tol=1e-9):
        return []
    if floats and math.isnan(stored) and math.isnan(found):
        return []
    if not floats and type(stored) is type(found) and stored == found:
        return []
    return [f"{where}: {stored!r} != {found!r}"]


def case_differences(stored: dict[str, Any], found: dict[str, str]) -> list[str]:
    """Every difference between a case's stored outputs and the texts ``found`` of its files."""
    return [
        f"{file}{where}"
        for file in FILES
        for where in differences(_parsed(file, stored[file]["text"]), _parsed(file, found[file]))
    ]


def _stored_form(texts: dict[str, str]) -> dict[str, dict[str, str]]:
    return {
        file: {"sha256": hashlib.sha256(text.encode()).hexdigest(), "text": text}
        for file, text in texts.items()
    }


def outputs(names: list[str]) -> dict[str, dict[str, str]]:
    """Every named case's file texts, each trained in its own temporary folder."""
    out = {}
    for name in names:
        with tempfile.TemporaryDirectory() as tmp:
            out[name] = run_case(name, Path(tmp))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--write", action="store_true", help="store the outputs instead of checking them")
    parser.add_argument("--case", action="append", choices=sorted(CASES), help="only this case (repeatable)")
    args = parser.parse_args(argv)
    names = args.case or list(CASES)
    found = outputs(names)
    if args.write:
        stored = json.loads(DIGESTS.read_text()) if DIGESTS.is_file() else {}
        stored.update({name: _stored_form(texts) for name, texts in found.items()})
        DIGESTS.write_text(json.dumps(stored, indent=2, sort_keys=True) + "\n")
        print(f"wrote {DIGESTS} ({', '.join(names)})")
        return 0
    stored = json.loads(DIGESTS.read_text())
    failed = False
    for name in names:
        differ = case_differences(stored[name], found[name])
        print(f"{name}: {'differs' if differ else 'same numbers'}")
        for line in differ[:20]:
            print(f"  {line}", file=sys.stderr)
        failed = failed or bool(differ)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
