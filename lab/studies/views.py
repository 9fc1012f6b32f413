"""The views study, exploratory (issue 79): where does the second view pay? On each task (grid16,
grid16 with blind spots, where each view errs where the other sees, MiniGrid DoorKey and LavaGap, the
fast highway), at four label budgets, DOSPCoT (two views) against the one-view peers with the same
query strategy and labels: a same-sensor twin (two agents and classifiers on one view: a second model
without a second view), the reward-model peer and self-training; the blind control (random queries)
at the largest budget; the oracle with every reward; on the blind-spot task also DOSPCoT with both
views blind on the same cells, its errors made dependent. Every arm trains under version 12 of the
defaults, the adopted one (one schedule, one exploration setting, ten score passes a round, which the
reward model takes by its config), and numerics 2, seeds 0-9; a confirmatory study on other seeds and
maps follows its preregistration. A first look under version 2 (sweeps without the ``-v12`` suffix) is
kept in the record and not read here.

Arms carry short names on every table and figure (:data:`ARMS`); their full settings are in one table
under the figure.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dospcot.run.plots import Band, plot_bands
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.budget_arms import BUDGET, STRATEGY
from dospcot_lab.studies.declaration import EXPLORATORY, Glance, Study, Sweep
from dospcot_lab.studies.error_dependence import (
    by_round_table,
    last_round_dependence,
    last_round_table,
    mean_text,
)
from dospcot_lab.studies.grid_studies import LAYOUT
from dospcot_lab.studies.label_curves import SHARE, Curve, labels_text
from dospcot_lab.studies.tables import cpu_per_run, labels_used

DEFAULTS, NUMERICS, SEEDS = 12, 2, 10

SCORE_PASSES = {"training.cotrain_passes": ("10",), "training.pass_kind": ('"score"',)}
"""Version 12's ten score passes a round, which it gives DOSPCoT's method alone: the reward model takes
them here by its config, so every arm's steps are rewarded a tenth of a round after they are taken."""

BLIND_RATE, BLIND_SPOTS = "env.blind_spot_rate", "env.blind_spots"
BLIND = {BLIND_RATE: ("0.5",), BLIND_SPOTS: ('"independent"',)}
"""grid16 with blind spots: each terrain view reads half the lava cells as floor, each view its own
half, so each errs where the other sees (the second-view study's setting): where theory says a second
view must pay."""

TASKS: dict[str, tuple[str, str, tuple[str, ...], dict[str, tuple[str, ...]]]] = {
    "grid16": ("grid16", "patch", ("5", "10", "20", "40"), {}),
    "grid16-blind-spots": ("grid16", "patch", ("5", "10", "20", "40"), BLIND),
    "doorkey": ("minigrid-doorkey", "image", ("25", "50", "100", "200"), {}),
    "lavagap": ("minigrid-lavagap", "image", ("25", "50", "100", "200"), {}),
    "fasthighway": ("fasthighway", "kinematics", ("100", "200", "400", "800"), {}),
}
"""Per task: its presets' prefix, the view of its one-view arms (the presets' own), its budgets and
the settings every arm of it takes."""

LOW_BUDGETS: dict[str, tuple[str, ...]] = {
    "grid16": ("1", "2", "3"),
    "doorkey": ("5", "10"),
    "fasthighway": ("25", "50"),
}
"""Budgets below the registered ones, added after the exploration's seeds 0-1 under version 12 (its
first runs) had every arm at the oracle at the smallest registered budget on grid16 and DOSPCoT at 90%
of it there on DoorKey, and after seed 0 of DOSPCoT on the fast highway held the oracle's success at
100 labels: a curve needs budgets where the arms fail. The arms that compare views train them in sweeps
of their own (``-low`` before the version's suffix); the blind control keeps the largest budget
alone."""


def budgets_of(task: str) -> tuple[str, ...]:
    """Every budget of ``task``, the lower ones first (:data:`LOW_BUDGETS`, then :data:`TASKS`')."""
    return LOW_BUDGETS.get(task, ()) + TASKS[task][2]


