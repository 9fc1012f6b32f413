"""The defaults-6 study (confirmatory): version 6 of the defaults (version 3 with each round's
co-training in four passes and the refit on a new class) against version 3, paired by seed on
``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's runs are the numerics study's
numerics-2 runs, as in the defaults-4 study. Version 6 replaces version 3 as the adopted version where,
on both presets, the lower end of the 95% interval of (version 6 minus version 3) lies above -0.05 for
success and for pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Study, Sweep
from dospcot_lab.studies.defaults import PRESETS, VersionPair
from dospcot_lab.studies.numerics import NUMERICS_2
from dospcot_lab.studies.tables import ADOPTION_SEEDS


def _version(run: TrialRun) -> int | None:
    """6 for the study's own runs, 3 for the numerics-2 runs, None for the others its sweeps hold."""
    if run.trial.params.get("defaults") == "6":
        return 6
    return 3 if run.trial.params.get("cotraining.numerics") == "2" else None


SIX_AGAINST_THREE = VersionPair(3, 6, _version)
"""The defaults-6 study: version 6's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES: dict[str, Study] = {
    "defaults-6": Study(
        (
            # grid16 first: its runs cost the least.
            Sweep("defaults-6", PRESETS, {"defaults": ("6",)}, batch_seeds=1, numerics=None),
            NUMERICS_2,
        ),
        SIX_AGAINST_THREE.tables,
        "Version 6 of the defaults against version 3: four co-training passes a round, refit on a new class",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        SIX_AGAINST_THREE.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
