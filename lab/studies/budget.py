"""Labels that pay: a label budget counted in answers, spread over the rounds, against the
reward-model peer, with label-efficiency curves. ``budget-explore`` is the exploration (seeds 0-2,
recorded as exploratory; its studies are declared in :mod:`~dospcot_lab.studies.budget_explore`); it
chooses the settings a confirmatory study registers before its runs.

Its tables split a shortfall against the oracle into its parts: the labels each arm bought, its
success round by round beside the oracle's (fewer rounds with a reward), the pseudo-rewards per hidden
reward class in the last round (wrong or missing rewards, from each run's ``pseudo_rewards.csv``), and
success against labels bought with the labels each arm needs to reach 90% of the oracle's success.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dospcot.run.plots import Band, plot_bands
from dospcot.run.run_folder import METRICS_FILE, PSEUDO_REWARDS_FILE
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.budget_arms import (
    BUDGET,
    ENDS,
    EXPLORATION,
    REFIT,
    SCHEDULE,
    STRATEGY,
    by_arm,
    short_names,
)
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.grid_studies import LAYOUT
from dospcot_lab.studies.label_curves import first_reach
from dospcot_lab.studies.tables import FRACTION, LABELS_COLUMN, labels_cell, labels_used

ORACLE_SHARE = 0.9
"""Label efficiency: the labels an arm needs to reach this share of the oracle's success."""
ROUNDS = {EXPLORATION: ("rounds",)}
"""Exploration by the share of rounds done, as the oracle explores (the first exploration's control)."""
OWN = {"training.agent_draws": ("own",)}
"""Each agent draws from its own generators (the control's finding: a shared draw made one arm's agent
another draw of the same learner)."""
OUTCOMES = '"outcomes+disagreement"'
"""Half of a round's chosen queries on episode ends, half by the views' disagreement (a TOML string)."""
REFIT_ON = {REFIT: ("true",)}
"""Each classifier learns the labels alone again when a class first shows
(``cotraining.refit_new_classes``)."""
ENDS_ON = {ENDS: ("true",)}
"""On the grid, a reward class labelled only on keys that ended their episode (grid16's goal) is given
to such keys alone (``env.episode_end_classes``)."""


def spend(strategy: str, schedule: str = "even", *labels: str) -> dict[str, tuple[str, ...]]:
    """A grid that buys ``labels`` labels (100 unless given) chosen by ``strategy``, spent on
    ``schedule``."""
    return {BUDGET: labels or ("100",), STRATEGY: (strategy,), SCHEDULE: (schedule,)}


def budget_sweep(name: str, preset: str, grid: dict[str, tuple[str, ...]]) -> Sweep:
    """Sweep ``name`` of ``preset`` over ``grid`` as the label-budget studies run every arm since the
    second exploration: exploring by rounds, each agent's own draws, numerics 2."""
    return Sweep(name, (preset,), {**grid, **ROUNDS, **OWN}, numerics=2)


def _success(runs: list[TrialRun]) -> SeedSummary:
    return SeedSummary.of([r.summary["mean"]["success"] for r in runs])


def _arm_table(arms: dict[str, list[TrialRun]]) -> list[str]:
    """One row per arm and budget: success, pseudo-reward accuracy and the labels each run bought."""
    lines = [
        f"| arm | label budget | {LABELS_COLUMN} | success | pseudo-reward accuracy | seeds |",
        "|---|---|---|---|---|---|",
    ]
    for arm, members in arms.items():
        for budget, cell in _by_budget(members).items():
            accuracy = SeedSummary.of([r.summary["mean"]["pseudo_accuracy"] for r in cell])
            lines.append(
                f"| {arm} | {budget} | {labels_cell(cell)} | {_success(cell)} | {accuracy} | {len(cell)} |"
            )
    return lines


def _by_budget(members: list[TrialRun]) -> dict[str, list[TrialRun]]:
    """An arm's runs by label budget (or, for a uniform mask, its label fraction), smallest first."""
    cells: dict[str, list[TrialRun]] = {}
    for run in members:
        params = run.trial.params
        key = params.get(BUDGET) or (f"share {params[FRACTION]}" if FRACTION in params else "preset")
        cells.setdefault(key, []).append(run)
    return dict(sorted(cells.items(), key=lambda item: (item[0].startswith("share"), _number(item[0]))))


def _number(text: str) -> float:
    try:
        return float(text.split()[-1])
    except ValueError:
        return float("inf")


def _round_success(run: TrialRun) -> dict[int, float]:
    """A run's success after each round, mean over its agents."""
    by_round: dict[int, list[float]] = {}
    with (run.run_dir / METRICS_FILE).open(newline="") as handle:
        for row in csv.DictReader(handle):
            by_round.setdefault(int(row["round"]), []).append(float(row["success"]))
    return {r: float(np.mean(values)) for r, values in by_round.items()}


