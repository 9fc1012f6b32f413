"""scripts/big_machine.py: the big-machines guide's measured table is generated from its JSON, the
ways it sweeps, and how it merges runs of one machine."""

from __future__ import annotations

import copy
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC = importlib.util.spec_from_file_location("big_machine", ROOT / "scripts" / "big_machine.py")
big_machine = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(big_machine)
RECORD = json.loads((ROOT / "docs" / "guide" / "big-machines.json").read_text())


def test_the_guide_shows_the_recorded_measurement(tmp_path: Path) -> None:
    """The page's block between the markers is what the script renders from the JSON: no figure
    typed by hand."""
    page = big_machine.GUIDE.read_text()
    copied = tmp_path / "big-machines.md"
    copied.write_text(page)
    big_machine.write_guide(RECORD, copied)
    assert copied.read_text() == page
    assert RECORD["machine"]["gpu"] in page


def test_the_four_ways_for_16_seeds_on_16_cores() -> None:
    planned = big_machine.ways(16, 16)
    assert planned == {
        "alone": {"workers": 16, "batch": 1, "device": "cpu"},
        "cpu-batches": {"workers": 4, "batch": 4, "device": "cpu"},
        "gpu-batches": {"workers": 4, "batch": 4, "device": "cuda"},
        "gpu-batch": {"workers": 1, "batch": 16, "device": "cuda"},
    }
    assert big_machine.ways(16, 6)["alone"]["workers"] == 6


def test_merging_keeps_the_ways_order_and_refuses_another_machine() -> None:
    first = copy.deepcopy(RECORD)
    second = copy.deepcopy(RECORD)
    first["ways"] = {"gpu-batch": RECORD["ways"]["gpu-batch"]}
    second["ways"] = {name: way for name, way in RECORD["ways"].items() if name != "gpu-batch"}
    assert list(big_machine.merged([first, second])["ways"]) == list(big_machine.LABELS)
    second["machine"]["cores"] = 2
    with pytest.raises(SystemExit, match="different machines"):
        big_machine.merged([first, second])


def test_readings_are_ratios_of_the_table() -> None:
    """2 seeds alone: 10 s wall, 40 CPU-s; in one CPU batch: 15 s wall, 20 CPU-s; GPU skipped."""
    record = copy.deepcopy(RECORD)
    record["seeds"] = 2
    record["ways"] = {
        "alone": {"workers": 2, "batch": 1, "device": "cpu", "wall_s": 10.0, "cpu_s": 40.0, "finished": 2},
        "cpu-batches": {
            "workers": 1,
            "batch": 2,
            "device": "cpu",
            "wall_s": 15.0,
            "cpu_s": 20.0,
            "finished": 2,
        },
        "gpu-batch": {"workers": 1, "batch": 2, "device": "cuda", "skipped": "torch sees no GPU"},
    }
    page = big_machine.render(record)
    assert "| 2 worker(s), every seed alone | 10 s | 40 s | 20.0 s |" in page
    assert "torch sees no GPU" in page
    assert big_machine.readings(record) == [
        "- The CPU batches took 1.5x the wall time of every seed alone, and 0.50x its CPU time."
    ]
