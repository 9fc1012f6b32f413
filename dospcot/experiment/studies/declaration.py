"""How a study is declared: its sweeps (each a folder under ``--runs-dir``), its tables and its pages."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from dospcot.experiment.report import TrialRun


@dataclass(frozen=True)
class Sweep:
    """One sweep of a study: its folder's name under --runs-dir, its configs and its grid."""

    name: str
    configs: tuple[str, ...]
    grid: dict[str, tuple[str, ...]]


@dataclass(frozen=True)
class Study:
    """A study: its sweeps, the tables built from their finished runs, its docs page's title and its
    seeds (0..seeds-1 unless --seeds says otherwise)."""

    sweeps: tuple[Sweep, ...]
    tables: Callable[[list[TrialRun]], list[str]]
    title: str
    seeds: int = 5
    readme: Callable[[str], str] | None = lambda table: table
    """The README block from the study's table text; ``None``: the study has no README block."""
    plot: tuple[str, str] | None = None
    """A plot of the report that goes into ``docs/``: (its name in the sweep folder, its name there)."""
