"""The seed paper's future work as studies: on grid16-dospcot and fasthighway-dospcot, expert
demonstrations against per-step labels, and per-step labels, segment sums and demonstrations at equal
rater effort (its 6.1 and 6.2); on MiniGrid DoorKey-5x5, a third view against two at equal labels
(its 6.3). Each arm is a set of overrides of the preset, one sweep each."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.tables import (
    COLUMNS,
    FRACTION,
    LABELS_COLUMN,
    LABELS_EXPLAINED,
    labels_cell,
    over_seeds,
    paired,
    verdict,
)

# A first comparison of label sources: expert demonstrations with 1% per-step labels against 5% per-step
# labels, on grid16-dospcot, seeds 0-9. Each arm is a set of overrides of the preset, one sweep each.
DEMOS, MARGIN_WEIGHT, DEMO_LABELS = (
    "demonstrations.episodes",
    "demonstrations.margin_loss_weight",
    "demonstrations.labels",
)
DEMO_ARMS: dict[str, dict[str, str]] = {  # the target's two arms first: a partial sweep has them
    "labels 5%": {FRACTION: "0.05"},
    "labels 1% + 10 demonstrations": {FRACTION: "0.01", DEMOS: "10"},
    "labels 1%": {FRACTION: "0.01"},
    "demonstrations as labels only": {FRACTION: "0.01", DEMOS: "10", MARGIN_WEIGHT: "0"},
    "demonstrations as margin only": {FRACTION: "0.01", DEMOS: "10", DEMO_LABELS: "false"},
}
DEMO_COLUMNS = ("success", "agreement", "pseudo_accuracy", "worst_class_precision")
DEMO_TARGET = ("labels 1% + 10 demonstrations", "labels 5%")
"""The target on grid16: the first arm's success at least the second's."""


def _by_arm(runs: list[TrialRun], arms: dict[str, dict[str, str]]) -> dict[str, dict[int, TrialRun]]:
    """The runs of each arm (its overrides of the preset), by seed; every run belongs to one."""
    by_arm: dict[str, dict[int, TrialRun]] = {}
    for run in runs:
        params = {k: v for k, v in run.trial.params.items() if k != "seed"}
        arm = next(name for name, keys in arms.items() if keys == params)
        by_arm.setdefault(arm, {})[run.trial.seed] = run
    return by_arm


def _arm_sweeps(
    prefix: str, arms: dict[str, dict[str, str]], sweep_names: dict[str, str], preset: str = "grid16-dospcot"
) -> tuple[Sweep, ...]:
    """One sweep of ``preset`` per arm, named after it but where ``sweep_names`` names it: an arm that
    another study's sweep already holds (the same trials: they run once), or one the record holds under
    the arm's longer earlier name. They train under numerics 2, as their pre-registration fixes
    (docs/preregistration-future-work.md)."""
    return tuple(
        Sweep(
            sweep_names.get(arm) or prefix + re.sub(r"[^a-z0-9]+", "-", arm.lower()).strip("-"),
            (preset,),
            {key: (value,) for key, value in keys.items()},
            numerics=2,
        )
        for arm, keys in arms.items()
    )


def _arm_rows(
    by_arm: dict[str, dict[int, TrialRun]],
    arms: Sequence[str],
    columns: Sequence[str],
    names: dict[str, str],
    labels: bool = False,
) -> list[str]:
    """A table's header and one row per arm that ran: its seeds, then ``columns`` over seeds, then
    (``labels``) the labels each run used."""
    titles = [names[c] for c in columns] + ([LABELS_COLUMN] if labels else [])
    lines = ["| arm | seeds | " + " | ".join(titles) + " |", "|---|---|" + "---|" * len(titles)]
    for arm in arms:
        if arm in by_arm:
            members = list(by_arm[arm].values())
            cells_ = [over_seeds(members, c) for c in columns] + ([labels_cell(members)] if labels else [])
            lines.append(f"| {arm} | {len(by_arm[arm])} | " + " | ".join(cells_) + " |")
    return lines


def demonstration_tables(runs: list[TrialRun]) -> list[str]:
    """One row per arm over seeds, then the target's paired difference in success."""
    by_arm = _by_arm(runs, DEMO_ARMS)
    lines = [
        "Every arm is `grid16-dospcot` with the overrides named; demonstrations are value iteration's "
        "optimal episodes, the first from the map's start (docs/demonstrations.md). The last two arms are "
        "labels 1% + 10 demonstrations with the demonstrations used one way only: as labels with no "
        "margin loss, or in the margin loss and not as labels.",
        LABELS_EXPLAINED,
        "",
        *_arm_rows(by_arm, DEMO_ARMS, DEMO_COLUMNS, COLUMNS, labels=True),
    ]
    ours, theirs = DEMO_TARGET
    if ours in by_arm and theirs in by_arm:
        diff = paired(by_arm[ours], by_arm[theirs], "success")
        lines += ["", f"- success, {ours} minus {theirs} (paired by seed): {diff}; {f1_grade(diff)}"]
    return lines


