"""The defaults-12 study (confirmatory): version 12 of the defaults (version 10, the MiniGrid presets'
agents and the label study's queries at 100 labels, with ten score passes a round for DOSPCoT) against
version 3, paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's runs are
the numerics study's numerics-2 runs, as in the defaults-4 study. Version 12 replaces version 3 as the
adopted version where, on both presets, the lower end of the 95% interval of (version 12 minus
version 3) lies above -0.05 for success and for pseudo-reward accuracy (non-inferiority;
docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot_lab.studies.version_3_pairs import against_version_3

TWELVE_AGAINST_THREE, _STUDY = against_version_3(12, "100 chosen labels and ten score passes a round")
"""The defaults-12 study's pair: version 12's runs name it in their grid, version 3's are numerics-2 runs."""

STUDIES = {"defaults-12": _STUDY}