DISAGREEMENT, UNCERTAINTY = '"outcomes+disagreement"', '"outcomes+uncertainty"'
ARMS: dict[str, str] = {
    "DOSPCoT": "two views co-trained (the task's DOSPCoT preset), outcomes+disagreement queries",
    "twin": "two agents and two classifiers on the one-view arms' view, each from its own initial "
    "weights and draws, co-trained as DOSPCoT is, outcomes+disagreement queries",
    "reward model": "an ensemble of reward classifiers on one view fitted on the labels alone, "
    "rewarding every unlabelled sample, and between fits the samples met since (ten score passes a "
    "round); outcomes+disagreement queries (between its members)",
    "self-training": "one view co-trained with itself (one agent, one classifier), "
    "outcomes+uncertainty queries",
    "blind": "DOSPCoT with random queries, at the largest budget only",
    "DOSPCoT, identical blind spots": "DOSPCoT where both views miss the same lava cells (blind-spot task "
    "only): the views' errors made dependent, so no view can correct the other",
}
"""Each arm's short name and its settings in words; every arm also takes version 12's defaults."""
ONE_VIEW = ("twin", "reward model", "self-training")
"""The arms that read one view, DOSPCoT's peers."""


Grid = dict[str, tuple[str, ...]]


def arm_sweep(
    study: str, task: str, arm: str, preset: str, grid: Grid, part: str = "", maps: Grid | None = None
) -> Sweep:
    """One arm's sweep of ``study`` on ``task``, at the settings ``grid`` adds to the task's and ``maps``'
    (grid16's layouts)."""
    prefix, _, _, settings = TASKS[task]
    name = f"{study}-{task}-{arm.lower().replace(' ', '-')}{part}-v{DEFAULTS}"
    return Sweep(
        name,
        (f"{prefix}-{preset}",),
        {**settings, **(maps or {}), **grid},
        numerics=NUMERICS,
        defaults=DEFAULTS,
    )


def comparing_arms(
    study: str, task: str, spend: Grid, part: str = "", maps: Grid | None = None
) -> tuple[Sweep, ...]:
    """The sweeps of the arms that compare views (DOSPCoT, the twin, the reward model, self-training) at
    the budgets of ``spend``."""
    view = TASKS[task][1]
    disagreement = {**spend, STRATEGY: (DISAGREEMENT,)}
    return (
        arm_sweep(study, task, "DOSPCoT", "dospcot", disagreement, part, maps),
        arm_sweep(
            study, task, "twin", "dospcot", {**disagreement, "views": (f'["{view}", "{view}"]',)}, part, maps
        ),
        arm_sweep(study, task, "reward model", "reward-model", {**disagreement, **SCORE_PASSES}, part, maps),
        arm_sweep(
            study, task, "self-training", "self-training", {**spend, STRATEGY: (UNCERTAINTY,)}, part, maps
        ),
    )


def curve_sweeps(
    study: str, task: str, budgets: tuple[str, ...], maps: Grid | None = None
) -> tuple[Sweep, ...]:
    """A task's curves: the oracle, the arms that compare views at ``budgets`` and the blind control at
    the largest."""
    return (
        arm_sweep(study, task, "oracle", "oracle", {}, maps=maps),
        *comparing_arms(study, task, {BUDGET: budgets}, maps=maps),
        arm_sweep(
            study, task, "blind", "dospcot", {BUDGET: budgets[-1:], STRATEGY: ('"random"',)}, maps=maps
        ),
    )


def _sweeps(task: str) -> tuple[Sweep, ...]:
    """The exploration's sweeps of ``task``: its curves at the registered budgets, DOSPCoT with identical
    blind spots on the blind-spot task, and the arms that compare views below the registered budgets."""
    budgets, settings = TASKS[task][2], TASKS[task][3]
    identical = (
        (
            arm_sweep(
                "views",
                task,
                "dospcot-identical",
                "dospcot",
                {BUDGET: budgets, STRATEGY: (DISAGREEMENT,), BLIND_SPOTS: ('"identical"',)},
            ),
        )
        if BLIND_SPOTS in settings
        else ()
    )
    low = comparing_arms("views", task, {BUDGET: LOW_BUDGETS[task]}, "-low") if task in LOW_BUDGETS else ()
    return (*curve_sweeps("views", task, budgets), *identical, *low)


def arm_of(run: TrialRun) -> str:
    """A run's short arm name (a key of :data:`ARMS`, or "oracle")."""
    config, params = run.trial.config, run.trial.params
    if config.endswith("-oracle"):
        return "oracle"
    if config.endswith("-reward-model"):
        return "reward model"
    if config.endswith("-self-training"):
        return "self-training"
    if params.get(STRATEGY) == '"random"':
        return "blind"
    if params.get(BLIND_SPOTS) == '"identical"':
        return "DOSPCoT, identical blind spots"
    return "twin" if "views" in params else "DOSPCoT"