def f1_grade(diff: SeedSummary) -> str:
    """F1's grade (docs/preregistration-future-work.md) of the demonstrations arm's success minus 5%
    labels': **met** where the mean is at least 0; demonstrations *pay* only where the interval lies
    above 0."""
    met = "**met**" if diff.mean >= 0 else "**not met**"
    pay = "yes" if diff.low > 0 else "no"
    return f"F1, target (at least 0): {met}; demonstrations pay (the interval above 0): {pay}"


# Label sources at equal rater effort, counted in labelled env steps (docs/segments.md): per-step
# labels, segment sums (k = 4 and 8) and demonstrations, on grid16-dospcot, seeds 0-9.
SEGMENT = "training.segment_length"
EQUAL_EFFORT_FRACTION = "0.0006"
"""The segments' label fraction at the per-step arm's effort. A grid run's per-step labels reveal 5% of
the 1,024 (s, a) keys, each labelled once for every visit: at most 51 labelled steps. Its agents take
80,000 steps, so segments labelled with probability 0.0006 hold about 48 labelled steps, whatever k.
The table shows the effort each arm measured."""
EFFORT_ARMS: dict[str, dict[str, str]] = {  # the target's arms first: a partial study has them
    "per-step labels, 5% of keys": {FRACTION: "0.05"},
    "segments of 4, equal effort": {FRACTION: EQUAL_EFFORT_FRACTION, SEGMENT: "4"},
    "segments of 8, equal effort": {FRACTION: EQUAL_EFFORT_FRACTION, SEGMENT: "8"},
    "labels 1% + 10 demonstrations": {FRACTION: "0.01", DEMOS: "10"},
    "segments of 4, 5% of segments": {FRACTION: "0.05", SEGMENT: "4"},
}
EFFORT_SHARED = {"labels 1% + 10 demonstrations": "demonstrations-labels-1-10-demonstrations"}
DEMO_SHARED = {
    "labels 5%": "effort-per-step-labels-5-of-keys",
    "demonstrations as labels only": "demonstrations-labels-1-10-demonstrations-as-labels-only",
    "demonstrations as margin only": "demonstrations-labels-1-10-demonstrations-margin-loss-only",
}
"""The two studies' arms with the same overrides of the same preset train once, in one sweep; two
arms' sweeps keep their earlier, longer names."""
EFFORT_COLUMNS = ("labelled_steps", "success", "agreement", "pseudo_accuracy")
NO_WORSE = 0.1
"""F2's margin (docs/preregistration-future-work.md): segments at equal effort are "no worse" than
per-step labels where their paired interval in success starts at -0.1 or above."""


@dataclass(frozen=True)
class EffortTarget:
    """A pre-registered target of a label-source study: ``metric`` of ``arm`` minus the per-step arm,
    paired by seed, **met** where its interval lies above 0, **no worse** where its lower end is at
    least ``-no_worse`` (None: no such grade), else **not met**."""

    name: str
    arm: str
    metric: str
    no_worse: float | None = None

    def grade(self, diff: SeedSummary) -> str:
        """The target's grade of ``diff``, the arm minus the per-step arm, e.g. "F2: **met** (...)"."""
        if diff.n == 0:
            return f"{self.name}: not run"
        if diff.low > 0:
            return f"{self.name}: **met** (segments pay per unit of effort)"
        if self.no_worse is not None and diff.low >= -self.no_worse:
            return f"{self.name}: **no worse** (the interval's lower end is at least -{self.no_worse})"
        return f"{self.name}: **not met**"


EFFORT_TARGETS = tuple(
    EffortTarget("F2", arm, "success", NO_WORSE)
    for arm in ("segments of 4, equal effort", "segments of 8, equal effort")
)


