"""The defaults-14 study (confirmatory): version 14 of the defaults (version 13 with round 1's labels
bought and fitted at round 1's first pass, ``training.first_labels = "first_pass"``) against version 13,
the adopted version, paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 13's
runs are the defaults-13 study's, trained on the CPU model this study's runs train on. Version 14
replaces version 13 where, on both presets, the lower end of the 95% interval of (version 14 minus
version 13) lies above -0.05 for success and for pseudo-reward accuracy (non-inferiority;
docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot_lab.studies.declaration import Study, Sweep
from dospcot_lab.studies.defaults import PRESETS, VersionPair
from dospcot_lab.studies.defaults_13 import SWEEP as VERSION_13
from dospcot_lab.studies.tables import ADOPTION_SEEDS

OLD, NEW = 13, 14


FOURTEEN_AGAINST_THIRTEEN = VersionPair.named_in_grid(OLD, NEW)
"""The defaults-14 study's pair: each run names its version in its sweep's grid."""
SWEEP = Sweep(f"defaults-{NEW}", PRESETS[::-1], {"defaults": (str(NEW),)}, batch_seeds=1, numerics=None)
"""Version 14's runs, DoorKey's first."""

STUDIES = {
    "defaults-14": Study(
        (SWEEP, VERSION_13),
        FOURTEEN_AGAINST_THIRTEEN.tables,
        "Version 14 of the defaults against version 13: round 1's labels at its first pass",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        FOURTEEN_AGAINST_THIRTEEN.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