def task_of(run: TrialRun) -> str | None:
    """The key of :data:`TASKS` a run belongs to, by its preset and whether it has blind spots (None:
    none)."""
    blind = BLIND_RATE in run.trial.params
    return next(
        (
            task
            for task, (prefix, _, _, settings) in TASKS.items()
            if run.trial.config.startswith(f"{prefix}-") and (BLIND_RATE in settings) == blind
        ),
        None,
    )


def of_task(runs: list[TrialRun], task: str) -> list[TrialRun]:
    """The runs of ``runs`` that belong to ``task`` (:func:`task_of`)."""
    return [r for r in runs if task_of(r) == task]


def success_of(run: TrialRun, view: str | None = None) -> float:
    """A run's last-round success: the mean over its agents, or (``view``) over its agents on that view
    alone (a twin's second agent on it is named ``<view>-2``); NaN where no agent reads ``view``."""
    if view is None:
        return float(run.summary["mean"]["success"])
    on_view = [
        v["success"]
        for k, v in run.summary["per_view"].items()
        if re.fullmatch(rf"{re.escape(view)}(-\d+)?", k)
    ]
    return float(np.mean(on_view)) if on_view else math.nan


def pair_of(run: TrialRun) -> tuple[str, int]:
    """What pairs a run with the other arms' runs: its grid16 layout ("" on other tasks) and seed."""
    return run.trial.params.get(LAYOUT, ""), run.trial.seed


def curves(runs: list[TrialRun], view: str | None = None) -> dict[str, Curve]:
    """Each arm's curve on one task's ``runs``, over the pairs (:func:`pair_of`) the arm ran at every
    budget and the oracle ran too; an arm with no such pair has none. Success is each run's mean over its
    agents, or (``view``) over its agents on that view (:func:`success_of`)."""
    oracle = {pair_of(r): success_of(r, view) for r in runs if arm_of(r) == "oracle"}
    found = {}
    for arm in ARMS:
        cells: dict[str, dict[tuple[str, int], TrialRun]] = {}
        for r in runs:
            if arm_of(r) == arm:
                cells.setdefault(r.trial.params[BUDGET], {})[pair_of(r)] = r
        pairs = sorted(set(oracle).intersection(*(set(c) for c in cells.values()))) if cells else []
        if pairs:
            order = sorted(cells, key=float)
            found[arm] = Curve(
                np.array([float(b) for b in order]),
                np.array([[labels_used(cells[b][p]) for b in order] for p in pairs]),
                np.array([[success_of(cells[b][p], view) for b in order] for p in pairs]),
                np.array([oracle[p] for p in pairs], dtype=float),
                tuple(pairs),
            )
    return found


def _task_table(task: str, runs: list[TrialRun], budgets: tuple[str, ...]) -> list[str]:
    """One task: each arm's success as a share of the oracle's at each budget (labels used beside it),
    the labels to reach 90% of the oracle with its interval, and the area under its curve; first over
    each run's agents, then over its agents on the one-view arms' view alone."""
    view = TASKS[task][1]
    oracle = [r for r in runs if arm_of(r) == "oracle"]
    lines = [
        "",
        f"### {task}",
        "",
        f"The oracle (every reward): success {SeedSummary.of([success_of(r) for r in oracle])}"
        f" over {len(oracle)} seeds; {cpu_per_run(oracle)}.",
    ]
    found = curves(runs)
    if not found:
        return lines
    lines += ["", *_curve_rows(budgets, found, runs)]
    on_view = curves(runs, view)
    if any(arm in on_view for arm in ("DOSPCoT", "blind")):
        lines += [
            "",
            f"The same on the {view} agent alone, the view of the one-view arms: DOSPCoT's and the blind "
            f"control's other agent left out, and the oracle's {view} agent the target "
            f"({SeedSummary.of([success_of(r, view) for r in oracle])}):",
            "",
            *_curve_rows(budgets, on_view, runs),
        ]
    return lines


