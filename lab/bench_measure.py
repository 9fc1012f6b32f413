"""How ``dospcot-lab bench`` measures (:mod:`dospcot_lab.bench`): a figure's median, min and max over
repetitions that alternate between ours and the peer's, a row of the table, how the row was made (its
provenance), and the timers."""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import gymnasium as gym
import torch

from dospcot.envs import CLIFF_VIEWS, ViewObservationWrapper
from dospcot.run.run_folder import cpu_description, source_commit

NOT_RECORDED = "not recorded"
"""A provenance field that a row written before rows carried their provenance does not know."""


def short_commit() -> str:
    """The commit of the checkout this code runs from, shortened, ``+dirty`` where tracked files differ
    from it (:func:`~dospcot.run.run_folder.source_commit`); :data:`NOT_RECORDED` outside a checkout."""
    commit = source_commit()
    if commit is None:
        return NOT_RECORDED
    sha, plus, dirty = commit.partition("+")
    return sha[:7] + plus + dirty


@dataclass(frozen=True)
class Measurement:
    """Median, min and max of repeated measurements, in ``unit``, and how many there were."""

    median: float
    low: float
    high: float
    unit: str
    count: int = 1
    """The repetitions measured (their number, whatever ``--repeats`` asked)."""

    @classmethod
    def of(cls, values: list[float], unit: str) -> Measurement:
        """The median, min and max of repeated measurements ``values``, in ``unit``."""
        return cls(statistics.median(values), min(values), max(values), unit, len(values))

    @property
    def _format(self) -> str:
        return ",.0f" if self.median >= 100 else ".2f"

    @property
    def brief(self) -> str:
        """The median and the unit alone."""
        return f"{self.median:{self._format}} {self.unit}"

    def __str__(self) -> str:
        return f"{self.brief} [{self.low:{self._format}}, {self.high:{self._format}}]"


@dataclass(frozen=True)
class Row:
    """One benchmark: ours against the peer, their ratio and the target it should meet."""

    name: str
    setting: str
    ours: Measurement
    peer: Measurement
    higher_is_better: bool
    target: float
    made: Provenance | None = None
    """How the row was made; ``dospcot-lab bench`` stamps it as the row lands (None: not stamped)."""

    @classmethod
    def measured(
        cls, name: str, setting: str, unit: str, ours: list[float], peer: list[float], **verdict: Any
    ) -> Row:
        """A row of the repetitions of ours and the peer, in ``unit``; ``verdict`` holds
        ``higher_is_better`` and ``target``."""
        return cls(name, setting, Measurement.of(ours, unit), Measurement.of(peer, unit), **verdict)

    @property
    def ratio(self) -> float:
        """Ours over the peer, of the medians (infinite over a peer of 0, which no target meets)."""
        return self.ours.median / self.peer.median if self.peer.median else math.inf

    @property
    def met(self) -> bool:
        """Whether the ratio meets the target (at least it, or at most it where lower is better)."""
        return self.ratio >= self.target if self.higher_is_better else self.ratio <= self.target

    @property
    def target_text(self) -> str:
        """The target as the table writes it: rounded to 3 decimals, as the ratio is (1/3 reads 0.333)."""
        return str(round(self.target, 3))


