"""The defaults-13 study (confirmatory): version 13 of the defaults (version 12 with the steps' reward
in a class of its own on a gym task, ``gym.step_class``) against version 12, the adopted version,
paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 12's runs are the
defaults-12 study's. Version 13 replaces version 12 where, on both presets, the lower end of the 95%
interval of (version 13 minus version 12) lies above -0.05 for success and for pseudo-reward accuracy
(non-inferiority; docs/guide/defaults.md).

The defaults-13-same-cpu study (confirmatory) repeats the comparison with version 12's runs trained
again on the CPU model that trained version 13's: the defaults-12 study's ran on another, whose torch
kernels round differently, so its pairs parted where the two versions' settings match."""

from __future__ import annotations

from dospcot_lab.studies.declaration import Study, Sweep
from dospcot_lab.studies.defaults import PRESETS, VersionPair
from dospcot_lab.studies.defaults_12 import STUDIES as DEFAULTS_12
from dospcot_lab.studies.tables import ADOPTION_SEEDS

OLD, NEW = 12, 13


THIRTEEN_AGAINST_TWELVE = VersionPair.named_in_grid(OLD, NEW)
"""The defaults-13 study's pair: each run names its version in its sweep's grid."""
SWEEP = Sweep(f"defaults-{NEW}", PRESETS[::-1], {"defaults": (str(NEW),)}, batch_seeds=1, numerics=None)
"""Version 13's runs, DoorKey's first: on grid16 the version moves nothing."""
SAME_CPU = Sweep(
    f"defaults-{OLD}-same-cpu", PRESETS[::-1], {"defaults": (str(OLD),)}, batch_seeds=1, numerics=None
)
"""Version 12's runs again, DoorKey's first, on the CPU model that trained :data:`SWEEP`'s."""

STUDIES = {
    "defaults-13": Study(
        (SWEEP, DEFAULTS_12["defaults-12"].sweeps[0]),
        THIRTEEN_AGAINST_TWELVE.tables,
        "Version 13 of the defaults against version 12: the steps' own reward class",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        THIRTEEN_AGAINST_TWELVE.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
    "defaults-13-same-cpu": Study(
        (SWEEP, SAME_CPU),
        THIRTEEN_AGAINST_TWELVE.tables,
        "Version 13 of the defaults against version 12, both trained on one CPU model",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        THIRTEEN_AGAINST_TWELVE.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
