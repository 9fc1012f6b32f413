"""Raters: who answers a run's reward queries (docs/queries.md).

- :class:`SimulatedRater` answers from the hidden reward, as the mask would have revealed it (studies,
  tests). It is the one reader of a hidden reward outside the metrics, and it reads only the samples
  it is asked about.
- :class:`FileRater` asks a person: it writes each round's queries to ``queries/round_<r>.csv`` in the
  run folder and stops the run (:class:`QueriesPending`); ``dospcot train --resume`` reads the answers
  from the ``reward`` column of that file. A query's frames (PNG images, :func:`encode_png`) go beside
  it, in ``queries/round_<r>/``, its row naming them.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from PIL import Image

QUERY_COLUMNS = ("sample", "key", "reward")
"""The first columns of a round's query file; each view's predicted class and confidence follow."""


def encode_png(image: np.ndarray) -> bytes:
    """A PNG of ``image``, (H, W, 3) uint8 RGB (an env's ``render()`` in mode ``"rgb_array"``)."""
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


class QueriesPending(Exception):
    """The rater has queries waiting for a person's answers; the run stops until they are given."""

    def __init__(self, count: int, path: Path) -> None:
        super().__init__(f"{count} reward queries wait in {path}: fill in its reward column, then resume")
        self.count, self.path = count, path


class RaterError(ValueError):
    """An answer file that cannot be read: one line, nothing trained, nothing lost."""


class SimulatedRater:
    """Answers each query with the sample's hidden reward.

    :param hidden_reward: the hidden rewards of given sample ids (the task's store, metrics only but here).
    """

    def __init__(self, hidden_reward: Callable[[np.ndarray], np.ndarray]) -> None:
        self.hidden_reward = hidden_reward

    def answer(self, round_: int, ids: np.ndarray, described: Sequence[dict[str, object]]) -> np.ndarray:
        """(n,) the rewards of samples ``ids`` (``described`` is what a person would be shown)."""
        return np.asarray(self.hidden_reward(ids), dtype=np.float64)


class FileRater:
    """Writes each round's queries for a person and reads the answers back.

    :param folder: where the query files go (``<run>/queries``).
    """

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    def path(self, round_: int) -> Path:
        """The query file of round ``round_``."""
        return self.folder / f"round_{round_}.csv"

    def answer(self, round_: int, ids: np.ndarray, described: Sequence[dict[str, object]]) -> np.ndarray:
        """The rewards a person wrote for ``ids``; the first time, write the queries and raise
        :class:`QueriesPending`.

        :raises RaterError: the file does not answer every query with a finite number.
        """
        path = self.path(round_)
        if not path.is_file():
            self.folder.mkdir(parents=True, exist_ok=True)
            rows = [
                {"sample": int(i), **self._write_frames(round_, int(i), row), "reward": ""}
                for i, row in zip(ids, described, strict=True)
            ]
            fields = list(dict.fromkeys([*QUERY_COLUMNS, *(k for row in rows for k in row)]))
            temporary = path.with_suffix(".csv.tmp")
            with temporary.open("w", newline="") as handle:
                writer = csv.DictWriter(handle, fieldnames=fields)
                writer.writeheader()
                writer.writerows(rows)
            temporary.replace(path)
            raise QueriesPending(len(ids), path)
        return self._read(path, ids)

    def _write_frames(self, round_: int, sample: int, described: dict[str, object]) -> dict[str, object]:
        """``described`` with each PNG written to ``round_<r>/<sample>_<column>.png`` and named in its
        place (relative to the queries folder)."""
        row = dict(described)
        for column, value in described.items():
            if isinstance(value, bytes):
                name = Path(f"round_{round_}") / f"{sample}_{column}.png"
                (self.folder / name).parent.mkdir(exist_ok=True)
                (self.folder / name).write_bytes(value)
                row[column] = name.as_posix()
        return row

    @staticmethod
    def _read(path: Path, ids: np.ndarray) -> np.ndarray:
        with path.open(newline="") as handle:
            rows = list(csv.DictReader(handle))
        if rows and ("sample" not in rows[0] or "reward" not in rows[0]):
            raise RaterError(f"{path}: needs the columns sample and reward, has {', '.join(rows[0])}")
        answers: dict[int, float] = {}
        for line, row in enumerate(rows, start=2):
            try:
                sample, reward = int(row["sample"]), float(row["reward"])
            except (TypeError, ValueError):
                raise RaterError(
                    f"{path} line {line}: sample {row.get('sample')!r} has no numeric reward "
                    f"({row.get('reward')!r}); answer every query with a number"
                ) from None
            if not math.isfinite(reward):
                raise RaterError(f"{path} line {line}: the reward of sample {sample} is {reward}, not finite")
            answers[sample] = reward
        missing = [int(i) for i in ids if int(i) not in answers]
        if missing:
            raise RaterError(
                f"{path}: {len(missing)} of its {len(ids)} queries have no answer (e.g. sample {missing[0]})"
            )
        return np.array([answers[int(i)] for i in ids], dtype=np.float64)
