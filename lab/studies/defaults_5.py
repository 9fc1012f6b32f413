"""The defaults-5 study (confirmatory): version 5 of the defaults (version 3 with each round's
co-training in four passes) against version 3, paired by seed on ``grid16-dospcot`` and
``minigrid-doorkey-dospcot``. Version 3's runs are the numerics study's numerics-2 runs, as in the
defaults-4 study. Version 5 replaces version 3 as the adopted version where, on both presets, the lower
end of the 95% interval of (version 5 minus version 3) lies above -0.05 for success and for
pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot_lab.studies.version_3_pairs import against_version_3

FIVE_AGAINST_THREE, _STUDY = against_version_3(5, "four co-training passes a round")
"""The defaults-5 study's pair: version 5's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES = {"defaults-5": _STUDY}
