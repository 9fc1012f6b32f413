"""What a user measures does not move under a refactor: each shortened preset of
``scripts/output_digests.py`` trains to the ``metrics.csv`` and ``summary.json`` stored there."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[1] / "scripts" / "output_digests.py"
_spec = importlib.util.spec_from_file_location("output_digests", SCRIPT)
output_digests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(output_digests)


@pytest.mark.parametrize("case", sorted(output_digests.CASES))
def test_a_shortened_preset_trains_to_its_stored_digests(case: str, tmp_path: Path) -> None:
    stored = json.loads(output_digests.DIGESTS.read_text())[case]
    assert output_digests.run_case(case, tmp_path) == stored
