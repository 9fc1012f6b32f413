"""A round's answer file, ``queries/round_<r>.csv``: read as a person (or a spreadsheet) left it, written
atomically (docs/queries.md, docs/guide/rating.md).

Every mistake a person can make in the file is one line that names the file, the line the row starts
on (a grid query's text map spans several lines) and the fix. A reward is accepted only as a finite
number a float32 buffer holds; a value the run has not seen in an earlier round's answers is accepted
only where the person confirmed it (``yes`` in the row's ``confirm_new`` column, the rating page's
confirmation, or ``dospcot rate RUN_DIR --accept VALUE``), so a typo never becomes a reward class.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

QUERY_COLUMNS = ("sample", "key", "reward", "confirm_new", "rewards_seen")
"""The first columns of a round's query file; the frames and each view's prediction follow."""
CONFIRMED = frozenset({"yes", "y", "true", "1", "x"})
"""What ``confirm_new`` holds where a person confirmed a new reward value (any case)."""
FLOAT32_MAX = float(np.finfo(np.float32).max)
"""The largest reward the run's float32 buffers hold (about 3.4e38); a larger one would become inf."""
ROUND_FILE = re.compile(r"round_(\d+)\.csv")


class RaterError(ValueError):
    """An answer that cannot be taken: one line, nothing trained, nothing lost."""


def show(value: float) -> str:
    """A reward as a person reads it: 12 significant digits, no trailing ``.0``."""
    return f"{value:.12g}"


def parse_reward(text: str, decimal_comma: bool = False) -> float:
    """The reward written as ``text``.

    :param decimal_comma: read ``0,5`` as 0.5 (a file saved with ``;`` between its columns).
    :raises ValueError: a message that completes "the reward of sample s ...".
    """
    text = text.strip()
    if decimal_comma and re.fullmatch(r"[-+]?\d*,\d+", text):
        text = text.replace(",", ".")
    value = float(text)  # ValueError for anything that is not a number
    if not math.isfinite(value):
        raise ValueError(f"is {value}, not finite")
    if abs(value) > FLOAT32_MAX:
        raise ValueError(
            f"is {text}, beyond the +-3.4e38 a float32 reward holds (it would become "
            f"{math.copysign(math.inf, value)})"
        )
    return value


def round_of(path: Path) -> int:
    """The round of an answer file ``round_<r>.csv``."""
    match = ROUND_FILE.fullmatch(path.name)
    if match is None:
        raise RaterError(f"{path} is not a round's answer file (round_<r>.csv)")
    return int(match.group(1))


def read_rows(path: Path) -> tuple[list[str], list[tuple[int, dict[str, str]]], bool]:
    """The columns and rows of an answer file, each row with the line it starts on, and whether the
    file was saved with ``;`` between its columns (so with decimal commas).

    A UTF-8 byte-order mark is dropped; ``;`` and tab separated files (as spreadsheets save CSV in many
    locales) are read as well as comma separated ones.
    """
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise RaterError(
            f"{path} is not UTF-8 text (byte {err.start}); save it again as CSV in UTF-8 (a spreadsheet's "
            "'CSV UTF-8')"
        ) from None
    header = text.split("\n", 1)[0]
    delimiter = max((",", ";", "\t"), key=header.count)
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    rows: list[tuple[int, dict[str, str]]] = []
    try:
        fields = [name.strip() for name in next(reader, [])]
        start = reader.line_num + 1
        for values in reader:
            if any(v.strip() for v in values):  # a spreadsheet's empty trailing rows are no answers
                rows.append((start, dict(zip(fields, values, strict=False))))
            start = reader.line_num + 1
    except csv.Error as err:
        raise RaterError(f"{path} line {reader.line_num}: not readable as CSV ({err})") from None
    return fields, rows, delimiter == ";"


def write_rows(
    path: Path, fields: Sequence[str], rows: Iterable[dict[str, object]], semicolons: bool = False
) -> None:
    """Write an answer file atomically: a reader sees the old file or the new one, never a part.

    :param semicolons: ``;`` between the columns (a file a person saved so, with decimal commas).
    """
    temporary = path.with_name(path.name + ".tmp")
    with temporary.open("w", newline="", encoding="utf-8") as handle:
        delimiter = ";" if semicolons else ","
        writer = csv.DictWriter(handle, fieldnames=list(fields), extrasaction="ignore", delimiter=delimiter)
        writer.writeheader()
        writer.writerows(rows)
    temporary.replace(path)


def rewards_seen(folder: Path, round_: int) -> list[float]:
    """The distinct rewards answered in the answer files of the rounds before ``round_`` (which the run
    read, so every answer there was accepted), in increasing order."""
    seen: set[float] = set()
    for path in folder.glob("round_*.csv"):
        if ROUND_FILE.fullmatch(path.name) and round_of(path) < round_:
            _, rows, comma = read_rows(path)
            for _, row in rows:
                try:
                    seen.add(parse_reward(row.get("reward") or "", comma))
                except ValueError:
                    continue
    return sorted(seen)


