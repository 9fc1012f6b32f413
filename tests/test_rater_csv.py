"""Answer files as people fill them in: each bad one is one line naming the file, the line and the fix
(dospcot.raters.answer_files), and what the file shows a person (views named, actions explained, the
rewards seen so far)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from dospcot.cli import main
from dospcot.raters.answer_files import accept_values, read_rows
from dospcot.raters.file_rater import FileRater, QueriesPending, RaterError

MAP = "......\n.A..L.\n......\n..L...\n......\n.....G"  # a grid query's text map: six lines
IDS = np.array([4, 8, 15])


def _round(tmp_path: Path, answers: list[tuple[object, object]] | None = None) -> tuple[FileRater, Path]:
    """A file rater whose round 1 answered -1 and 0 and whose round 2 asks samples 4, 8 and 15, each
    row with its six-line map; ``answers``: the round 2 rows written back, (sample, reward) each."""
    rater = FileRater(tmp_path / "run" / "queries", views=["coords", "patch"])
    rater.folder.mkdir(parents=True)
    (rater.folder / "round_1.csv").write_text("sample,key,reward\n1,k,-1\n2,k,0\n")
    with pytest.raises(QueriesPending):
        rater.answer(2, IDS, [{"key": f"state {i}, action 1", "frame": MAP} for i in IDS])
    if answers is not None:
        _write(rater.path(2), [{"sample": s, "key": "k", "reward": r, "frame": MAP} for s, r in answers])
    return rater, rater.path(2)


def _write(path: Path, rows: list[dict], delimiter: str = ",", bom: bool = False) -> None:
    with path.open("w", newline="", encoding="utf-8-sig" if bom else "utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), delimiter=delimiter)
        writer.writeheader()
        writer.writerows(rows)


def _one_line(rater: FileRater, match: str) -> str:
    with pytest.raises(RaterError) as err:
        rater.answer(2, IDS, [])
    message = str(err.value)
    assert "\n" not in message and str(rater.path(2)) in message and match in message, message
    return message


def test_a_reward_never_seen_is_taken_only_once_confirmed(tmp_path):
    rater, path = _round(tmp_path, [(4, "-1"), (8, "42"), (15, "0")])  # 42: a typo of -1 or 0
    message = _one_line(rater, "line 8: sample 8's reward 42 is new (rewards seen so far: -1, 0)")
    assert (
        f"write yes in its confirm_new column (or run dospcot rate {path.parent.parent} --accept=42)"
        in message
    )
    assert accept_values(path, [42.0]) == 1
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 42.0, 0.0]


def test_several_new_values_are_named_in_one_line(tmp_path):
    rater, _ = _round(tmp_path, [(4, "7"), (8, "42"), (15, "7")])
    _one_line(rater, "line 2: sample 4's reward 7 is new (rewards seen so far: -1, 0) as are 42 (line 8)")


def test_a_reward_beyond_float32_is_refused_not_made_infinite(tmp_path):
    rater, _ = _round(tmp_path, [(4, "-1"), (8, "-1e300"), (15, "0")])
    _one_line(rater, "line 8: the reward of sample 8 is -1e300, beyond the +-3.4e38 a float32 reward holds")


@pytest.mark.parametrize("text", ["nan", "inf", "-Infinity"])
def test_a_reward_that_is_not_finite_is_refused(tmp_path, text):
    rater, _ = _round(tmp_path, [(4, "-1"), (8, text), (15, "0")])
    _one_line(rater, "line 8: the reward of sample 8 is ")


def test_a_row_for_a_sample_outside_the_round_is_refused(tmp_path):
    rater, _ = _round(tmp_path, [(4, "-1"), (8, "0"), (16, "0"), (15, "0")])
    _one_line(rater, "line 14: sample 16 is not one of this round's 3 queries; delete the row")


def test_a_duplicated_row_with_another_answer_is_refused(tmp_path):
    rater, _ = _round(tmp_path, [(4, "-1"), (8, "0"), (15, "0"), (8, "-1")])
    _one_line(rater, "lines 8 and 20 both answer sample 8, with 0 and -1; keep one of the two rows")
    rater, _ = _round(tmp_path / "same", [(4, "-1"), (8, "0"), (15, "0"), (8, "0")])  # the same answer twice
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 0.0, 0.0]


def test_a_semicolon_separated_file_with_decimal_commas_is_read(tmp_path):
    rater, path = _round(tmp_path)
    rows = [
        {"sample": s, "key": "a; b", "reward": r, "frame": MAP} for s, r in ((4, "-1"), (8, "0,0"), (15, "0"))
    ]
    _write(path, rows, delimiter=";")
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 0.0, 0.0]
    _write(path, [{**rows[0], "reward": "minus one"}, *rows[1:]], delimiter=";")
    _one_line(
        rater, "line 2: sample '4' has no numeric reward ('minus one'); answer every query with a number"
    )


def test_sample_numbers_a_spreadsheet_saved_as_decimals_are_read(tmp_path):
    rater, _ = _round(tmp_path, [("4.0", "-1"), ("8", "0"), ("15.0", "0")])
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 0.0, 0.0]
    rater, _ = _round(tmp_path / "b", [("4.5", "-1"), ("8", "0"), ("15", "0")])
    _one_line(rater, "line 2: '4.5' in the sample column is not a sample number")


def test_a_tab_separated_file_is_read(tmp_path):
    rater, path = _round(tmp_path)
    _write(path, [{"sample": s, "reward": r} for s, r in ((4, "-1"), (8, "0"), (15, "0"))], delimiter="\t")
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 0.0, 0.0]


def test_a_byte_order_mark_is_dropped(tmp_path):
    rater, path = _round(tmp_path)
    _write(
        path, [{"sample": s, "key": "k", "reward": r} for s, r in ((4, "-1"), (8, "0"), (15, "0"))], bom=True
    )
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 0.0, 0.0]


def test_a_file_in_another_encoding_is_one_line(tmp_path):
    rater, path = _round(tmp_path)
    path.write_bytes("sample,key,reward\n4,caf\xe9,-1\n".encode("latin-1"))
    _one_line(rater, "is not UTF-8 text (byte 23); save it again as CSV in UTF-8")


def test_lines_are_the_files_lines_not_its_rows(tmp_path):
    rater, _ = _round(tmp_path, [(4, "-1"), (8, "0"), (15, "")])  # the third row starts on line 14
    _one_line(rater, "line 14: sample '15' has no numeric reward ('')")


def test_missing_answers_renamed_columns_and_bad_sample_numbers_are_one_line(tmp_path):
    rater, path = _round(tmp_path, [(4, "-1"), (8, "0")])
    _one_line(rater, "1 of its 3 queries have no answer (e.g. sample 15)")
    _round(tmp_path / "b", [(4, "-1"), ("eight", "0"), (15, "0")])
    _one_line(
        FileRater(tmp_path / "b" / "run" / "queries"), "line 8: 'eight' in the sample column is not a sample"
    )
    path.write_text("Sample,Key,Reward value\n4,k,-1\n")
    _one_line(
        rater, "needs the columns sample and reward, has Sample, Key, Reward value; keep the header row"
    )
    path.write_text("")
    _one_line(rater, "needs the columns sample and reward, has none")
    path.write_text('sample,key,reward\n4,"unclosed,-1\n')
    _one_line(rater, "line 2: sample '4' has no numeric reward (None)")  # the quote swallowed the rest


def test_trailing_empty_rows_a_spreadsheet_adds_are_no_answers(tmp_path):
    rater, path = _round(tmp_path, [(4, "-1"), (8, "0"), (15, "0")])
    path.write_text(path.read_text() + ",,,\n,,,\n")
    assert rater.answer(2, IDS, []).tolist() == [-1.0, 0.0, 0.0]


def test_the_file_names_views_explains_actions_and_lists_the_rewards_seen(tmp_path):
    rater = FileRater(tmp_path / "run" / "queries", views=["image", "ego"])
    rater.actions = ("left", "right", "forward")
    rater.folder.mkdir(parents=True)
    (rater.folder / "round_1.csv").write_text("sample,reward\n1,0\n2,0.955\n")
    (tmp_path / "run" / "reward_classes.json").write_text(json.dumps({"rewards": [0.0, 0.955]}))
    described = {
        "key": "state #ab12, action 2",
        "frame": b"\x89PNG",
        "view0_class": 1,
        "view0_confidence": 0.93,
        "view1_class": 0,
        "view1_confidence": 0.61,
    }
    with pytest.raises(QueriesPending):
        rater.answer(2, np.array([7]), [described])
    fields, rows, _ = read_rows(rater.path(2))
    assert fields == [
        "sample",
        "key",
        "reward",
        "confirm_new",
        "rewards_seen",
        "frame",
        "image_predicts",
        "image_confidence",
        "ego_predicts",
        "ego_confidence",
    ]
    ((_, row),) = rows
    assert row["key"] == "state #ab12, action 2 (forward)" and row["rewards_seen"] == "0, 0.955"
    assert (row["image_predicts"], row["ego_predicts"], row["ego_confidence"]) == ("0.955", "0", "0.61")
    assert (rater.folder / row["frame"]).read_bytes() == b"\x89PNG"


def test_accept_confirms_new_values_from_the_command_line(tmp_path, capsys):
    rater, path = _round(tmp_path, [(4, "5"), (8, "-2"), (15, "5")])
    (path.parent.parent / "config.toml").write_text("")
    assert main(["rate", str(path.parent.parent), "--accept=5,-2"]) == 0
    assert "confirmed 5, -2 as new rewards on 3 rows" in capsys.readouterr().out
    assert rater.answer(2, IDS, []).tolist() == [5.0, -2.0, 5.0]
    with pytest.raises(SystemExit) as usage:
        main(["rate", str(path.parent.parent), "--accept=x"])
    assert usage.value.code == 2
    assert "--accept takes a reward or a comma list" in capsys.readouterr().err
