"""Studies of a later version of the defaults against version 3, the adopted one: each trains seeds
0-19 of ``grid16-dospcot`` and ``minigrid-doorkey-dospcot`` (grid16 first, its runs cost the least)
under the new version, and pairs them by seed with the numerics study's numerics-2 runs, which are
version 1 with numerics 2's fits, what version 3 resolves to. The adoption rule decides
(:class:`~dospcot_lab.studies.defaults.VersionPair`)."""

from __future__ import annotations

from collections.abc import Callable

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Study, Sweep
from dospcot_lab.studies.defaults import PRESETS, VersionPair
from dospcot_lab.studies.numerics import NUMERICS_2
from dospcot_lab.studies.tables import ADOPTION_SEEDS


def _version_of(new: int) -> Callable[[TrialRun], int | None]:
    """``new`` for the study's own runs (they name it in their grid), 3 for the numerics-2 runs, None
    for the others its sweeps hold."""

    def version(run: TrialRun) -> int | None:
        if run.trial.params.get("defaults") == str(new):
            return new
        return 3 if run.trial.params.get("cotraining.numerics") == "2" else None

    return version


def against_version_3(new: int, change: str) -> tuple[VersionPair, Study]:
    """Version ``new`` against version 3: its pair of versions, and its confirmatory study, whose sweep
    ``defaults-<new>`` trains the new version's runs.

    :param change: what the new version moves, in words (the page's title ends with it).
    """
    pair = VersionPair(3, new, _version_of(new))
    sweep = Sweep(f"defaults-{new}", PRESETS, {"defaults": (str(new),)}, batch_seeds=1, numerics=None)
    study = Study(
        (sweep, NUMERICS_2),
        pair.tables,
        f"Version {new} of the defaults against version 3: {change}",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        pair.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    )
    return pair, study