def _rounds_table(arms: dict[str, list[TrialRun]]) -> list[str]:
    """Mean success after each round, per arm and budget, beside the oracle's: where co-trained agents
    trail it from the first rounds, they had fewer rounds with a reward to learn from."""
    curves = {
        (arm, budget): [_round_success(r) for r in cell]
        for arm, members in arms.items()
        for budget, cell in _by_budget(members).items()
    }
    rounds = sorted({r for runs in curves.values() for curve in runs for r in curve})
    lines = [
        "| arm | label budget | " + " | ".join(f"round {r}" for r in rounds) + " |",
        "|---|---|" + "---|" * len(rounds),
    ]
    for (arm, budget), runs in curves.items():
        cells = [
            f"{np.mean([c[r] for c in runs if r in c]):.2f}" if any(r in c for c in runs) else ""
            for r in rounds
        ]
        lines.append(f"| {arm} | {budget} | " + " | ".join(cells) + " |")
    return lines


def _last_round(run: TrialRun) -> list[dict[str, str]] | None:
    """The rows of the run's ``pseudo_rewards.csv`` for its last round (None without the file)."""
    path = run.run_dir / PSEUDO_REWARDS_FILE
    if not path.is_file():
        return None
    with path.open(newline="") as handle:
        table = list(csv.DictReader(handle))
    last = max(int(row["round"]) for row in table)
    return [row for row in table if int(row["round"]) == last]


def _by_class(tables: list[list[dict[str, str]]]) -> dict[str, list[dict[str, str]]]:
    """Rows of several runs' last rounds by hidden reward class, keyed by the reward in words: "never
    labelled" for a class no label showed the run (class -1), first. A class is its reward where the
    runs' rewards are one small set (grid16's step cost, goal and lava, in whatever order each run met
    them); where each run's differ (MiniGrid's goal pays by the step count), its index, with the
    rewards' range."""
    if not tables:
        return {}
    shown = [row for rows in tables for row in rows if row["class"] != "-1"]
    by_reward = len({row["reward"] for row in shown}) <= max(map(len, tables))
    groups: dict[str, list[dict[str, str]]] = {}
    order: dict[str, float] = {}
    for row in (row for rows in tables for row in rows):
        if row["class"] == "-1":
            key, rank = "never labelled", -np.inf
        elif by_reward:
            key, rank = f"{float(row['reward']):g}", float(row["reward"])
        else:
            key, rank = row["class"], float(row["class"])
        groups.setdefault(key, []).append(row)
        order[key] = rank
    words = {}
    for key in sorted(groups, key=order.__getitem__):
        if by_reward or key == "never labelled":
            words[key] = groups[key]
        else:
            low, high = min(r := [float(row["reward"]) for row in groups[key]]), max(r)
            words[f"{low:g}" if low == high else f"{low:g} to {high:g}"] = groups[key]
    return words


def _class_table(arms: dict[str, list[TrialRun]]) -> list[str]:
    """The last round's pseudo-rewards per hidden reward class, mean over the runs of each arm and
    budget: recall (the share of a class's unlabelled samples given it) and precision (the share of
    those given it that hold it). Low recall with high precision: rewards missing, not wrong."""
    lines = [
        "| arm | label budget | reward | samples | labelled | recall | precision | runs |",
        "|---|---|---|---|---|---|---|---|",
    ]
    cells = (
        (arm, budget, cell) for arm, members in arms.items() for budget, cell in _by_budget(members).items()
    )
    for arm, budget, cell in cells:
        tables = [rows for run in cell if (rows := _last_round(run)) is not None]
        for reward, members_rows in _by_class(tables).items():
            mean = {
                key: SeedSummary.of([float(row[key]) for row in members_rows]).mean
                for key in ("samples", "labelled", "recall", "precision")
            }
            share = {
                key: "n/a" if np.isnan(mean[key]) else f"{mean[key]:.3f}" for key in ("recall", "precision")
            }
            lines.append(
                f"| {arm} | {budget} | {reward} | {mean['samples']:.0f} | {mean['labelled']:.0f} | "
                f"{share['recall']} | {share['precision']} | {len(members_rows)} |"
            )
    return lines if len(lines) > 2 else []


def labels_to_reach(points: list[tuple[float, float]], target: float) -> float | None:
    """The labels at which success first reaches ``target``, linearly interpolated between the
    (labels, success) points sorted by labels; None where no point reaches it."""
    x, y = np.array(sorted(points), dtype=float).T
    reached = float(first_reach(x[None], y[None], target)[0])
    return None if math.isinf(reached) else reached


