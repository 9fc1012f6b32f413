"""The defaults-4 study (confirmatory): version 4 of the defaults (version 3 with exploration by rounds)
against version 3, paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``. Version 3's
runs are the numerics study's numerics-2 runs: version 1 with numerics 2's fits, which is what version
3 resolves to. Version 4 replaces version 3 as the adopted version where, on both presets, the lower
end of the 95% interval of (version 4 minus version 3) lies above -0.05 for success and for
pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.numerics import NUMERICS_2, PRESETS
from dospcot_lab.studies.tables import (
    ADOPTION_METRICS,
    ADOPTION_SEEDS,
    NON_INFERIOR_WORDS,
    adoption_glance,
    held_lines,
    non_inferior,
    paired,
    version_rows,
)

VERSIONS = (3, 4)
METRICS = tuple(ADOPTION_METRICS)


def _version(run: TrialRun) -> int | None:
    """4 for the study's own runs, 3 for the numerics-2 runs, None for the others its sweeps hold."""
    if run.trial.params.get("defaults") == "4":
        return 4
    return 3 if run.trial.params.get("cotraining.numerics") == "2" else None


def _by_seed(runs: list[TrialRun], preset: str, version: int) -> dict[int, TrialRun]:
    return {r.trial.seed: r for r in runs if r.trial.config == preset and _version(r) == version}


def _differences(runs: list[TrialRun], preset: str) -> dict[str, SeedSummary]:
    """Per metric: version 4 minus version 3, paired by seed."""
    new, old = _by_seed(runs, preset, 4), _by_seed(runs, preset, 3)
    return {metric: paired(new, old, metric) for metric in METRICS}


def tables(runs: list[TrialRun]) -> list[str]:
    """Per preset and version: success, pseudo-reward accuracy, labels and CPU time per run; then each
    difference, version 4 minus 3, against the non-inferiority margin."""
    rows = version_rows(
        lambda preset, version: list(_by_seed(runs, preset, version).values()),
        PRESETS,
        VERSIONS,
        "defaults",
        {**ADOPTION_METRICS, "labelled_steps": "labels"},
    )
    differences = {preset: _differences(runs, preset) for preset in PRESETS}
    return [
        "",
        *rows,
        "",
        "Version 4 minus version 3, paired by seed:",
        "",
        *held_lines(differences, non_inferior, NON_INFERIOR_WORDS),
    ]


def glance(runs: list[TrialRun]) -> Glance:
    """The headline: success, version 4 minus 3, on the last preset holding its 20 pairs; the verdict:
    adopt version 4 only where every difference on both presets is non-inferior."""
    return adoption_glance(
        {preset: _differences(runs, preset) for preset in PRESETS},
        "defaults 4 minus 3",
        (
            "version 4 not shown non-inferior: not adopted",
            "non-inferior where measured; a preset not measured yet",
            "version 4 non-inferior: adopt it",
        ),
    )


STUDIES: dict[str, Study] = {
    "defaults-4": Study(
        (
            # grid16 first: its runs cost the least, and version 2 failed the rule there.
            Sweep("defaults-4", PRESETS, {"defaults": ("4",)}, batch_seeds=1, numerics=None),
            NUMERICS_2,
        ),
        tables,
        "Version 4 of the defaults against version 3: exploration by rounds",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
