"""The defaults study: version 2 of the defaults against version 1, paired by seed on
``grid16-dospcot`` and ``minigrid-doorkey-dospcot``, each config giving only its preset (so every
moved default takes its version's value). Version 2 replaces version 1 as the adopted version where,
on both presets, the lower end of the 95% interval of (version 2 minus version 1) lies above -0.05
for success and for pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study, Sweep
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

PRESETS = ("grid16-dospcot", "minigrid-doorkey-dospcot")
METRICS = tuple(ADOPTION_METRICS)
VERSIONS = (1, 2)


def _version(run: TrialRun) -> int:
    return int(run.trial.params.get("defaults", 1))


def _by_seed(runs: list[TrialRun], preset: str, version: int) -> dict[int, TrialRun]:
    return {r.trial.seed: r for r in runs if r.trial.config == preset and _version(r) == version}


def _differences(runs: list[TrialRun], preset: str) -> dict[str, SeedSummary]:
    """Per metric: version 2 minus version 1, paired by seed."""
    new, old = _by_seed(runs, preset, 2), _by_seed(runs, preset, 1)
    return {metric: paired(new, old, metric) for metric in METRICS}


def tables(runs: list[TrialRun]) -> list[str]:
    """Per preset and version: success, pseudo-reward accuracy, labels and CPU time per run; then each
    difference, version 2 minus 1, against the non-inferiority margin."""
    lines = [
        "",
        *version_rows(
            lambda preset, version: list(_by_seed(runs, preset, version).values()),
            PRESETS,
            VERSIONS,
            "defaults",
            {**ADOPTION_METRICS, "labelled_steps": "labels"},
        ),
    ]
    differences = {preset: _differences(runs, preset) for preset in PRESETS}
    return [
        *lines,
        "",
        "Version 2 minus version 1, paired by seed:",
        "",
        *held_lines(differences, non_inferior, NON_INFERIOR_WORDS),
    ]


def glance(runs: list[TrialRun]) -> Glance:
    """The headline: DoorKey's success, version 2 minus 1 (grid16's until DoorKey holds its 20 seeds);
    the verdict: adopt version 2 only where every difference on both presets is non-inferior."""
    return adoption_glance(
        {preset: _differences(runs, preset) for preset in PRESETS},
        "defaults 2 minus 1",
        (
            "version 2 not shown non-inferior: not adopted",
            "not measured yet (a preset lacks one version's runs)",
            "version 2 non-inferior: adopt it",
        ),
    )


VERSION_SWEEPS = {
    version: Sweep(f"defaults-{version}", PRESETS, {"defaults": (str(version),)}, batch_seeds=1)
    for version in VERSIONS
}
"""Each version's sweep: both presets, nothing but the version set, under numerics 1 (a sweep's own)."""


STUDIES: dict[str, Study] = {
    "defaults": Study(
        tuple(VERSION_SWEEPS.values()),
        tables,
        "Version 2 of the defaults against version 1",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
