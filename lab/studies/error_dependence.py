"""The tables of the reward classifiers' error dependence (docs/design.md, section 4) that the views
studies print per task: each arm's last round, and each arm's rounds one by one.

Both take a task's runs grouped by arm (short arm name to runs), only the arms with two classifiers or
more to compare, in the order the page lists them.
"""

from __future__ import annotations

import math

import numpy as np

from dospcot.core.round_records import DEPENDENCE_STATS
from dospcot.sweeps.report import TrialRun


def last_round_dependence(run: TrialRun) -> dict[str, float]:
    """The error-dependence figures of a run's last round (:data:`DEPENDENCE_STATS`; NaN where its
    ``metrics.csv`` predates them or the round had one classifier)."""
    last = max((row["round"] for row in run.curves), default=None)
    row = next((row for row in run.curves if row["round"] == last), {})
    return {key: float(row.get(key, math.nan)) for key in DEPENDENCE_STATS}


def dependence_by_round(run: TrialRun, stat: str) -> dict[int, float]:
    """A run's figure ``stat`` (one of :data:`DEPENDENCE_STATS`) at each of its rounds, NaN where it is
    undefined; every agent's row of a round holds the round's figure."""
    return {int(row["round"]): float(row.get(stat, math.nan)) for row in run.curves}


def mean_text(values: list[float], decimals: int = 3) -> str:
    """The mean of the finite ``values`` to ``decimals`` decimals; "–" where none is."""
    finite = [v for v in values if not math.isnan(v)]
    return f"{np.mean(finite):.{decimals}f}" if finite else "–"


def last_round_table(by_arm: dict[str, list[TrialRun]]) -> list[str]:
    """Per arm: its runs' last-round error dependence, mean over the runs (every budget); [] where no
    arm has runs."""
    lines = [
        "| arm | joint error | independent error | disagreement | error correlation | runs |",
        "|---|---|---|---|---|---|",
    ]
    for arm, runs in by_arm.items():
        figures = [last_round_dependence(r) for r in runs]
        if figures:
            cells = " | ".join(mean_text([f[key] for f in figures]) for key in DEPENDENCE_STATS)
            lines.append(f"| {arm} | {cells} | {len(figures)} |")
    return lines if len(lines) > 2 else []


def by_round_table(by_arm: dict[str, list[TrialRun]]) -> list[str]:
    """Per arm, at each round: the mean error correlation over the runs where it is defined (both
    classifiers erred somewhere on the scored samples; those runs counted in brackets) and the mean
    disagreement over every run; [] where no arm has runs."""
    by_arm = {arm: runs for arm, runs in by_arm.items() if runs}
    rounds = sorted({int(row["round"]) for runs in by_arm.values() for r in runs for row in r.curves})
    if not rounds:
        return []
    lines = [
        "| arm | figure | " + " | ".join(f"round {n}" for n in rounds) + " |",
        "|---|---|" + "---|" * len(rounds),
    ]
    for arm, runs in by_arm.items():
        correlation = [dependence_by_round(r, "error_correlation") for r in runs]
        disagreement = [dependence_by_round(r, "disagreement") for r in runs]
        cells = []
        for n in rounds:
            defined = [c[n] for c in correlation if not math.isnan(c.get(n, math.nan))]
            cells.append(f"{np.mean(defined):.2f} ({len(defined)})" if defined else "– (0)")
        lines.append(f"| {arm} | error correlation (runs) | " + " | ".join(cells) + " |")
        # a rate of a few samples in a thousand where the classifiers are right: four decimals show it
        means = [mean_text([d.get(n, math.nan) for d in disagreement], 4) for n in rounds]
        lines.append(f"| {arm} | disagreement | " + " | ".join(means) + " |")
    return lines