def _efficiency(arms: dict[str, list[TrialRun]]) -> list[str]:
    """Labels to reach 90% of the oracle's success, per arm with a budget, from its mean success
    against its mean labels used at each budget."""
    oracle = arms.get("oracle")
    if not oracle or len(arms) == 1:
        return []
    target = ORACLE_SHARE * _success(oracle).mean
    lines = [
        f"Labels to reach {ORACLE_SHARE:.0%} of the oracle's success ({target:.3f}), interpolated between "
        "each arm's budgets:",
        "",
        "| arm | budgets | labels to reach it |",
        "|---|---|---|",
    ]
    for arm, members in arms.items():
        if arm == "oracle":
            continue
        cells = _by_budget(members)
        points = [(np.mean([labels_used(r) for r in c]), _success(c).mean) for c in cells.values()]
        reached = labels_to_reach(points, target)
        where = "not reached" if reached is None else f"{reached:.0f}"
        lines.append(f"| {arm} | {', '.join(cells)} | {where} |")
    return lines


def figure(tasks: dict[str, Callable[[TrialRun], bool]]) -> Callable[[list[TrialRun], Path], None]:
    """The figure of a study over ``tasks`` (title, whether a run belongs to it): one panel per task,
    success against labels used per arm (mean over seeds with its 95% interval), and the oracle's
    success as a flat line across the panel."""

    def draw(runs: list[TrialRun], path: Path) -> None:
        panels = {}
        for task, belongs in tasks.items():
            arms = by_arm([r for r in runs if belongs(r)])
            names = short_names(arms)[1] if arms else {}
            bands = _arm_bands({names[arm]: members for arm, members in arms.items()})
            if bands:
                panels[task] = bands
        if panels:
            plot_bands(panels, "labels used per run", "success", path, markers=True, legend_below=True)

    return draw


def _arm_bands(arms: dict[str, list[TrialRun]]) -> list[Band]:
    bands = []
    for arm, members in arms.items():
        if arm == "oracle":
            continue
        cells = list(_by_budget(members).values())
        x = np.array([np.mean([labels_used(r) for r in c]) for c in cells])
        stats = [_success(c) for c in cells]
        order = np.argsort(x)
        bands.append(_band(arm, x[order], [stats[i] for i in order]))
    if "oracle" in arms and bands:
        stat = _success(arms["oracle"])
        x = np.array([min(b.x.min() for b in bands), max(b.x.max() for b in bands)])
        bands.append(_band("oracle (every reward)", x, [stat, stat]))
    return bands


def _band(label: str, x: np.ndarray, stats: list[SeedSummary]) -> Band:
    return Band(
        label,
        np.asarray(x, dtype=float),
        np.array([s.mean for s in stats]),
        np.array([s.low for s in stats]),
        np.array([s.high for s in stats]),
    )


EXPLORATORY = (
    "settings chosen here are confirmed on other seeds, maps and tasks by a study registered before its "
    "runs. An arm names its method, label strategy, schedule and what else its sweep sets; labels used "
    "counts the labels each run held at its end (bought answers, or a uniform mask's share of the samples "
    "met), so equal budgets read as equal counts."
)


def exploration_tables(
    tasks: dict[str, Callable[[TrialRun], bool]],
    study: str,
    seeds: str,
    comparisons: tuple[tuple[str, str, str], ...],
) -> Callable[[list[TrialRun]], list[str]]:
    """The tables of exploratory study ``study`` (its figure ``<study>.png``), per task: ``seeds`` says
    which seeds it ran, ``comparisons`` those it reads (arm a, arm b, what a minus b asks; see
    :func:`descriptive`)."""

    def tables(runs: list[TrialRun]) -> list[str]:
        lines = [f"Exploratory: {seeds}, {EXPLORATORY}"]
        if set(by_arm(runs)) - {"oracle"}:  # the figure draws the other arms against the oracle's line
            lines += ["", f"![success against labels used, per arm, and the oracle's]({study}.png)"]
        for task, belongs in tasks.items():
            arms = by_arm([r for r in runs if belongs(r)])
            if arms:
                compared = descriptive(arms, comparisons)
                lines += task_tables(task, arms, ["Descriptive, exploratory comparisons:", "", *compared])
        return lines

    return tables