@dataclass(frozen=True)
class Provenance:
    """How a row of BENCHMARKS.md was made: the benchmark that measured it (a key of
    :data:`dospcot_lab.bench.BENCHMARKS`), its repetitions, when (UTC), the source's commit and the CPU.
    Written in the row's *made by* cell as its five fields, ``; ``-separated; a field a row written
    before rows carried their provenance lacks reads :data:`NOT_RECORDED`."""

    bench: str
    repetitions: str
    date: str
    commit: str
    cpu: str

    @classmethod
    def now(cls, bench: str, row: Row, commit: str) -> Provenance:
        """The provenance of ``row``, measured just now by benchmark ``bench`` on this machine: its
        repetitions counted from its measurements, ``commit`` (the checkout's as the run started,
        :func:`short_commit`) and the CPU model with torch's kernels
        (:func:`~dospcot.run.run_folder.cpu_description`, from ``/proc/cpuinfo``, else :mod:`platform`)."""
        return cls(
            bench,
            str(max(row.ours.count, row.peer.count)),
            f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC",
            commit,
            cpu_description(),
        )

    @classmethod
    def unknown(cls) -> Provenance:
        """A row written before rows carried their provenance: every field not recorded."""
        return cls(*[NOT_RECORDED] * 5)

    @classmethod
    def parse(cls, cell: str) -> Provenance:
        """The provenance in a *made by* cell (the form :meth:`__str__` writes); ``ValueError`` if the
        cell is not one."""
        fields = cell.split("; ")
        error = ValueError(f"not a made-by cell (`bench`; N repetitions; date; commit C; CPU): {cell!r}")
        if len(fields) != 5:
            raise error
        values = []
        for field, (label, place) in zip(fields, _LABELS, strict=True):
            if field == f"{label} {NOT_RECORDED}":
                values.append(NOT_RECORDED)
            elif place == "before" and field.startswith(f"{label} "):
                values.append(field.removeprefix(f"{label} "))
            elif place == "after" and field.endswith((f" {label}", f" {label[:-1]}")):  # "1 repetition"
                values.append(field.rsplit(" ", 1)[0])
            elif place == "alone" and field:
                values.append(field.strip("`"))
            else:
                raise error
        return cls(*values)

    def __str__(self) -> str:
        cells = []
        values = (self.bench, self.repetitions, self.date, self.commit, self.cpu)
        for value, (label, place) in zip(values, _LABELS, strict=True):
            if value == NOT_RECORDED:
                cells.append(f"{label} {NOT_RECORDED}")
            elif place == "alone":
                cells.append(f"`{value}`" if label == "bench" else value)
            elif place == "before":
                cells.append(f"{label} {value}")
            else:
                cells.append(f"{value} {label if value != '1' else label[:-1]}")
        return "; ".join(cells)


_LABELS = (
    ("bench", "alone"),
    ("repetitions", "after"),
    ("date", "alone"),
    ("commit", "before"),
    ("CPU", "alone"),
)
"""Each provenance field's word in a *made by* cell and where it stands: before the value (``commit
abc1234``), after it (``3 repetitions``), or only where the value is not recorded (``date not
recorded``; the bench, in backticks, the date and the CPU stand alone)."""


def alternating(
    repeats: int, ours: Callable[[int], float], peer: Callable[[int], float]
) -> tuple[list[float], list[float]]:
    """``repeats`` measurements of ours and of the peer (each called with the repetition index),
    alternating which goes first, so drift in the machine's speed hits both alike."""
    results: tuple[list[float], list[float]] = ([], [])
    for rep in range(repeats):
        for side in (0, 1) if rep % 2 == 0 else (1, 0):
            results[side].append((ours, peer)[side](rep))
    return results


def onehot_cliff() -> gym.Env:
    """CliffWalking with one-hot observations, 100 steps an episode: the agent rows' task."""
    return ViewObservationWrapper(gym.make("CliffWalking-v1", max_episode_steps=100), CLIFF_VIEWS["onehot"])


class Clock:
    """Seconds spent between :meth:`start` and :meth:`stop`: the process's CPU time on the CPU (see
    NOTES), wall time on a GPU, whose work the CPU only queues (the GPU finishes its queue first)."""

    def __init__(self, device: str) -> None:
        self.device = device
        self._started = 0.0

    @property
    def unit(self) -> str:
        """``"CPU-s"`` or ``"s"``."""
        return "CPU-s" if self.device == "cpu" else "s"

    def _now(self) -> float:
        if self.device == "cpu":
            return time.process_time()
        torch.cuda.synchronize(self.device)
        return time.perf_counter()

    def start(self) -> None:
        """Start counting."""
        self._started = self._now()

    def stop(self) -> float:
        """The seconds since :meth:`start`."""
        return self._now() - self._started
