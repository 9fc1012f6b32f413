"""How ``dospcot bench`` measures (:mod:`dospcot.lab.bench`): a figure's median, min and max over
repetitions that alternate between ours and the peer's, a row of the table, and the timers."""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import torch

from dospcot.envs import CLIFF_VIEWS, ViewObservationWrapper


@dataclass(frozen=True)
class Measurement:
    """Median, min and max of repeated measurements, in ``unit``."""

    median: float
    low: float
    high: float
    unit: str

    @classmethod
    def of(cls, values: list[float], unit: str) -> Measurement:
        """The median, min and max of repeated measurements ``values``, in ``unit``."""
        return cls(statistics.median(values), min(values), max(values), unit)

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
