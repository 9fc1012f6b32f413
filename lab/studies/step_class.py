"""The step class on DoorKey at a few labels (exploratory): whether the reward every labelled step that
went on pays, kept in a class of its own (``gym.step_class``), gives back what the labels' quantile
classes lost there.

In the views studies' DoorKey runs at 5 and 10 labels, most runs of every arm failed with the
pseudo-rewards' classes right: the classes are the labels' quantiles, and with most labels on episode
ends a late goal's low pay shared the steps' class, which then paid every step part of a goal. This
study trains DOSPCoT as the views study's low-budget arm did, with the step class on, and pairs it by
seed with that arm's runs."""

from __future__ import annotations

import json
import math
from collections.abc import Callable

import numpy as np

from dospcot.run.run_folder import REWARD_CLASSES_FILE
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies import views
from dospcot_lab.studies.budget_arms import BUDGET
from dospcot_lab.studies.declaration import EXPLORATORY, Glance, Study
from dospcot_lab.studies.tables import cpu_per_run
from dospcot_lab.studies.views import (
    LOW_BUDGETS,
    TASKS,
    arm_of,
    arm_sweep,
    comparing_arms,
    of_task,
    success_of,
)

STEP_CLASS = "gym.step_class"
"""The key the study turns on."""
VIEW = "image"
"""The agent compared: DoorKey's one-view arms' view, and the oracle's."""
QUANTILES = comparing_arms("views", "doorkey", {BUDGET: LOW_BUDGETS["doorkey"]}, "-low")[0]
"""The views study's DOSPCoT at 5 and 10 labels: the classes its labels' quantiles made."""
STEP = arm_sweep(
    "step-class",
    "doorkey",
    "DOSPCoT",
    "dospcot",
    {**QUANTILES.grid, STEP_CLASS: ("true",)},
)
"""The same runs with the step class on."""
ARMS = ("quantile classes", "step class")
"""The two ways of making the reward classes, as the tables name them."""


def _arm(run: TrialRun) -> str:
    return "step class" if run.trial.params.get(STEP_CLASS) == "true" else "quantile classes"


def steps_class_value(run: TrialRun) -> float:
    """The reward the run's lowest class paid at its last round (``reward_classes.json``): DoorKey's
    steps pay 0, so above 0 every step was paid part of a goal."""
    path = run.run_dir / REWARD_CLASSES_FILE
    values = [v for v in json.loads(path.read_text())["rewards"] if v is not None] if path.is_file() else []
    return min(values) if values else math.nan


def steps_paid(runs: list[TrialRun], budgets: Callable[[str], tuple[str, ...]]) -> list[str]:
    """Per MiniGrid task of the views studies, a table: per arm and budget of ``budgets(task)``, how many
    of the runs had a steps' class paying above 0 at their last round (:func:`steps_class_value`)."""
    lines = []
    for task, (prefix, *_) in TASKS.items():
        members = of_task(runs, task) if prefix.startswith("minigrid-") else []
        if not members:
            continue
        rows = []
        for arm in views.ARMS:
            paid = {
                b: [
                    steps_class_value(r) > 0
                    for r in members
                    if arm_of(r) == arm and r.trial.params[BUDGET] == b
                ]
                for b in budgets(task)
            }
            if any(paid.values()):
                rows.append(
                    f"| {arm} | "
                    + " | ".join(f"{sum(p)} of {len(p)}" if p else "–" for p in paid.values())
                    + " |"
                )
        if rows:
            lines += [
                "",
                f"{task}: the runs whose steps' reward class paid above 0 at the last round, of the runs at "
                "each budget (a MiniGrid step pays 0, so such a class pays every step part of a goal; "
                "[step-class](step-class.md)):",
                "",
                "| arm | " + " | ".join(f"budget {b}" for b in budgets(task)) + " |",
                "|---|" + "---|" * len(budgets(task)),
                *rows,
            ]
    return lines


def _cells(runs: list[TrialRun]) -> dict[tuple[str, str], dict[int, TrialRun]]:
    """(budget, arm) -> seed -> run."""
    cells: dict[tuple[str, str], dict[int, TrialRun]] = {}
    for r in runs:
        cells.setdefault((r.trial.params[BUDGET], _arm(r)), {})[r.trial.seed] = r
    return cells


def _paired(cells: dict[tuple[str, str], dict[int, TrialRun]], budgets: tuple[str, ...]) -> SeedSummary:
    """The image agent's success, step class minus quantile classes, paired by seed and budget."""
    diffs = [
        success_of(on[s], VIEW) - success_of(off[s], VIEW)
        for b in budgets
        for on, off in [(cells.get((b, "step class"), {}), cells.get((b, "quantile classes"), {}))]
        for s in sorted(set(on) & set(off))
    ]
    return SeedSummary.of(diffs)


def tables(runs: list[TrialRun]) -> list[str]:
    """Per budget and arm: the image agent's success, the run's mean success, the steps' class value
    at the last round and how many runs paid steps above 0; then the paired differences."""
    cells = _cells(runs)
    budgets = LOW_BUDGETS["doorkey"]
    lines = [
        "",
        "| labels | classes | success, image agent | success, both agents | the steps' class pays | "
        "runs paying steps above 0 | CPU time per run |",
        "|---|---|---|---|---|---|---|",
    ]
    for b in budgets:
        for arm in ARMS:
            members = list(cells.get((b, arm), {}).values())
            if members:
                paid = [steps_class_value(r) for r in members]
                lines.append(
                    f"| {b} | {arm} | {SeedSummary.of([success_of(r, VIEW) for r in members])} | "
                    f"{SeedSummary.of([success_of(r) for r in members])} | {np.nanmean(paid):.3f} | "
                    f"{sum(p > 0 for p in paid)} of {len(members)} | {cpu_per_run(members)} |"
                )
    lines += ["", "The image agent's success, step class minus quantile classes, paired by seed:", ""]
    for b in budgets:
        one = _paired(cells, (b,))
        lines.append(f"- {b} labels: {one} over {one.n} seeds.")
    both = _paired(cells, budgets)
    return [*lines, f"- both budgets: {both} over {both.n} pairs."]


def glance(runs: list[TrialRun]) -> Glance:
    """The headline: the image agent's success at 5 and 10 labels, step class minus quantiles."""
    both = _paired(_cells(runs), LOW_BUDGETS["doorkey"])
    return Glance(
        "DoorKey at 5 and 10 labels, image agent's success, step class minus quantile classes, "
        f"paired: {both}",
        EXPLORATORY,
    )


STUDIES: dict[str, Study] = {
    "step-class": Study(
        (QUANTILES, STEP),
        tables,
        "The steps' own reward class on DoorKey at a few labels",
        "MiniGrid DoorKey-5x5, 5 and 10 labels",
        glance,
        seeds=10,
    ),
}
