"""The defaults-6 study (confirmatory): version 6 of the defaults (version 3 with each round's
co-training in four passes and the refit on a new class) against version 3, paired by seed on
``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's runs are the numerics study's
numerics-2 runs, as in the defaults-4 study. Version 6 replaces version 3 as the adopted version where,
on both presets, the lower end of the 95% interval of (version 6 minus version 3) lies above -0.05 for
success and for pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot_lab.studies.version_3_pairs import against_version_3

SIX_AGAINST_THREE, _STUDY = against_version_3(6, "four co-training passes a round, refit on a new class")
"""The defaults-6 study's pair: version 6's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES = {"defaults-6": _STUDY}