def effort_tables(
    runs: list[TrialRun],
    arms: dict[str, dict[str, str]] = EFFORT_ARMS,
    columns: tuple[str, ...] = EFFORT_COLUMNS,
    preset: str = "grid16-dospcot",
    targets: tuple[EffortTarget, ...] = EFFORT_TARGETS,
) -> list[str]:
    """One row per arm over seeds (effort first), then each arm's paired differences from the first
    arm (per-step labels) in the outcome columns (return, where shown, and success), each graded
    where ``targets`` pre-registered it; the preset's oracle, where the study ran it, as a last row."""
    base = next(iter(arms))
    by_arm = _by_arm([run for run in runs if run.trial.config == preset], arms)
    oracle = [run for run in runs if run.trial.config != preset]
    names = {**COLUMNS, "labelled_steps": "labelled steps (effort)", "greedy_return": "return"}
    if preset.startswith("fasthighway"):
        names["success"] = "no-crash episodes"
    lines = [
        f"Every arm is `{preset}` with the overrides named. Effort is the labelled env steps a "
        "rater watched: labelled samples under per-step labels ((s, a) keys on the grid, steps on "
        "highway), the summed length of the labelled segments under segment labels, and the "
        "demonstrations' steps on top of their arm's labels (docs/segments.md). Under segment labels "
        "the pseudo-reward accuracy is that of the segments' sums (their quantile classes), not of "
        "single steps.",
        "",
        *_arm_rows(by_arm, arms, columns, names),
    ]
    if oracle:
        cells_ = [over_seeds(oracle, c) if c != "labelled_steps" else "every step" for c in columns]
        lines.append(f"| oracle (`{oracle[0].trial.config}`) | {len(oracle)} | " + " | ".join(cells_) + " |")
    lines += [
        "",
        "n/a: not recorded before the effort column existed, or undefined (an oracle has no pseudo-rewards).",
    ]
    if base in by_arm:
        lines.append("")
        outcomes = [c for c in ("greedy_return", "success") if c in columns]
        for arm in arms:
            if arm != base and arm in by_arm:
                for column in outcomes:
                    diff = paired(by_arm[arm], by_arm[base], column)
                    grades = [t.grade(diff) for t in targets if (t.arm, t.metric) == (arm, column)]
                    line = f"- {names[column]}, {arm} minus {base} (paired by seed): {diff}"
                    lines.append("; ".join([line, *grades]))
    return lines


# The fast-highway half: labels reveal each step with probability p, so segments at the same p cost
# the same effort. The demonstrator is the study's own oracle run of seed 0 (its kinematics agent).
EXPERT = "runs/sweeps/effort-highway-oracle/trials/fasthighway-oracle/seed=0/agent_kinematics.zip"
EFFORT_HIGHWAY_ARMS: dict[str, dict[str, str]] = {
    "per-step labels, 5% of steps": {FRACTION: "0.05"},
    "segments of 4, 5% of segments": {FRACTION: "0.05", SEGMENT: "4"},
    "segments of 8, 5% of segments": {FRACTION: "0.05", SEGMENT: "8"},
    "labels 1% + 10 demonstrations": {FRACTION: "0.01", DEMOS: "10", "demonstrations.agent": f'"{EXPERT}"'},
}
EFFORT_HIGHWAY_COLUMNS = ("labelled_steps", "greedy_return", "success", "pseudo_accuracy")
F3 = EffortTarget("F3", "segments of 4, 5% of segments", "greedy_return")
"""F3 (docs/preregistration-future-work.md): no "no worse" grade on the highway."""


# A third view beyond grid16 (the seed paper's 6.3; grid16's m = 3 row is the grid16 study's): DoorKey-5x5
# with the full grid's one-hot map added to the image and the egocentric map, every arm buying the
# same 100 answers at random as soon as it meets samples (docs/preregistration-future-work.md).
VIEWS, BUDGET, STRATEGY = "views", "training.label_budget", "training.label_strategy"
THIRD_VIEW_ARMS: dict[str, dict[str, str]] = {
    "m = 2 (image, ego)": {VIEWS: '["image", "ego"]', BUDGET: "100", STRATEGY: "random"},
    "m = 3 (image, ego, full)": {
        VIEWS: '["image", "ego", "full"]',
        BUDGET: "100",
        STRATEGY: "random",
    },
}
THIRD_VIEW_SWEEPS = {
    "m = 2 (image, ego)": "third-view-doorkey-m-2-image-ego-100-labels",
    "m = 3 (image, ego, full)": "third-view-doorkey-m-3-image-ego-full-100-labels",
}
"""The arms' sweeps, named when the arms' names still said their shared 100 labels."""
THIRD_VIEW_COLUMNS = ("success", "pseudo_accuracy")
THIRD_VIEW_PRESET = "minigrid-doorkey-dospcot"


