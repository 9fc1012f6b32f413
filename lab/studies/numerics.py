"""The numerics studies, each a newer numerics version against numerics 1 (float64 fits over the whole
pool, dense agents), paired by seed on ``grid16-dospcot`` and ``minigrid-doorkey-dospcot``:
``numerics``, numerics 2 (the reward classifiers fit in float32, on the samples that carry weight), to
show that the cheaper fits give the same science; ``numerics-3``, numerics 3 (numerics 2 plus a sparse
first layer and a fused Adam for every network), decided by the adoption rule for a default alone."""

from __future__ import annotations

import dataclasses

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.batched_seeds import ALONE
from dospcot_lab.studies.declaration import NOT_MEASURED, Glance, Study, Sweep
from dospcot_lab.studies.defaults import VERSION_SWEEPS
from dospcot_lab.studies.tables import (
    ADOPTION_METRICS,
    ADOPTION_SEEDS,
    CLASS_RECALL,
    CLASS_RECALL_NOTE,
    NON_INFERIOR_WORDS,
    adoption_glance,
    deciding_preset,
    held_lines,
    non_inferior,
    numerics_of,
    paired,
    version_rows,
)

PRESETS = ("grid16-dospcot", "minigrid-doorkey-dospcot")
METRICS = tuple(ADOPTION_METRICS)
HALF_WIDTH = 0.1
"""How far from 0 either end of a difference's 95% interval may lie for the same science (the bound
registered before the runs: equivalence)."""


def _by_seed(runs: list[TrialRun], preset: str, numerics: int) -> dict[int, TrialRun]:
    """The runs of ``preset`` trained under ``numerics``, by seed (the version each run_info.json names)."""
    return {r.trial.seed: r for r in runs if r.trial.config == preset and numerics_of(r) == numerics}


def _differences(
    runs: list[TrialRun], preset: str, new_numerics: int = 2, old_numerics: int = 1
) -> dict[str, SeedSummary]:
    """Per metric: numerics ``new_numerics`` minus ``old_numerics``, paired by seed (a pair shares its
    seed's initial weights, mask and env resets; the fits' numbers differ, and with them every later
    draw)."""
    new, old = _by_seed(runs, preset, new_numerics), _by_seed(runs, preset, old_numerics)
    return {metric: paired(new, old, metric, across_numerics=True) for metric in METRICS}


def _held(diff: SeedSummary) -> bool:
    return diff.low <= 0 <= diff.high and diff.low >= -HALF_WIDTH and diff.high <= HALF_WIDTH


def _rows(runs: list[TrialRun], versions: tuple[int, ...]) -> list[str]:
    """The table, after a blank line (a block of its own, after the page's provenance lines): per preset
    and numerics version of ``versions``, success, pseudo-reward accuracy and CPU time per run."""

    def members(preset: str, version: int) -> list[TrialRun]:
        return list(_by_seed(runs, preset, version).values())

    columns = {**ADOPTION_METRICS, **CLASS_RECALL}
    return ["", *version_rows(members, PRESETS, versions, "numerics", columns), "", CLASS_RECALL_NOTE]


def tables(runs: list[TrialRun]) -> list[str]:
    """Per preset and numerics: success, pseudo-reward accuracy and CPU time per run; then each
    difference, numerics 2 minus 1."""
    bound = f"the interval holds 0 and lies within +-{HALF_WIDTH}"
    differences = {preset: _differences(runs, preset) for preset in PRESETS}
    return [
        *_rows(runs, (1, 2)),
        "",
        "Numerics 2 minus numerics 1, paired by seed, against the registered equivalence bound:",
        "",
        *held_lines(differences, _held, bound),
        "",
        "The same differences against the adoption rule for a default (non-inferiority):",
        "",
        *held_lines(differences, non_inferior, NON_INFERIOR_WORDS),
    ]


def glance(runs: list[TrialRun]) -> Glance:
    """The headline: success, numerics 2 minus 1, on the last preset measured under both (DoorKey once
    it is); the verdict by the adoption rule for a default (non-inferiority on both presets)."""
    return adoption_glance(
        {preset: _differences(runs, preset) for preset in PRESETS},
        "numerics 2 minus 1",
        (
            "numerics 2 not shown non-inferior",
            "non-inferior where measured; DoorKey not measured yet",
            "numerics 2 non-inferior: adopt it",
        ),
    )


