"""The error-dependence tables of the views pages, on runs built by hand."""

from __future__ import annotations

import math

from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies.error_dependence import by_round_table, dependence_by_round, last_round_table

NAN = math.nan


def _run(rounds: list[tuple[float, float]]) -> TrialRun:
    """A run of two agents whose round ``n`` (from 1) has (error correlation, disagreement)
    ``rounds[n - 1]``, written on both agents' rows as metrics.csv writes a round's figures."""
    rows = [
        {"round": float(n), "agent": float(agent), "error_correlation": corr, "disagreement": dis}
        for n, (corr, dis) in enumerate(rounds, start=1)
        for agent in (0, 1)
    ]
    return TrialRun(Trial("p", "p", {}, 0), {"mean": {}}, rows, None)


def test_each_round_is_read_once_and_the_last_round_is_the_largest():
    run = _run([(0.5, 0.01), (NAN, 0.0), (1.0, 0.0)])
    assert dependence_by_round(run, "disagreement") == {1: 0.01, 2: 0.0, 3: 0.0}
    table = last_round_table({"DOSPCoT": [run], "twin": []})
    # joint and independent errors are absent from the rows (NaN: "–"); the last round's figures
    assert table[2] == "| DOSPCoT | – | – | 0.000 | 1.000 | 1 |" and len(table) == 3


def test_the_correlation_averages_only_where_defined_and_counts_those_runs():
    first = _run([(0.6, 0.002), (NAN, 0.0)])
    second = _run([(0.2, 0.004), (NAN, 0.0)])
    third = _run([(NAN, 0.0), (NAN, 0.0)])
    table = by_round_table({"DOSPCoT": [first, second, third], "reward model": []})
    assert table[0] == "| arm | figure | round 1 | round 2 |"
    # round 1: (0.6 + 0.2) / 2 over the two runs where it is defined; round 2: none
    assert table[2] == "| DOSPCoT | error correlation (runs) | 0.40 (2) | – (0) |"
    # disagreement over all three runs: (0.002 + 0.004 + 0) / 3
    assert table[3] == "| DOSPCoT | disagreement | 0.0020 | 0.0000 |"
    assert len(table) == 4  # an arm without runs has no rows
    assert by_round_table({"twin": []}) == []