def third_view_tables(runs: list[TrialRun]) -> list[str]:
    """One row per arm over seeds with the labels each run used, then m = 3 minus m = 2 in success,
    paired by seed."""
    by_arm = _by_arm(runs, THIRD_VIEW_ARMS)
    lines = [
        f"Every arm is `{THIRD_VIEW_PRESET}` with the views named, buying 100 labels at random (numerics 2).",
        LABELS_EXPLAINED,
        "",
        *_arm_rows(by_arm, THIRD_VIEW_ARMS, THIRD_VIEW_COLUMNS, COLUMNS, labels=True),
    ]
    two, three = THIRD_VIEW_ARMS
    if two in by_arm and three in by_arm:
        diff = paired(by_arm[three], by_arm[two], "success")
        lines += [
            "",
            f"- success, {three} minus {two} (paired by seed): {diff}; {verdict(diff, 'm = 3', 'm = 2')}",
        ]
    return lines


def arms_glance(
    runs: list[TrialRun],
    arms: dict[str, dict[str, str]],
    ours: str,
    theirs: str,
    metric: str = "success",
    preset: str = "grid16-dospcot",
    grade: Callable[[SeedSummary], str] | None = None,
) -> Glance:
    """``metric`` of arm ``ours`` minus arm ``theirs`` (overrides of ``preset``), paired by seed, with
    its pre-registered ``grade`` where the study has one."""
    by_arm = _by_arm([run for run in runs if run.trial.config == preset], arms)
    diff = paired(by_arm.get(ours, {}), by_arm.get(theirs, {}), metric)
    words = metric.replace("greedy_", "")
    said = verdict(diff, ours, theirs)
    if grade is not None and diff.n:
        said = f"{grade(diff)}; {said}"
    return Glance(f"{words}, {ours} minus {theirs}, paired by seed: {diff}", said)


STUDIES: dict[str, Study] = {
    "demo-labels": Study(
        _arm_sweeps("demonstrations-", DEMO_ARMS, DEMO_SHARED),
        demonstration_tables,
        "Expert demonstrations against per-step labels (grid16)",
        "16 x 16 grid, layout 0: demonstrations or labels",
        partial(arms_glance, arms=DEMO_ARMS, ours=DEMO_TARGET[0], theirs=DEMO_TARGET[1], grade=f1_grade),
        seeds=10,
    ),
    "equal-effort": Study(
        _arm_sweeps("effort-", EFFORT_ARMS, EFFORT_SHARED),
        effort_tables,
        "Label sources at equal effort: per-step labels, segments, demonstrations (grid16)",
        "16 x 16 grid, layout 0: label sources at equal effort",
        partial(
            arms_glance,
            arms=EFFORT_ARMS,
            ours=EFFORT_TARGETS[0].arm,
            theirs=next(iter(EFFORT_ARMS)),
            grade=EFFORT_TARGETS[0].grade,
        ),
        seeds=10,
    ),
    "third-view-doorkey": Study(
        _arm_sweeps("third-view-doorkey-", THIRD_VIEW_ARMS, THIRD_VIEW_SWEEPS, THIRD_VIEW_PRESET),
        third_view_tables,
        "A third view against two at equal labels (MiniGrid DoorKey-5x5)",
        "MiniGrid DoorKey-5x5, 100 labels at random: a third view",
        partial(
            arms_glance,
            arms=THIRD_VIEW_ARMS,
            ours=list(THIRD_VIEW_ARMS)[1],
            theirs=next(iter(THIRD_VIEW_ARMS)),
            preset=THIRD_VIEW_PRESET,
        ),
        seeds=10,
    ),
    "equal-effort-highway": Study(
        (
            # first: it trains the expert
            Sweep("effort-highway-oracle", ("fasthighway-oracle",), {}, numerics=2),
            *_arm_sweeps("effort-highway-", EFFORT_HIGHWAY_ARMS, {}, "fasthighway-dospcot"),
        ),
        partial(
            effort_tables,
            arms=EFFORT_HIGHWAY_ARMS,
            columns=EFFORT_HIGHWAY_COLUMNS,
            preset="fasthighway-dospcot",
            targets=(F3,),
        ),
        "Label sources at equal effort: per-step labels, segments, demonstrations (fast highway)",
        "our fast highway: label sources at equal effort",
        partial(
            arms_glance,
            arms=EFFORT_HIGHWAY_ARMS,
            ours=F3.arm,
            theirs=next(iter(EFFORT_HIGHWAY_ARMS)),
            metric=F3.metric,
            preset="fasthighway-dospcot",
            grade=F3.grade,
        ),
    ),
}
