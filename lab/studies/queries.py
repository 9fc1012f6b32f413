"""The active-queries study (docs/preregistration-queries.md): label strategies at an equal budget on
grid16's unseen layouts, MiniGrid and the fast highway, with the pre-registered hypotheses Q1-Q3."""

from __future__ import annotations

import csv
import json
from collections.abc import Callable

from dospcot.run.run_folder import METRICS_FILE, QUERIES_FILE, REWARD_CLASSES_FILE
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.budget_arms import ABBREVIATIONS
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.grid_studies import LAYOUT, UNSEEN_LAYOUTS
from dospcot_lab.studies.tables import FRACTION, MINIGRID_TASKS, labels_cell, over_seeds

STRATEGY = "training.label_strategy"
SELF_TRAINING = ("uniform", "random", "uncertainty")
DOSPCOT = ("uniform", "random", "uncertainty", "outcomes", "disagreement")
Q3_STRATEGY = "outcomes"
"""The strategy the MiniGrid target (Q3) is judged on, named in the pre-registration."""
COLUMNS = ("success", "pseudo_accuracy", "worst_class_precision", "labelled_steps")


def _arms(prefix: str, fraction: str, extra: dict[str, tuple[str, ...]], name: str) -> tuple[Sweep, ...]:
    """The study's arms on one task: oracle; self-training and DOSPCoT under their strategies."""
    budget = {**extra, FRACTION: (fraction,)}
    return (
        Sweep(f"{name}-oracle", (f"{prefix}-oracle",), dict(extra)),
        Sweep(f"{name}-self-training", (f"{prefix}-self-training",), {**budget, STRATEGY: SELF_TRAINING}),
        Sweep(f"{name}-dospcot", (f"{prefix}-dospcot",), {**budget, STRATEGY: DOSPCOT}),
    )


def _arm(run: TrialRun) -> str:
    """A run's arm: its method and, but for the oracle, its strategy and label fraction."""
    config = run.trial.config
    method = "self-training" if config.endswith("-self-training") else config.rsplit("-", 1)[-1]
    if method == "oracle":
        return "oracle"
    strategy = run.trial.params.get(STRATEGY, "uniform")
    return f"{method} {strategy} @ {run.trial.params.get(FRACTION, '')}"


def _shown(arm: str) -> str:
    """An arm's name in a table, self-training said as ST so that every name fits in 30 characters."""
    return arm.replace("self-training", ABBREVIATIONS["self-training"])


def _pairs(runs: list[TrialRun], arm: str) -> dict[tuple[str, int], TrialRun]:
    """The runs of one arm by (layout, seed): the pairs of a paired comparison."""
    return {(r.trial.params.get(LAYOUT, ""), r.trial.seed): r for r in runs if _arm(r) == arm}


def _difference(runs: list[TrialRun], a: str, b: str, metric: str) -> SeedSummary:
    """``metric`` of arm a minus arm b, paired by layout and seed."""
    first, second = _pairs(runs, a), _pairs(runs, b)
    both = sorted(set(first) & set(second))
    return SeedSummary.of(
        [first[k].summary["mean"][metric] - second[k].summary["mean"][metric] for k in both]
    )


def _arm_table(runs: list[TrialRun], task: str) -> list[str]:
    """One row per arm. On MiniGrid, whose only reward is the goal's, also how many seeds' labels hold
    a goal step: a co-trained agent cannot learn a reward class that no label shows it."""
    goal = task.startswith("MiniGrid")
    columns = [*COLUMNS, *(["goal labelled"] if goal else [])]
    lines = [f"| {task} | " + " | ".join(columns) + " | seeds |", "|---|" + "---|" * (len(columns) + 1)]
    for arm in dict.fromkeys(_arm(r) for r in runs):
        members = [r for r in runs if _arm(r) == arm]
        cells = [over_seeds(members, column) for column in COLUMNS]
        if goal:  # the oracle is told every reward: it has no labels to count
            cells.append("n/a" if arm == "oracle" else f"{sum(map(_goal_labelled, members))}/{len(members)}")
        lines.append(f"| {_shown(arm)} | {' | '.join(cells)} | {len(members)} |")
    return lines


DESCRIPTIVE = (
    ("dospcot outcomes", "dospcot uniform", "labels placed on episode ends against the blind mask"),
    ("dospcot disagreement", "dospcot random", "co-testing against random queries on its schedule"),
    ("dospcot uniform", "self-training uniform", "the second view under the paper's mask"),
)
"""Comparisons the pre-registration does not name (arm a, arm b, what a minus b asks), reported with
no threshold and no verdict."""


