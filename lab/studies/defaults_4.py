"""The defaults-4 study (confirmatory): version 4 of the defaults (version 3 with exploration by rounds)
against version 3, paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's
runs are the numerics study's numerics-2 runs: version 1 with numerics 2's fits, which is what version
3 resolves to. Version 4 replaces version 3 as the adopted version where, on both presets, the lower
end of the 95% interval of (version 4 minus version 3) lies above -0.05 for success and for
pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Study, Sweep
from dospcot_lab.studies.defaults import PRESETS, VersionPair
from dospcot_lab.studies.numerics import NUMERICS_2
from dospcot_lab.studies.tables import ADOPTION_SEEDS


def _version(run: TrialRun) -> int | None:
    """4 for the study's own runs, 3 for the numerics-2 runs, None for the others its sweeps hold."""
    if run.trial.params.get("defaults") == "4":
        return 4
    return 3 if run.trial.params.get("cotraining.numerics") == "2" else None


FOUR_AGAINST_THREE = VersionPair(3, 4, _version)
"""The defaults-4 study: version 4's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES: dict[str, Study] = {
    "defaults-4": Study(
        (
            # grid16 first: its runs cost the least, and version 2 failed the rule there.
            Sweep("defaults-4", PRESETS, {"defaults": ("4",)}, batch_seeds=1, numerics=None),
            NUMERICS_2,
        ),
        FOUR_AGAINST_THREE.tables,
        "Version 4 of the defaults against version 3: exploration by rounds",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        FOUR_AGAINST_THREE.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
