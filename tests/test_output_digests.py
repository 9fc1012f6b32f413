"""What a user measures does not move under a refactor: each shortened preset of
``scripts/output_digests.py`` trains to the ``metrics.csv`` and ``summary.json`` stored there, to the
last digit that every CPU's torch kernels agree on."""

from __future__ import annotations

import hashlib
import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[1] / "scripts" / "output_digests.py"
_spec = importlib.util.spec_from_file_location("output_digests", SCRIPT)
output_digests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(output_digests)


@pytest.mark.parametrize("case", sorted(output_digests.CASES))
def test_a_shortened_preset_trains_to_its_stored_outputs(case: str, tmp_path: Path) -> None:
    stored = json.loads(output_digests.DIGESTS.read_text())[case]
    assert output_digests.case_differences(stored, output_digests.run_case(case, tmp_path)) == []


def test_the_stored_texts_are_the_files_their_digests_name() -> None:
    for case, files in json.loads(output_digests.DIGESTS.read_text()).items():
        for file, stored in files.items():
            assert hashlib.sha256(stored["text"].encode()).hexdigest() == stored["sha256"], (case, file)


def test_the_comparison_allows_kernel_rounding_and_nothing_else() -> None:
    stored = {"metrics.csv": {"text": "round,loss,view\n1,0.0027827618519298495,ego\n"}}
    stored["summary.json"] = {"text": '{"success": 0.5, "rounds": 2}'}

    def found(loss: str, view: str = "ego", success: str = "0.5", rounds: str = "2") -> dict[str, str]:
        return {
            "metrics.csv": f"round,loss,view\n1,{loss},{view}\n",
            "summary.json": f'{{"success": {success}, "rounds": {rounds}}}',
        }

    assert output_digests.case_differences(stored, found("0.0027827618519313306")) == []  # AVX-512's sum
    assert output_digests.case_differences(stored, found("0.00278277")) != []  # a 1e-6 change
    assert output_digests.case_differences(stored, found("0.0027827618519298495", view="image")) != []
    assert output_digests.case_differences(stored, found("0.0027827618519298495", success="0.6")) != []
    assert output_digests.case_differences(stored, found("0.0027827618519298495", rounds="3")) != []
