"""The defaults-4 study (confirmatory): version 4 of the defaults (version 3 with exploration by rounds)
against version 3, paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's
runs are the numerics study's numerics-2 runs: version 1 with numerics 2's fits, which is what version
3 resolves to. Version 4 replaces version 3 as the adopted version where, on both presets, the lower
end of the 95% interval of (version 4 minus version 3) lies above -0.05 for success and for
pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot_lab.studies.version_3_pairs import against_version_3

FOUR_AGAINST_THREE, _STUDY = against_version_3(4, "exploration by rounds")
"""The defaults-4 study's pair: version 4's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES = {"defaults-4": _STUDY}