def _curve_rows(budgets: tuple[str, ...], found: dict[str, Curve], runs: list[TrialRun]) -> list[str]:
    """The table of each arm's curve in ``found``: its share of the oracle at each budget with the labels
    used, its labels to the oracle's share, the area under it, its seeds and CPU time per run."""
    lines = [
        f"| arm | {' | '.join(f'budget {b}' for b in budgets)} | labels to {SHARE:.0%} of the oracle "
        "[95% interval] | area under the curve | runs per budget | CPU time per run |",
        "|---|" + "---|" * (len(budgets) + 4),
    ]
    for arm, curve in found.items():
        at = dict(
            zip(
                curve.budgets,
                zip(curve.labels.mean(axis=0), curve.shares().mean(axis=0), strict=True),
                strict=True,
            )
        )
        shown = [
            f"{at[float(b)][1]:.2f} ({at[float(b)][0]:,.0f})" if float(b) in at else "–" for b in budgets
        ]
        ends = curve.ends()
        low, high = curve.labels_interval()
        reach = f"{curve.reach_text()} [{labels_text(low, *ends)}, {labels_text(high, *ends)}]"
        area = curve.area()
        members = [r for r in runs if arm_of(r) == arm]
        lines.append(
            f"| {arm} | {' | '.join(shown)} | {reach} | {'–' if math.isnan(area) else f'{area:.2f}'} | "
            f"{len(curve.oracle)} | {cpu_per_run(members)} |"
        )
    return lines


COMPARED = ("DOSPCoT", "twin", "reward model", "DOSPCoT, identical blind spots")
"""The arms with two classifiers or more, whose errors' dependence the pages compare."""


def by_compared_arm(runs: list[TrialRun]) -> dict[str, list[TrialRun]]:
    """``runs`` of the :data:`COMPARED` arms, grouped by arm in that order."""
    return {arm: [r for r in runs if arm_of(r) == arm] for arm in COMPARED}


REWARD_QUALITY = {
    "pseudo_accuracy": "Pseudo-reward accuracy",
    "worst_class_recall": "Worst-class recall (of the reward class least often given its reward, the share "
    "of its samples given it)",
}
"""The pseudo-reward figures a task's tables give per arm and budget. Accuracy is dominated by the
commonest class; worst-class recall reads 0 where no label showed a class (a goal never labelled)."""


def _accuracy_table(
    runs: list[TrialRun], budgets: tuple[str, ...], metric: str = "pseudo_accuracy"
) -> list[str]:
    """Per arm that rewards unlabelled samples, ``metric`` (:data:`REWARD_QUALITY`) at each budget, mean
    over seeds at the last round: where success saturates (the grid, whose lava does not end an
    episode), what the classifiers got right still tells the arms apart."""
    lines = [f"| arm | {' | '.join(f'budget {b}' for b in budgets)} |", "|---|" + "---|" * len(budgets)]
    for arm in (a for a in ARMS if a != "blind"):
        cells = {
            b: [r.summary["mean"][metric] for r in runs if arm_of(r) == arm and r.trial.params[BUDGET] == b]
            for b in budgets
        }
        if any(cells.values()):
            shown = [f"{np.mean(v):.3f}" if v else "–" for v in cells.values()]
            lines.append(f"| {arm} | {' | '.join(shown)} |")
    return lines if len(lines) > 2 else []


def _reach_against_best_peer(found: dict[str, Curve]) -> tuple[str, str | None]:
    """DOSPCoT's labels to the oracle's share (its curve in ``found``), and the one-view peer's that
    needs the fewest, named ("twin 40"; None where no peer has a curve), as :func:`labels_text` writes
    them."""
    peers = {arm: found[arm].labels_to_reach() for arm in ONE_VIEW if arm in found}
    best = min(peers, key=peers.get) if peers else None
    mine = found["DOSPCoT"].reach_text()
    return mine, (f"{best} {found[best].reach_text()}" if best else None)


def _margins(runs: list[TrialRun]) -> list[str]:
    """Across tasks: DOSPCoT's views' error correlation beside the twin's, and the labels each needs to
    reach the oracle's share beside the best one-view peer's, over each run's agents and then on the
    one-view arms' view alone, so dependence reads against margin."""
    lines = [
        f"| task | DOSPCoT's error correlation | the twin's | DOSPCoT's labels to {SHARE:.0%} | "
        "best one-view peer's | on the peers' view: DOSPCoT's | best peer's |",
        "|---|---|---|---|---|---|---|",
    ]
    for task, (_, view, _, _) in TASKS.items():
        members = of_task(runs, task)
        found, on_view = curves(members), curves(members, view)
        if "DOSPCoT" not in found:
            continue
        grouped = by_compared_arm(members)
        correlation = {
            arm: mean_text([last_round_dependence(r)["error_correlation"] for r in grouped[arm]])
            for arm in ("DOSPCoT", "twin")
        }
        mine, peer = _reach_against_best_peer(found)
        mine_on_view, peer_on_view = _reach_against_best_peer(on_view)
        lines.append(
            f"| {task} | {correlation['DOSPCoT']} | {correlation['twin']} | {mine} | {peer or '–'} | "
            f"{mine_on_view} | {peer_on_view or '–'} |"
        )
    return lines if len(lines) > 2 else []


