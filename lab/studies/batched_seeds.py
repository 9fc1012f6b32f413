"""The batched-seeds study: the same seeds of ``grid16-dospcot`` and ``grid16-oracle`` trained one run
at a time and as batches (docs/batched_seeds.md), to show that the batch gives the same science."""

from __future__ import annotations

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.tables import (
    LABELS_COLUMN,
    LABELS_EXPLAINED,
    cpu_per_run,
    held_lines,
    labels_cell,
    over_seeds,
    paired,
)

PRESETS = ("grid16-dospcot", "grid16-oracle")
METRICS = ("success", "agreement")
HALF_WIDTH = 0.1
"""The widest 95% interval of a difference that counts as measured."""
ALONE, BATCHED = "batched-seeds-alone", "batched-seeds-batched"


def _path(run: TrialRun) -> str:
    """How a run was trained: ``"alone"`` or ``"batched"`` (its sweep folder's name says)."""
    return "batched" if run.run_dir.parents[2].name.startswith(BATCHED) else "alone"


def _differences(runs: list[TrialRun], preset: str) -> dict[str, SeedSummary]:
    """Per metric: batched minus alone, paired by seed (a pair shares its seed's initial weights, mask
    and env resets; its random draws differ)."""
    alone = {r.trial.seed: r for r in runs if r.trial.config == preset and _path(r) == "alone"}
    batched = {r.trial.seed: r for r in runs if r.trial.config == preset and _path(r) == "batched"}
    return {metric: paired(batched, alone, metric) for metric in METRICS}


def _held(diff: SeedSummary) -> bool:
    return diff.low <= 0 <= diff.high and (diff.high - diff.low) / 2 <= HALF_WIDTH


def tables(runs: list[TrialRun]) -> list[str]:
    """Per preset and path: success, agreement, CPU time and labels per run; then each difference."""
    lines = [
        LABELS_EXPLAINED,
        "",  # the table a block of its own, after the page's provenance lines
        f"| preset | trained | success | agreement | CPU time per run | seeds | {LABELS_COLUMN} |",
        "|---|---|---|---|---|---|---|",
    ]
    for preset in PRESETS:
        for path in ("alone", "batched"):
            members = [r for r in runs if r.trial.config == preset and _path(r) == path]
            if members:
                cells = " | ".join(over_seeds(members, metric) for metric in METRICS)
                lines.append(
                    f"| `{preset}` | {path} | {cells} | {cpu_per_run(members)} | {len(members)} | "
                    f"{labels_cell(members)} |"
                )
    bound = f"the interval holds 0 and its half-width is at most {HALF_WIDTH}"
    differences = {preset: _differences(runs, preset) for preset in PRESETS}
    return [*lines, "", "Batched minus alone, paired by seed:", "", *held_lines(differences, _held, bound)]


def glance(runs: list[TrialRun]) -> Glance:
    """The headline: grid16-dospcot's success, batched minus alone."""
    diff = _differences(runs, "grid16-dospcot")["success"]
    held = all(_held(d) for p in PRESETS for d in _differences(runs, p).values() if d.n)
    return Glance(
        f"grid16-dospcot success, batched minus alone, paired by seed: {diff}",
        "same science" if held else "differs (or too wide)",
    )


STUDIES: dict[str, Study] = {
    "batched-seeds": Study(
        (Sweep(ALONE, PRESETS, {}, batch_seeds=1), Sweep(BATCHED, PRESETS, {}, batch_seeds=10)),
        tables,
        "Batched seeds against runs of their own",
        "grid16 (layout 0)",
        glance,
        seeds=20,
    ),
}