def exploration(
    study: str,
    sweeps: tuple[Sweep, ...],
    tasks: dict[str, Callable[[TrialRun], bool]],
    seeds_line: str,
    comparisons: tuple[tuple[str, str, str], ...],
    title: str,
    task: str,
    glance: Callable[[list[TrialRun]], Glance],
    seeds: int = 10,
) -> tuple[str, Study]:
    """Exploratory study ``study`` of the label budgets, with its name (a registry's entry): its
    ``sweeps`` on ``seeds`` seeds, a table per task of ``tasks`` reading ``comparisons``
    (:func:`exploration_tables`, ``seeds_line`` saying which seeds ran) and a figure with a panel each
    (:func:`figure`)."""
    tables = exploration_tables(tasks, study, seeds_line, comparisons)
    return study, Study(sweeps, tables, title, task, glance, seeds=seeds, figure=figure(tasks))


def task_tables(task: str, arms: dict[str, list[TrialRun]], read: list[str]) -> list[str]:
    """One task's tables of a label-budget study: the settings its arms share, its arms (by their short
    names, :func:`short_names`), any control against the oracle, success after each round,
    pseudo-rewards per hidden reward class, then ``read`` (the study's comparisons on the task, left
    out with its heading where it holds nothing past it), label efficiency and the settings of each
    arm shown by a letter."""
    shared, names, used = short_names(arms)
    shown = {names[arm]: members for arm, members in arms.items()}
    lines = ["", f"### {task}", ""]
    if shared:
        lines += [f"Every arm but the oracle: {', '.join(shared)}.", ""]
    if used:
        lines += ["Arm names: " + "; ".join(f"{short} = {word}" for short, word in used.items()) + ".", ""]
    lines += [*_arm_table(shown), *(["", *c] if (c := _controls(arms)) else [])]
    lines += ["", "Success after each round:", "", *_rounds_table(shown)]
    classes = _class_table(shown)
    if classes:
        lines += ["", "Pseudo-rewards per hidden reward class, last round:", "", *classes]
    if any(line.startswith("- ") for line in read):
        lines += ["", *read]
    efficiency = _efficiency(shown)
    lines += ["", *efficiency] if efficiency else []
    lettered = [(names[arm], arm) for arm in arms if names[arm] != arm and names[arm].startswith("arm ")]
    if lettered:
        lines += [
            "",
            "| arm | its settings |",
            "|---|---|",
            *(f"| {name} | {arm} |" for name, arm in lettered),
        ]
    return lines


def _view_success(run: TrialRun, view: str | None) -> float:
    return (run.summary["per_view"][view] if view else run.summary["mean"])["success"]


def _pair(run: TrialRun) -> tuple[str, int]:
    return run.trial.params.get(LAYOUT, ""), run.trial.seed


def paired_values(first: list[TrialRun], second: list[TrialRun], view: str | None = None) -> list[float]:
    """Success of ``first`` minus ``second``, paired by seed and, on the grid, layout (the pairs both
    ran): the runs' mean over their agents, or (``view``) the agent of that view in ``first``."""
    a = {_pair(r): _view_success(r, view) for r in first}
    b = {_pair(r): r.summary["mean"]["success"] for r in second}
    return [a[key] - b[key] for key in sorted(set(a) & set(b))]


def paired_difference(first: list[TrialRun], second: list[TrialRun], view: str | None = None) -> SeedSummary:
    """:func:`paired_values` summarised: its mean and 95% bootstrap interval."""
    return SeedSummary.of(paired_values(first, second, view))


def _controls(arms: dict[str, list[TrialRun]]) -> list[str]:
    """Each control arm (every reward labelled) against the oracle, paired by seed, over its agents and
    for its agent of the oracle's view: an interval that excludes 0 is success the co-training
    machinery costs whatever the labels."""
    oracle = arms.get("oracle")
    lines = []
    for arm, members in arms.items():
        if not oracle or "every reward labelled" not in arm:
            continue
        view = oracle[0].summary["views"][0]
        for who, diff in (
            ("mean over its agents", paired_difference(members, oracle)),
            (f"its {view} agent", paired_difference(members, oracle, view)),
        ):
            verdict = "holds 0" if diff.low <= 0 <= diff.high else "excludes 0"
            lines.append(
                f"- Control: {arm} ({who}) minus the oracle, success, paired by seed: {diff} ({verdict})."
            )
    return lines


def descriptive(arms: dict[str, list[TrialRun]], comparisons: tuple[tuple[str, str, str], ...]) -> list[str]:
    """Each comparison (arm a, arm b, what a minus b asks) whose arms both ran: success of a minus b,
    paired by seed over the seeds both ran, with no threshold and no verdict."""
    lines = []
    for a, b, question in comparisons:
        if a in arms and b in arms:
            diff = paired_difference(arms[a], arms[b])
            if diff.n:
                lines.append(f"- {question}: success of {a} minus {b}, paired: {diff} over {diff.n} seeds.")
    return lines