def tables_linking(
    figure_name: str, budgets: Callable[[str], tuple[str, ...]] = budgets_of
) -> Callable[[list[TrialRun]], list[str]]:
    """The tables of a page whose figure is ``figure_name``, each task's columns at ``budgets(task)``:
    per task, the arms' curves (:func:`_task_table`), their pseudo-reward accuracy and their classifiers'
    error dependence; then, across tasks, dependence beside margin; then every arm's settings."""

    def tables(runs: list[TrialRun]) -> list[str]:
        """The study's tables on ``runs``, its figure linked as ``figure_name``."""
        lines = [
            "",
            f"Each budget's cell: success as a share of the oracle's mean success (labels used per run). "
            f"Labels to {SHARE:.0%} of the oracle are interpolated on the arm's mean curve, with a 95% "
            'bootstrap interval over seeds ("> N": not reached by its largest budget, N labels; "<= N": '
            "reached at its smallest); the area under the curve is over log labels from the arm's smallest "
            f"budget to its largest, the oracle's being 1. Figure: [{figure_name}]({figure_name}).",
        ]
        for task in TASKS:
            members = of_task(runs, task)
            if members:
                lines += _task_table(task, members, budgets(task))
                for metric, heading in REWARD_QUALITY.items():
                    quality = _accuracy_table(members, budgets(task), metric)
                    if quality:
                        lines += ["", f"{heading}, mean over seeds, last round:", "", *quality]
                grouped = by_compared_arm(members)
                dependence = last_round_table(grouped)
                if dependence:
                    lines += [
                        "",
                        "The classifiers' error dependence, last round (docs/design.md, section 4):",
                        "",
                    ]
                    lines += dependence
                    lines += [
                        "",
                        "The same by round: the error correlation's mean over the runs whose classifiers "
                        "both erred somewhere on the scored samples (elsewhere it is undefined; those runs "
                        "are counted), and the disagreement's over every run. Co-training fits each view's "
                        "classifier to the other's pseudo-rewards, which can merge the classifiers' errors "
                        "over the rounds: the first rounds show how the views err before the exchange has "
                        "run long, the last round what it left. Reported, outside any hypothesis (the "
                        "preregistration reads the last round):",
                        "",
                        *by_round_table(grouped),
                    ]
        margins = _margins(runs)
        if margins:
            lines += ["", "### Dependence against margin", "", *margins]
        return [*lines, "", "| arm | settings |", "|---|---|", *(f"| {a} | {s} |" for a, s in ARMS.items())]

    return tables


tables = tables_linking("views.png")


def figure(runs: list[TrialRun], path: Path, on_view: bool = False) -> None:
    """One panel per task: each arm's success as a share of the oracle's against labels used (log
    axis), with its 95% band over seeds; the success of each run's agents, or (``on_view``) of its
    agents on the one-view arms' view."""
    panels = {}
    for task, (_, view, _, _) in TASKS.items():
        bands = []
        for arm, curve in curves(of_task(runs, task), view if on_view else None).items():
            x, y = curve.share()
            shares, order = curve.shares(), np.argsort(curve.labels.mean(axis=0))
            stats = [SeedSummary.of(list(shares[:, i])) for i in order]
            bands.append(Band(arm, x, y, np.array([s.low for s in stats]), np.array([s.high for s in stats])))
        if bands:
            panels[task] = bands
    if panels:
        plot_bands(panels, "labels used per run", "success / oracle's", path, log_x=True, markers=True)


def glance(runs: list[TrialRun]) -> Glance:
    """The headline: on each task measured, DOSPCoT's labels to 90% of the oracle against the best
    one-view peer's."""
    parts = []
    for task in TASKS:
        found = curves(of_task(runs, task))
        if "DOSPCoT" in found:
            mine, peer = _reach_against_best_peer(found)
            parts.append(f"{task}: DOSPCoT {mine}" + (f", {peer}" if peer else ""))
    return Glance(f"labels to {SHARE:.0%} of the oracle: " + "; ".join(parts) if parts else "", EXPLORATORY)


STUDIES: dict[str, Study] = {
    "views": Study(
        tuple(s for task in TASKS for s in _sweeps(task)),
        tables,
        "Where the second view pays: label-efficiency curves",
        "grid16 (layout 0, and with blind spots), MiniGrid DoorKey-5x5 and LavaGapS7, the fast highway",
        glance,
        seeds=SEEDS,
        figure=figure,
    ),
}
