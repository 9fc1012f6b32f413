"""The defaults-8 study (confirmatory): version 8 of the defaults (version 7 with exploration by rounds)
against version 3, paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's
runs are the numerics study's numerics-2 runs, as in the defaults-4 study. Version 8 replaces version 3
as the adopted version where, on both presets, the lower end of the 95% interval of (version 8 minus
version 3) lies above -0.05 for success and for pseudo-reward accuracy (non-inferiority;
docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot_lab.studies.version_3_pairs import against_version_3

EIGHT_AGAINST_THREE, _STUDY = against_version_3(8, "co-training passes from round 2, exploration by rounds")
"""The defaults-8 study's pair: version 8's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES = {"defaults-8": _STUDY}
