"""The grid studies: the 16 x 16 presets (neural and tabular agents), on unseen layouts, the 32 x 32
map, and score against label fraction."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

from dospcot.sweeps.report import TrialRun, cells
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.provenance import score_floor
from dospcot_lab.studies.tables import (
    COLUMNS,
    FRACTION,
    GRID16_PRESETS,
    LABELS_COLUMN,
    LABELS_EXPLAINED,
    METHODS,
    by_method,
    cell_labels,
    glance_versus,
    labels_cell,
    over_seeds,
    per_view_rows,
    verdict,
    versus,
    views_line,
    with_headline,
)

WORST_CLASS = (
    "Worst-class precision: among the admitted pseudo-rewards of one reward class, the share that is "
    "right, for the class where it is lowest (lava given to ordinary steps lowers it; the mean accuracy "
    "hides it, as lava steps are few)."
)
LAYOUT_COLUMNS = ("success", "agreement", "normalised_score", "pseudo_accuracy", "worst_class_precision")
UNSEEN_LAYOUTS = ("101", "202", "303")
"""Layout seeds of the grid16-layouts study, fixed before any run on them: no preset was tuned there."""
LAYOUT = "env.layout_seed"


def grid16_tables(runs: list[TrialRun]) -> list[str]:
    """Per method: every column over seeds; then per method and view."""
    grouped = by_method(runs)
    lines = [
        views_line(grouped),
        WORST_CLASS,
        LABELS_EXPLAINED,
        "",
        "| method | preset | " + " | ".join([*COLUMNS.values(), LABELS_COLUMN]) + " |",
        "|---|---|" + "---|" * (len(COLUMNS) + 1),
    ]
    labels = cell_labels(grouped)
    for (name, params), members in grouped.items():
        stats = [*(over_seeds(members, key) for key in COLUMNS), labels_cell(members)]
        lines.append(f"| {labels[name, params]} | `{name}` | " + " | ".join(stats) + " |")
    per_view = list(COLUMNS)[:3]
    lines += [
        "",
        "Per view (the same runs; each cell over seeds):",
        "",
        "| method | view | " + " | ".join([*(COLUMNS[key] for key in per_view), LABELS_COLUMN]) + " |",
        "|---|---|" + "---|" * (len(per_view) + 1),
    ]
    return lines + per_view_rows(grouped, per_view)


def layout_tables(runs: list[TrialRun]) -> list[str]:
    """Per layout and method: success, agreement, score and pseudo-reward quality over seeds (each
    cell over seeds of the run's mean over its agents)."""
    grouped = by_method(runs)
    by_layout = sorted(grouped.items(), key=lambda item: int(dict(item[0][1])[LAYOUT]))
    floors = {dict(params)[LAYOUT]: score_floor(members[0]) for (_, params), members in by_layout}
    lines = [f"Layout {layout}: the map's {floor}." for layout, floor in floors.items()]
    lines += [
        views_line(grouped),
        WORST_CLASS,
        LABELS_EXPLAINED,
        "",
        "| layout seed | method | preset | "
        + " | ".join([*(COLUMNS[key] for key in LAYOUT_COLUMNS), LABELS_COLUMN])
        + " |",
        "|---|---|---|" + "---|" * (len(LAYOUT_COLUMNS) + 1),
    ]
    for (name, params), members in by_layout:
        stats = [*(over_seeds(members, key) for key in LAYOUT_COLUMNS), labels_cell(members)]
        lines.append(f"| {dict(params)[LAYOUT]} | {METHODS[name]} | `{name}` | " + " | ".join(stats) + " |")
    return lines


def label_fraction_tables(runs: list[TrialRun]) -> list[str]:
    """Per metric, a method x label-fraction table; then the labels each cell's runs used, in the same
    shape, so that every cell above has its labels in the same place below."""
    grouped = cells(runs)
    names = list(dict.fromkeys(name for name, _ in grouped))
    fractions = list(dict.fromkeys(dict(params)[FRACTION] for _, params in grouped))
    tables: dict[str, Callable[[list[TrialRun]], str]] = {
        f"{COLUMNS[key].capitalize()} by label fraction:": partial(over_seeds, key=key)
        for key in ("normalised_score", "success", "agreement")
    }
    tables[
        f"{LABELS_COLUMN.capitalize()} by label fraction (the labels each run held at its end, mean over "
        "seeds):"
    ] = labels_cell
    header = ["| method | " + " | ".join(fractions) + " |", "|---|" + "---|" * len(fractions)]
    lines = ["", "![normalised score and success against label fraction](docs/results/label-fraction.png)"]
    for title, cell in tables.items():
        lines += ["", title, "", *header]
        for name in names:
            stats = [cell(grouped.get((name, ((FRACTION, f),)), [])) for f in fractions]
            lines.append(f"| {METHODS.get(name, name)} | " + " | ".join(stats) + " |")
    return lines


def grid16_glance(runs: list[TrialRun]) -> Glance:
    """Success, DOSPCoT minus self-training, paired by seed."""
    return glance_versus(runs, "grid16", "success")


def grid32_glance(runs: list[TrialRun]) -> Glance:
    """Success on the 32 x 32 map, DOSPCoT minus self-training, paired by seed."""
    return glance_versus(runs, "grid32", "success")


def layouts_glance(runs: list[TrialRun]) -> Glance:
    """Success, DOSPCoT minus self-training, paired by layout and seed over the three layouts."""
    return glance_versus(
        runs, "grid16", "success", "layout and seed", key=lambda r: (r.trial.params[LAYOUT], r.trial.seed)
    )


def tabular_glance(runs: list[TrialRun]) -> Glance:
    """Success after the presets' 5 rounds, DOSPCoT minus self-training."""
    return glance_versus([r for r in runs if r.summary["rounds"] == 5], "grid16", "success", "seed, 5 rounds")


def label_fraction_glance(runs: list[TrialRun]) -> Glance:
    """Success at the fewest labels the study gives, DOSPCoT minus self-training."""
    fewest = min((r.trial.params[FRACTION] for r in runs), key=float)
    diff = versus(
        [r for r in runs if r.trial.params[FRACTION] == fewest],
        "grid16-dospcot",
        "grid16-self-training",
        "success",
    )
    return Glance(
        f"success at label fraction {fewest}, DOSPCoT minus self-training, paired by seed: {diff}",
        verdict(diff),
    )


LABEL_FRACTION = Sweep(
    "label-fraction",
    ("grid16-masked-zero", "grid16-self-training", "grid16-dospcot", "grid16-m3"),
    {FRACTION: ("0.01", "0.02", "0.05", "0.1", "0.25", "1.0")},
)
STUDIES: dict[str, Study] = {
    "grid16": Study(
        (Sweep("grid16", GRID16_PRESETS, {}),),
        with_headline(grid16_tables, grid16_glance),
        "The 16 x 16 grid study",
        "16 x 16 grid, layout 0, 5% labels",
        grid16_glance,
        seeds=10,
    ),
    # The presets on maps nobody tuned them on.
    "grid16-layouts": Study(
        (
            Sweep(
                "grid16-layouts",
                ("grid16-oracle", "grid16-self-training", "grid16-dospcot"),
                {LAYOUT: UNSEEN_LAYOUTS},
            ),
        ),
        with_headline(layout_tables, layouts_glance),
        "The 16 x 16 grid presets on three unseen layouts",
        "16 x 16 grid, layouts 101, 202, 303 (never tuned on)",
        layouts_glance,
    ),
    "grid32": Study(
        (
            Sweep(
                "grid32",
                tuple(f"grid32-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")),
                {},
            ),
        ),
        with_headline(grid16_tables, grid32_glance),
        "The 32 x 32 grid study",
        "32 x 32 grid, layout 0, 5% labels",
        grid32_glance,
    ),
    # The same six presets with a Q-table over each agent's view in place of every ExpectedSarsaDQN.
    "grid16-tabular": Study(
        (
            Sweep("grid16-tabular", GRID16_PRESETS, {"agent": ("tabular",)}),
            # A co-trained agent learns from a round's pseudo-rewards only in the next round, so
            # rewards admitted late get few updates: the same runs with twice the rounds.
            Sweep(
                "grid16-tabular-10rounds", GRID16_PRESETS, {"agent": ("tabular",), "training.rounds": ("10",)}
            ),
        ),
        grid16_tables,
        "The 16 x 16 grid study with tabular agents",
        "16 x 16 grid, layout 0, Q-table agents",
        tabular_glance,
    ),
    "label-fraction": Study(
        (LABEL_FRACTION,),
        label_fraction_tables,
        "Score against label fraction",
        "16 x 16 grid, label fractions 0.01-1.0",
        label_fraction_glance,
        plot=("score_vs_label_fraction.png", "label-fraction.png"),
    ),
}