def _study_fraction(runs: list[TrialRun]) -> str:
    """The task's label fraction of the study's equal budget: the first arm's (the sweeps run an arm at
    it first on every task; Q1's reference at 0.05 comes after)."""
    return next((r.trial.params[FRACTION] for r in runs if FRACTION in r.trial.params), "")


def _descriptive(runs: list[TrialRun], task: str) -> list[str]:
    """The :data:`DESCRIPTIVE` differences in success at the task's study fraction, over the pairs both
    arms have run so far."""
    fraction = _study_fraction(runs)
    lines = []
    for a, b, question in DESCRIPTIVE:
        diff = _difference(runs, f"{a} @ {fraction}", f"{b} @ {fraction}", "success")
        if diff.n:
            lines.append(
                f"- Descriptive, not registered ({task}): success of {a} minus {b} ({question}), "
                f"paired: {diff} over {diff.n} pairs."
            )
    return lines


def _chosen_table(runs: list[TrialRun], task: str) -> list[str]:
    """Who chose each active arm's queries, from its runs' ``queries.csv``: the queries per run, the
    share asked after round 1 (the first round with a fitted classifier) and the share the arm's
    strategy chose itself rather than at random (its random share, or no classifier yet)."""
    lines = [
        f"| {task}: queries | per run | after round 1 | chosen by the strategy | runs |",
        "|---|---|---|---|---|",
    ]
    for arm in dict.fromkeys(_arm(r) for r in runs):
        members = [r for r in runs if _arm(r) == arm]
        strategy = members[0].trial.params.get(STRATEGY, "uniform")
        if strategy == "uniform":
            continue  # a fixed mask (or the oracle): nothing was asked
        rows = []
        for run in members:
            with (run.run_dir / QUERIES_FILE).open(newline="") as handle:
                rows += list(csv.DictReader(handle))
        later = sum(int(row["round"]) > 1 for row in rows) / max(len(rows), 1)
        chosen = sum(row["strategy"] == strategy for row in rows) / max(len(rows), 1)
        per_run = len(rows) / len(members)
        lines.append(f"| {_shown(arm)} | {per_run:.1f} | {later:.1%} | {chosen:.1%} | {len(members)} |")
    return lines if len(lines) > 2 else []


def _verdict(held: bool | None, pairs: int = 0, of: int = 0) -> str:
    """A hypothesis's verdict; none until both arms have run every pair (``pairs`` of ``of`` so far)."""
    if held is None:
        return f"not decided yet ({pairs} of {of} pairs run)" if pairs else "not yet run"
    return "**held**" if held else "**not met**"


def _pair_counts(runs: list[TrialRun], a: str, b: str) -> tuple[int, int]:
    """The pairs both arms have run, and the pairs either has: a verdict waits until they agree."""
    first, second = set(_pairs(runs, a)), set(_pairs(runs, b))
    return len(first & second), len(first | second)


def _q1_q2(runs: list[TrialRun], task: str, q1: bool) -> list[str]:
    lines = []
    disagreement, uncertainty = "dospcot disagreement @ {f}", "self-training uncertainty @ {f}"
    fraction = _study_fraction(runs)
    if q1:
        a, b = disagreement.format(f="0.02"), "dospcot uniform @ 0.05"
        diff, (pairs, of) = _difference(runs, a, b, "success"), _pair_counts(runs, a, b)
        held = None if diff.n == 0 or pairs < of else diff.low >= -0.05
        lines.append(
            f"- Q1 ({task}): success of DOSPCoT disagreement at 2% minus DOSPCoT uniform at 5%, paired: "
            f"{diff} over {diff.n} pairs; lower bound >= -0.05: {_verdict(held, pairs, of)}."
        )
    for metric in ("success", "pseudo_accuracy"):
        a, b = disagreement.format(f=fraction), uncertainty.format(f=fraction)
        diff, (pairs, of) = _difference(runs, a, b, metric), _pair_counts(runs, a, b)
        held = None if diff.n == 0 or pairs < of else diff.low > 0
        lines.append(
            f"- Q2 ({task}, {metric}): DOSPCoT disagreement minus self-training uncertainty, paired: {diff} "
            f"over {diff.n} pairs; interval above 0: {_verdict(held, pairs, of)}."
        )
    return lines


def _goal_labelled(run: TrialRun) -> bool:
    """Whether the run's labels hold a goal step: a positive reward class (MiniGrid pays only there)."""
    return any(r > 0 for r in json.loads((run.run_dir / REWARD_CLASSES_FILE).read_text())["rewards"])


