"""How a study is declared: its sweeps (each a folder under ``--runs-dir``), its tables, its row in the
results at a glance, and its page (the prose of ``pages/<study>.md`` around the generated table)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from dospcot.config.versions import FIRST
from dospcot.sweeps.report import TrialRun


@dataclass(frozen=True)
class Sweep:
    """One sweep of a study: its folder's name under --runs-dir, its configs and its grid; how many
        seeds train per batch (docs/batched_seeds.md), where the study fixes it (None: the command's
        ``--batch-seeds``); and the numerics version its runs train under (``cotraining.numerics``, set
        for every trial, so the sweep keeps it when the default moves; None: the sweep's grid varies it,
        or its configs have no co-training key, as the paper protocol's). The record's earlier studies
        keep 1, the version their runs were trained under; the future-work studies pin 2. Likewise the version
    of the defaults its trials resolve under (``defaults``, :mod:`dospcot.config.versions`): every study
    of the record was declared under the first."""

    name: str
    configs: tuple[str, ...]
    grid: dict[str, tuple[str, ...]]
    batch_seeds: int | None = None
    numerics: int | None = 1
    defaults: int = FIRST
    seeds: int | None = None
    """Its own seed count, where it is another study's sweep reused with more seeds than this study
    runs (None: the study's)."""
    reads: tuple[str, ...] | None = None
    """The configs whose runs this study reads, where it reuses another study's sweep for some of its
    configs only (None: every config). The sweep still trains all of them: it is the other study's."""

    def overrides(self) -> tuple[str, ...]:
        """The settings every trial of the sweep gets before the grid's: its numerics version."""
        return () if self.numerics is None else (f"cotraining.numerics={self.numerics}",)


@dataclass(frozen=True)
class Glance:
    """A study's row in "Results at a glance": its headline comparison with the 95% interval, and the
    verdict that interval gives (both generated from the runs, never typed)."""

    headline: str
    verdict: str
    seeds: tuple[int, ...] | None = None
    """The seeds its headline compares, where the study reads other studies' runs of more seeds
    (None: every run's)."""


EXPLORATORY = "exploratory"
"""The verdict of a study that names no hypothesis: its settings are confirmed by another."""

NOT_MEASURED = "not measured yet"
"""The verdict of a study that decides a default before any preset holds the pairs its rule names."""


@dataclass(frozen=True)
class Study:
    """A study: its sweeps, the tables built from their finished runs, its page's title, the task it
    runs on (in words, for the results at a glance) and its seeds (``seeds`` of them from
    ``first_seed``, unless --seeds says how many). Its page's prose, the text above and below the
    table (what the study runs, the reading of its table, its history), is ``pages/<study>.md``
    beside this module."""

    sweeps: tuple[Sweep, ...]
    tables: Callable[[list[TrialRun]], list[str]]
    title: str
    task: str
    glance: Callable[[list[TrialRun]], Glance]
    seeds: int = 5
    first_seed: int = 0
    """A confirmatory study's seeds start past those its settings were explored on."""
    readme: Callable[[str], str] | None = None
    """The README block from the study's table text; ``None``: the study has no README block."""
    plot: tuple[str, str] | None = None
    """A plot of the report that goes into ``docs/results/``: (its name in the sweep folder, its name
    there)."""
    figure: Callable[[list[TrialRun], Path], None] | None = None
    """Draws a figure from the study's runs into the path given (``--docs``: ``docs/results/<study>.png``,
    which its tables link to); None: the study has none of its own."""
    cells_explained: bool = False
    """Whether its tables say what a cell is themselves (the paper's): the header then says only where
    the figures come from."""
    confirmatory: bool = False
    """Whether it tests hypotheses fixed before its runs, or decides a default: it then trains only from
    a committed checkout with no uncommitted change, so every run names the code it ran."""
    preregistration: str | None = None
    """The page that fixed its hypotheses before its runs (a path from the repository's root), if any: it
    trains only once that page is committed, and its header counts the runs whose source descends from
    the commit that added it."""