def sample_number(text: str) -> int:
    """A sample number as written, ``7`` or as a spreadsheet may save it, ``7.0``.

    :raises ValueError: not a whole number.
    """
    value = float(text.strip())
    if not value.is_integer():
        raise ValueError(text)
    return int(value)


def confirmed(row: dict[str, str]) -> bool:
    """Whether a row's ``confirm_new`` column confirms its reward as a new value."""
    return (row.get("confirm_new") or "").strip().lower() in CONFIRMED


def read_answers(
    path: Path, ids: np.ndarray, seen: Sequence[float], run_dir: Path | None = None
) -> np.ndarray:
    """(n,) the rewards a person wrote in ``path`` for the queries ``ids``.

    :param seen: the rewards accepted in earlier rounds; any other value needs its confirmation.
    :param run_dir: the run folder, for the command the messages give.
    :raises RaterError: one line naming the line of the file and the fix.
    """
    fields, rows, comma = read_rows(path)
    if "sample" not in fields or "reward" not in fields:
        raise RaterError(
            f"{path}: needs the columns sample and reward, has {', '.join(fields) or 'none'}; keep the "
            "header row the run wrote"
        )
    asked = {int(i) for i in ids}
    answers: dict[int, tuple[float, int]] = {}
    new: dict[float, tuple[int, int, bool]] = {}  # value -> first line, its sample, confirmed on any row
    for line, row in rows:
        text = row.get("sample") or ""
        try:
            sample = sample_number(text)
        except ValueError:
            raise RaterError(
                f"{path} line {line}: {text!r} in the sample column is not a sample number; restore the "
                "number the run wrote, or delete the row"
            ) from None
        if sample not in asked:
            raise RaterError(
                f"{path} line {line}: sample {sample} is not one of this round's {len(asked)} queries; "
                "delete the row, or restore the sample number the run wrote"
            )
        try:
            reward = parse_reward(row.get("reward") or "", comma)
        except ValueError as err:
            if str(err).startswith("is "):
                raise RaterError(f"{path} line {line}: the reward of sample {sample} {err}") from None
            raise RaterError(
                f"{path} line {line}: sample {text!r} has no numeric reward ({row.get('reward')!r}); answer "
                "every query with a number"
            ) from None
        if sample in answers and answers[sample][0] != reward:
            raise RaterError(
                f"{path} lines {answers[sample][1]} and {line} both answer sample {sample}, with "
                f"{show(answers[sample][0])} and {show(reward)}; keep one of the two rows"
            )
        answers[sample] = (reward, line)
        if reward not in seen:
            first = new.get(reward, (line, sample, False))
            new[reward] = (first[0], first[1], first[2] or confirmed(row))
    missing = [int(i) for i in ids if int(i) not in answers]
    if missing:
        raise RaterError(
            f"{path}: {len(missing)} of its {len(ids)} queries have no answer (e.g. sample {missing[0]})"
        )
    unconfirmed = [(value, line, sample) for value, (line, sample, ok) in new.items() if not ok]
    if unconfirmed:
        value, line, sample = unconfirmed[0]
        more = "".join(f", {show(v)} (line {n})" for v, n, _ in unconfirmed[1:])
        listed = ", ".join(show(v) for v in seen) or "none yet"
        command = f"dospcot rate {run_dir or path.parent.parent} --accept={show(value)}"
        raise RaterError(
            f"{path} line {line}: sample {sample}'s reward {show(value)} is new (rewards seen so far: "
            f"{listed}){' as are ' + more[2:] if more else ''}; if it is right, write yes in its confirm_new "
            f"column (or run {command}), else correct it"
        )
    return np.array([answers[int(i)][0] for i in ids], dtype=np.float64)


def accept_values(path: Path, values: Sequence[float]) -> int:
    """Confirm each of ``values`` as a new reward: ``yes`` in ``confirm_new`` on every row answering it.

    :return: the rows confirmed.
    :raises RaterError: a value no row answers.
    """
    fields, rows, comma = read_rows(path)
    fields = list(dict.fromkeys([*fields, "confirm_new"]))
    count = 0
    for value in values:
        matched = 0
        for _, row in rows:
            try:
                matches = parse_reward(row.get("reward") or "", comma) == value
            except ValueError:
                matches = False
            if matches:
                row["confirm_new"], matched = "yes", matched + 1
        if not matched:
            raise RaterError(
                f"--accept={show(value)}: no row of {path} answers {show(value)}; write it first"
            )
        count += matched
    write_rows(path, fields, (row for _, row in rows), comma)
    return count