def tables_3(runs: list[TrialRun]) -> list[str]:
    """Per preset and numerics (1, 2, 3): success, pseudo-reward accuracy and CPU time per run; then
    each difference against the adoption rule for a default: numerics 3 minus 1 (the registered
    comparison), and numerics 3 minus 2 (the numerics adopted after the study was registered, which
    the amendment of 2026-12-02 also holds numerics 3 to)."""
    none = ["- No preset holds a pair yet."]
    registered = {preset: _differences(runs, preset, 3) for preset in PRESETS}
    against_adopted = {preset: _differences(runs, preset, 3, 2) for preset in PRESETS}
    return [
        *_rows(runs, (1, 2, 3)),
        "",
        f"Numerics 3 minus numerics 1, paired by seed, against the adoption rule for a default "
        f"({ADOPTION_SEEDS} pairs on each preset):",
        "",
        *(held_lines(registered, non_inferior, NON_INFERIOR_WORDS) or none),
        "",
        "Numerics 3 minus numerics 2, the numerics version 3 of the defaults adopted after this study "
        "was registered, paired by seed, against the same rule (the amendment):",
        "",
        *(held_lines(against_adopted, non_inferior, NON_INFERIOR_WORDS) or none),
    ]


ADOPT_3 = "numerics 3 non-inferior to 1 and to 2: adopt it"
"""The numerics-3 study's verdict where both comparisons meet the adoption rule on both presets."""


def glance_3(runs: list[TrialRun]) -> Glance:
    """The headline: success, numerics 3 minus 1 and minus 2, on the preset deciding the registered
    comparison (:func:`~dospcot_lab.studies.tables.deciding_preset`); the verdict by the adoption rule
    for a default, which both comparisons must meet on both presets."""
    verdicts = (
        "numerics 3 not shown non-inferior",
        "non-inferior where measured; a preset not measured yet",
        ADOPT_3,
    )
    against_1, against_2 = ({p: _differences(runs, p, 3, old) for p in PRESETS} for old in (1, 2))
    registered = adoption_glance(against_1, "numerics 3 minus 1", verdicts)
    adopted = adoption_glance(against_2, "numerics 3 minus 2", verdicts)
    if registered.verdict == NOT_MEASURED:
        return registered
    if adopted.verdict == NOT_MEASURED:
        return Glance(registered.headline, verdicts[1])
    verdict = next(v for v in verdicts if v in (registered.verdict, adopted.verdict))
    # The headline's preset, the one deciding the registered comparison, named against numerics 2 too.
    preset = deciding_preset(against_1)
    return Glance(f"{registered.headline}; minus 2: {against_2[preset]['success']}", verdict)


NUMERICS_1 = (
    # grid16-dospcot's seeds 0-19 under numerics 1 are the batched-seeds study's runs alone, and
    # DoorKey's the defaults study's under version 1: each the preset alone under numerics 1.
    Sweep(ALONE, ("grid16-dospcot", "grid16-oracle"), {}, batch_seeds=1),
    dataclasses.replace(VERSION_SWEEPS[1], reads=PRESETS[1:]),
)
"""The numerics-1 arm both studies pair their runs with."""

NUMERICS_2 = Sweep("numerics-2", PRESETS, {"cotraining.numerics": ("2",)}, batch_seeds=1, numerics=None)
"""The numerics study's own sweep; the numerics-3 study reads it for its comparison with numerics 2."""

STUDIES: dict[str, Study] = {
    "numerics": Study(
        (
            NUMERICS_2,
            *NUMERICS_1,
        ),
        tables,
        "Numerics 2 against numerics 1: the cheaper classifier fits",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
    "numerics-3": Study(
        (
            # DoorKey first: its runs cost the most and decide the most.
            Sweep(
                "numerics-3",
                PRESETS[::-1],
                {"cotraining.numerics": ("3",)},
                batch_seeds=1,
                numerics=None,
            ),
            *NUMERICS_1,
            NUMERICS_2,
        ),
        tables_3,
        "Numerics 3 against numerics 1: sparse first layers and fused Adam",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        glance_3,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