def _q3(runs: list[TrialRun], task: str) -> str:
    oracle = [r.summary["mean"]["success"] for r in runs if _arm(r) == "oracle"]
    judged = [r for r in runs if _arm(r) == f"dospcot {Q3_STRATEGY} @ 0.1"]
    pairs, of = _pair_counts(runs, "oracle", f"dospcot {Q3_STRATEGY} @ 0.1")
    if not oracle or not judged or pairs < of:
        return f"- Q3 ({task}): {_verdict(None, pairs if oracle and judged else 0, of)}."
    success = SeedSummary.of([r.summary["mean"]["success"] for r in judged]).mean
    share = success / max(sum(oracle) / len(oracle), 1e-12)
    goal = sum(_goal_labelled(r) for r in judged)
    held = share >= 0.9 and goal == len(judged)
    return (
        f"- Q3 ({task}): DOSPCoT {Q3_STRATEGY} reaches {share:.0%} of the oracle's success; {goal} of its "
        f"{len(judged)} seeds' labels hold a goal pair; at least 90% and every seed: {_verdict(held)}."
    )


def _metrics(run: TrialRun) -> bytes:
    return (run.run_dir / METRICS_FILE).read_bytes()


def _identical(runs: list[TrialRun], task: str) -> list[str]:
    """Arms that trained the same runs: pairs whose ``metrics.csv`` match byte for byte (an active
    strategy that found nothing to prefer asks what another asks, and trains the same agents)."""
    arms = list(dict.fromkeys(_arm(r) for r in runs))
    lines = []
    for i, a in enumerate(arms):
        for b in arms[i + 1 :]:
            first, second = _pairs(runs, a), _pairs(runs, b)
            both = set(first) & set(second)
            same = sum(_metrics(first[k]) == _metrics(second[k]) for k in both)
            if same:
                lines.append(
                    f"- Identical runs ({task}): {a} and {b} trained byte-identical runs (metrics.csv) on "
                    f"{same} of their {len(both)} pairs."
                )
    return lines


def _tables(tasks: dict[str, Callable[[TrialRun], bool]], hypotheses: Callable[..., list[str]]) -> Callable:
    def tables(runs: list[TrialRun]) -> list[str]:
        lines = [
            "The arm names the method (ST: self-training, in the tables), its label strategy and its label "
            "fraction (docs/queries.md). "
            "Under each task, who chose the active arms' queries (their runs' queries.csv, pooled): every "
            "strategy draws its random share at random, and uncertainty and disagreement also draw at "
            "random where no classifier has been fitted yet (all of round 1). "
            "On MiniGrid, goal labelled counts the seeds whose labels hold a goal step (a reward class "
            "above 0). Differences are paired by seed (and layout on the grid); the descriptive ones are "
            "not in the pre-registration and carry no verdict.",
        ]
        for task, belongs in tasks.items():
            members = [r for r in runs if belongs(r)]
            if members:
                chosen = _chosen_table(members, task)
                lines += ["", *_arm_table(members, task), *(["", *chosen] if chosen else [])]
                lines += ["", *hypotheses(members, task), *_descriptive(members, task)]
                lines += _identical(members, task)
        return lines

    return tables


def _glance(runs: list[TrialRun]) -> Glance:
    """Q1's comparison: DOSPCoT disagreement at 2% minus DOSPCoT uniform at 5%, success, paired."""
    a, b = "dospcot disagreement @ 0.02", "dospcot uniform @ 0.05"
    diff, (pairs, of) = _difference(runs, a, b, "success"), _pair_counts(runs, a, b)
    held = None if diff.n == 0 or pairs < of else diff.low >= -0.05
    return Glance(
        f"grid16 success, DOSPCoT disagreement at 2% minus uniform at 5%, paired: {diff}",
        f"Q1: {_verdict(held, pairs, of).strip('*')}",
    )


def _labels(runs: list[TrialRun], arm: str) -> str:
    """The labels a run of ``arm`` bought, its runs' mean: at one label fraction, a method with two
    agents meets twice the steps of one with one, and buys twice the labels."""
    return labels_cell([r for r in runs if _arm(r) == arm])


