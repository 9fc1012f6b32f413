"""The views study, confirmatory (docs/preregistration-views.md): does the second view save labels? On
grid16 (layouts no study had used), MiniGrid DoorKey-5x5 and LavaGapS7 and the fast highway, at four
label budgets each, the exploration's arms (:mod:`~dospcot_lab.studies.views`) on seeds 200-209, and
the four hypotheses marked by the rules the preregistration fixed before any run:

- **V1**, the second view saves labels: on a task, DOSPCoT needs at most half the labels of the best
  one-view peer to reach 90% of the oracle, and the 95% interval of that ratio lies below 1; met where
  that holds on at least two of the four tasks.
- **V2**, the view pays, not the second model: on a task, the 95% interval of the twin's labels over
  DOSPCoT's lies above 1; met on at least two of the four tasks.
- **V3**, the views' error dependence predicts the margin: across the tasks, the rank correlation of
  DOSPCoT's error correlation with its margin (the peer's labels over DOSPCoT's) is -0.8 or below;
  not testable where fewer than three tasks have an error correlation or they span less than 0.2.
- **V4** (secondary), the second view lifts the whole curve: on a task, the 95% interval of the area
  under DOSPCoT's curve minus the area under the best one-view peer's (by area) lies above 0; met on at
  least two of the four tasks. It reads a curve that never reaches 90% of the oracle, where V1 cannot.

Labels and success are read on the agent of the one-view arms' view (the primary measure): a second,
weaker view's agent then neither lowers DOSPCoT's curve nor a stronger one lifts it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study
from dospcot_lab.studies.error_dependence import last_round_dependence
from dospcot_lab.studies.grid_studies import LAYOUT
from dospcot_lab.studies.label_curves import SHARE, Curve, area_difference, labels_ratio
from dospcot_lab.studies.step_class import steps_paid
from dospcot_lab.studies.views import (
    ONE_VIEW,
    TASKS,
    arm_of,
    curve_sweeps,
    curves,
    figure,
    of_task,
    tables_linking,
)

FIRST_SEED, SEEDS = 200, 10
LAYOUTS = ("707", "808", "909")
"""grid16 layouts no study had used (the record's: 0, 1, 3, 4, 11, 101, 202, 303, 404, 505, 606)."""
MAPS = {"grid16": {LAYOUT: LAYOUTS}}
BUDGETS: dict[str, tuple[str, ...]] = {
    "doorkey": ("5", "10", "25", "50"),
    "lavagap": ("50", "100", "200", "400"),
    "fasthighway": ("25", "50", "100", "200"),
    "grid16": ("2", "5", "10", "20"),
}
"""Each task's budgets, from where the exploration's arms failed to where they reached the oracle; its
sweeps train in this order, the task that costs least in all first."""
PAIRS = {task: SEEDS * (len(LAYOUTS) if task in MAPS else 1) for task in BUDGETS}
"""The pairs (seed, and layout on the grid) each arm's curve holds once the study has run."""
SAVES, TASKS_NEEDED, RANK, SPAN = 0.5, 2, -0.8, 0.2
"""The preregistration's thresholds: V1's ratio, the tasks V1 and V2 need, V3's rank correlation and
the least span of error correlations V3 can be tested on."""
ANSWERED = ("DOSPCoT", *ONE_VIEW, "blind")
"""The arms whose labels to 90% of the oracle the study answers with, and each of which must have run
every pair before any hypothesis is decided."""


def _on_view(runs: list[TrialRun], task: str) -> dict[str, Curve]:
    return curves(of_task(runs, task), TASKS[task][1])


def _complete(found: dict[str, Curve], task: str) -> bool:
    """Whether every arm on ``task`` has run every pair: DOSPCoT, each one-view peer and the blind
    control, which no hypothesis reads but the preregistration waits for before any verdict (a curve
    holds only the pairs the oracle ran too)."""
    return all(arm in found and len(found[arm].pairs) == PAIRS[task] for arm in ANSWERED)


def _best_peer(found: dict[str, Curve]) -> str:
    """The one-view peer that reaches the oracle's share with the fewest labels (the first, in
    :data:`ONE_VIEW`'s order, of a tie)."""
    return min((arm for arm in ONE_VIEW if arm in found), key=lambda arm: found[arm].labels_to_reach())


def _ratio_text(ratio: tuple[float, float, float]) -> str:
    """``"0.50 [0.25, 0.80]"``; "–" where the arms share no pair."""
    point, low, high = ratio
    return "–" if math.isnan(point) else f"{point:.2f} [{low:.2f}, {high:.2f}]"


def _interval_text(value: tuple[float, float, float]) -> str:
    """``"+0.10 [-0.02, +0.21]"``; "–" where the arms share no pair."""
    point, low, high = value
    return "–" if math.isnan(point) else f"{point:+.2f} [{low:+.2f}, {high:+.2f}]"


def _yes(counts: bool) -> str:
    return "yes" if counts else "no"


def hypotheses(runs: list[TrialRun]) -> tuple[list[str], dict[str, str], list[str]]:
    """The table of each task's ratios, each hypothesis's verdict by its rule ("not decided yet" until
    every arm of every task has run every pair), and the headline's part per task."""
    lines = [
        f"| task | best one-view peer | DOSPCoT's labels to {SHARE:.0%} over the peer's [95% interval] | "
        "V1 counts | the twin's over DOSPCoT's | V2 counts | DOSPCoT's error correlation | best peer by "
        "area | DOSPCoT's area minus its [95% interval] | V4 counts |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    counted, margins, parts, done = {"V1": 0, "V2": 0, "V4": 0}, {}, [], True
    for task in BUDGETS:
        found = _on_view(runs, task)
        done &= _complete(found, task)
        if "DOSPCoT" not in found or not any(arm in found for arm in ONE_VIEW):
            continue
        peer = _best_peer(found)
        saves = labels_ratio(found["DOSPCoT"], found[peer])
        twin = labels_ratio(found["twin"], found["DOSPCoT"]) if "twin" in found else (math.nan,) * 3
        widest = max((arm for arm in ONE_VIEW if arm in found), key=lambda arm: found[arm].area())
        lifts = area_difference(found["DOSPCoT"], found[widest])
        v1, v2, v4 = bool(saves[0] <= SAVES and saves[2] < 1), bool(twin[1] > 1), bool(lifts[1] > 0)
        counted["V1"] += v1
        counted["V2"] += v2
        counted["V4"] += v4
        finite = [
            c
            for c in (
                last_round_dependence(r)["error_correlation"]
                for r in of_task(runs, task)
                if arm_of(r) == "DOSPCoT"
            )
            if not math.isnan(c)
        ]
        dependence = float(np.mean(finite)) if finite else math.nan
        margins[task] = (dependence, 1 / saves[0] if saves[0] else math.inf)
        shown = "–" if math.isnan(dependence) else f"{dependence:.3f}"
        lines.append(
            f"| {task} | {peer} | {_ratio_text(saves)} | {_yes(v1)} | {_ratio_text(twin)} | {_yes(v2)} | "
            f"{shown} | {widest} | {_interval_text(lifts)} | {_yes(v4)} |"
        )
        parts.append(f"{task} {_ratio_text(saves)}")
    verdicts = {
        "V1": _met(counted["V1"] >= TASKS_NEEDED, done),
        "V2": _met(counted["V2"] >= TASKS_NEEDED, done),
        "V3": _v3(margins, done),
        "V4": _met(counted["V4"] >= TASKS_NEEDED, done),
    }
    return lines, verdicts, parts


def _met(held: bool, done: bool) -> str:
    return "not decided yet" if not done else ("met" if held else "not met")


def _v3(margins: dict[str, tuple[float, float]], done: bool) -> str:
    """V3's verdict, and the rank correlation of DOSPCoT's error correlation with its margin across the
    tasks that it read."""
    if not done:
        return "not decided yet"
    known = [(c, m) for c, m in margins.values() if not math.isnan(c)]
    if len(known) < 3 or np.ptp([c for c, _ in known]) < SPAN:
        return "not testable"
    rank = spearmanr(*zip(*known, strict=True)).statistic
    return f"{'met' if rank <= RANK else 'not met'} (rank correlation {rank:+.2f} over {len(known)} tasks)"


ANSWER = "### Labels to 90% of the oracle, per task"
"""The heading of the answer's table, which the README's block copies (:func:`readme_block`)."""
VERDICTS = "Pre-registered verdicts: "
"""The answer's last line starts so; the README's block ends with that line."""


def answer(runs: list[TrialRun], verdicts: dict[str, str]) -> list[str]:
    """Per task, each arm's labels to the oracle's share on the one-view arms' view (its mean curve),
    "not run yet" where the arm has no curve there; then the hypotheses' verdicts."""
    lines = [
        ANSWER,
        "",
        f"Labels each arm needed to reach {SHARE:.0%} of the oracle's success on the agent of the one-view "
        "arms' view, on its mean curve over seeds 200-209 (grid16: three layouts no study had used), "
        '"> N" where its largest budget did not reach it (the blind control trains at the largest '
        "budget alone).",
        "",
        "| task | " + " | ".join(ANSWERED) + " |",
        "|---|" + "---|" * len(ANSWERED),
    ]
    for task in BUDGETS:
        found = _on_view(runs, task)
        cells = [_answer_cell(found.get(arm), task) for arm in ANSWERED]
        lines.append(f"| {task} | " + " | ".join(cells) + " |")
    named = {"V1": "the second view saves labels", "V2": "the view pays, not the second model"}
    marked = "; ".join(f"{name} ({named[name]}): {verdicts[name]}" for name in named)
    return [*lines, "", f"{VERDICTS}{marked}."]


def _answer_cell(curve: Curve | None, task: str) -> str:
    """An arm's labels to the oracle's share, with the pairs its curve holds until it holds them all."""
    if curve is None:
        return "not run yet"
    held = len(curve.pairs)
    return curve.reach_text() + ("" if held >= PAIRS[task] else f" ({held} of {PAIRS[task]} pairs so far)")


def readme_block(table: str) -> str:
    """The README's block: the answer's table and verdicts, as the study's tables state them."""
    section = table.split(ANSWER, 1)[1].split(f"\n{VERDICTS}", 1)
    return section[0].strip("\n") + f"\n\n{VERDICTS}" + section[1].split("\n", 1)[0]


def tables(runs: list[TrialRun]) -> list[str]:
    """The hypotheses, marked by their rules; each arm's labels to the oracle's share per task; then the
    exploration's tables on these runs."""
    lines, verdicts, _ = hypotheses(runs)
    marked = [f"- **{name}**: {verdict}." for name, verdict in verdicts.items()]
    explained = (
        f"Labels to {SHARE:.0%} of the oracle on the agent of the one-view arms' view (the primary measure), "
        "DOSPCoT's over the best one-view peer's and the twin's over DOSPCoT's, paired by seed (and layout "
        "on the grid) with a 95% bootstrap interval; 0 where only the first reaches it, inf where only the "
        "second does, 1 where neither does. The figure draws the primary measure."
    )
    ratios = ["", explained, "", *lines] if len(lines) > 2 else []  # no task with DOSPCoT and a peer yet
    return [
        "",
        "### Hypotheses",
        "",
        *marked,
        *ratios,
        "",
        *answer(runs, verdicts),
        *_TABLES(runs),
        *steps_paid(runs, BUDGETS.__getitem__),
    ]


_TABLES = tables_linking("views-confirm.png", BUDGETS.__getitem__)


def glance(runs: list[TrialRun]) -> Glance:
    """Per task, DOSPCoT's labels to 90% of the oracle over the best one-view peer's; the verdicts."""
    _, verdicts, parts = hypotheses(runs)
    return Glance(
        f"labels to {SHARE:.0%} of the oracle, DOSPCoT over the best one-view peer, paired (0: only "
        "DOSPCoT reached it; inf: only the peer): " + "; ".join(parts),
        "; ".join(f"{name}: {verdict}" for name, verdict in verdicts.items()),
    )


def _figure(runs: list[TrialRun], path: Path) -> None:
    """The curves of the primary measure: each arm's agents on the one-view arms' view."""
    figure(runs, path, on_view=True)


STUDIES: dict[str, Study] = {
    "views-confirm": Study(
        tuple(
            s
            for task, budgets in BUDGETS.items()
            for s in curve_sweeps("views-confirm", task, budgets, MAPS.get(task))
        ),
        tables,
        "Where the second view pays: the confirmatory curves",
        "grid16 (unseen layouts), MiniGrid DoorKey-5x5 and LavaGapS7, the fast highway",
        glance,
        seeds=SEEDS,
        first_seed=FIRST_SEED,
        readme=readme_block,
        figure=_figure,
        confirmatory=True,
        preregistration="docs/preregistration-views.md",
    ),
}