def _highway_glance(runs: list[TrialRun]) -> Glance:
    """DOSPCoT disagreement minus self-training uncertainty, success, paired, with the labels each bought."""
    a, b = "dospcot disagreement @ 0.02", "self-training uncertainty @ 0.02"
    diff = _difference(runs, a, b, "success")
    return Glance(
        f"success, DOSPCoT disagreement ({_labels(runs, a)} labels a run) minus self-training uncertainty "
        f"({_labels(runs, b)}), paired: {diff}",
        "no hypothesis",
    )


def _minigrid_hypotheses(runs: list[TrialRun], task: str) -> list[str]:
    return [*_q1_q2(runs, task, q1=False), _q3(runs, task)]


def _grid_and_minigrid_hypotheses(runs: list[TrialRun], task: str) -> list[str]:
    if task.startswith("grid16"):
        return _q1_q2(runs, task, q1=True)
    return _minigrid_hypotheses(runs, task)


def _of_config(prefix: str) -> Callable[[TrialRun], bool]:
    return lambda run: run.trial.config.startswith(prefix)


def _minigrid_sweeps(
    method: str, strategies: tuple[str, ...], name: str, tasks: tuple[str, ...] = tuple(MINIGRID_TASKS)
) -> tuple[Sweep, ...]:
    """One sweep per MiniGrid task of ``tasks``: ``method``'s runs under ``strategies`` at label
    fraction 0.1."""
    budget = {FRACTION: ("0.1",), STRATEGY: strategies} if strategies else {}
    return tuple(Sweep(f"queries-{task}-{name}", (f"minigrid-{task}-{method}",), budget) for task in tasks)


# The arms of the hypotheses first, so that a study cut short has its verdicts: on the grid Q1, then
# Q2; on MiniGrid Q3 (DOSPCoT outcomes and the oracle), then Q2. The order changes no run's settings.
HYPOTHESIS_SWEEPS = (
    Sweep(
        "queries-grid16-disagreement",
        ("grid16-dospcot",),
        {LAYOUT: UNSEEN_LAYOUTS, FRACTION: ("0.02",), STRATEGY: ("disagreement",)},
    ),
    Sweep("queries-grid16-reference", ("grid16-dospcot",), {LAYOUT: UNSEEN_LAYOUTS, FRACTION: ("0.05",)}),
    Sweep(
        "queries-grid16-self-training",
        ("grid16-self-training",),
        {LAYOUT: UNSEEN_LAYOUTS, FRACTION: ("0.02",), STRATEGY: ("uncertainty", "uniform", "random")},
    ),
    *_minigrid_sweeps("dospcot", (Q3_STRATEGY,), Q3_STRATEGY),
    *_minigrid_sweeps("oracle", (), "oracle"),
    *_minigrid_sweeps("self-training", ("uncertainty",), "uncertainty"),
    *_minigrid_sweeps("dospcot", ("disagreement",), "disagreement"),
)
# DOSPCoT's other MiniGrid arms on DoorKey first, whose runs take less than half LavaGap's time: a
# study cut short then has them whole on one task and the uniform mask on both sooner.
OTHER_SWEEPS = (
    *_minigrid_sweeps("self-training", ("uniform", "random"), "self-training"),
    *_minigrid_sweeps("dospcot", ("uniform", "random", "uncertainty"), "dospcot", ("doorkey", "lavagap")),
    Sweep(
        "queries-grid16-dospcot",
        ("grid16-dospcot",),
        {
            LAYOUT: UNSEEN_LAYOUTS,
            FRACTION: ("0.02",),
            STRATEGY: ("uniform", "random", "uncertainty", "outcomes"),
        },
    ),
    Sweep("queries-grid16-oracle", ("grid16-oracle",), {LAYOUT: UNSEEN_LAYOUTS}),
)

STUDIES: dict[str, Study] = {
    "queries": Study(
        (*HYPOTHESIS_SWEEPS, *OTHER_SWEEPS),
        _tables(
            {
                "grid16, layouts 101, 202, 303": _of_config("grid16-"),
                **{env_id: _of_config(f"minigrid-{task}-") for task, env_id in MINIGRID_TASKS.items()},
            },
            _grid_and_minigrid_hypotheses,
        ),
        "Active reward queries: label strategies at an equal budget",
        "grid16 (unseen layouts), MiniGrid DoorKey-5x5 and LavaGapS7",
        _glance,
        seeds=10,
        confirmatory=True,
    ),
    "queries-highway": Study(
        _arms("fasthighway", "0.02", {}, "queries-fasthighway"),
        _tables({"fast highway": lambda r: True}, lambda runs, task: []),
        "Active reward queries on the fast highway (no hypothesis)",
        "fast highway",
        _highway_glance,
        seeds=5,
    ),
}
