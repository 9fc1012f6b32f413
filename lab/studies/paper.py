"""The seed paper's protocol on masked CliffWalking-v1: a sweep of one paper preset over seeds, which
``dospcot report`` tables; the page gets every table, the README the target line of ``paper-text``."""

from __future__ import annotations

from functools import partial

from dospcot.config.presets import PAPER_PRESETS
from dospcot.metrics import published_paper_tables
from dospcot.run.run_folder import CONFIG_FILE
from dospcot.statistics import SeedSummary
from dospcot.sweeps import paper_tables as protocol
from dospcot.sweeps.report import TrialRun, paper_report_tables
from dospcot.tasks import load_run_config
from dospcot_lab.studies.declaration import Glance, Study, Sweep


def _with_agreement_plot(plot: str, runs: list[TrialRun]) -> list[str]:
    """The paper tables, after the plot of optimal-action agreement against round."""
    return [
        "",
        f"![optimal-action agreement against round, per agent kind and method]({plot})",
        "",
        *paper_report_tables(runs)[0],
    ]


def paper_headline(table: str) -> str:
    """The README's block of the paper protocol: its target line, as the study's tables state it."""
    return next(line for line in table.splitlines() if line.startswith("**Target**"))


def paper_glance(runs: list[TrialRun]) -> Glance:
    """The protocol's target: ESARSA-ESARSA DOSPCoT's optimal-action agreement against the oracle's,
    as the study's target line computes it (:func:`dospcot.sweeps.paper_tables.target_check`)."""
    cfg = load_run_config(runs[0].run_dir / CONFIG_FILE)
    rows = protocol.build_tables(
        [row for run in runs for row in run.curves], published_paper_tables(), cfg.tabular.rounds
    )
    target = protocol.target_check(rows)
    ours = next(
        row
        for row in rows
        if (row["table"], row["metric"], row["agents"], row["method"], row["gamma"])
        == ("3", "agreement", "ESARSA-ESARSA", "DOSPCoT", 0.3)
    )
    ours_cell = SeedSummary(*[ours[k] for k in ("mean", "low", "high", "iqm", "n")])
    met = target["meets_95pct_of_oracle"] and target["beats_masked_zero"] and target["beats_labels_only"]
    return Glance(
        f"optimal-action agreement, ESARSA-ESARSA DOSPCoT after {cfg.tabular.rounds} rounds: {ours_cell}, "
        f"{100 * target['ratio_to_oracle']:.1f}% of the oracle's {target['oracle_agreement']:.3f}",
        "target met (at least 95% of the oracle, interval above masked-zero and labels-only)"
        if met
        else "target not met (95% of the oracle, interval above masked-zero and labels-only)",
    )


# The seed paper's protocol: a sweep of one paper preset over seeds; `dospcot report` tables it.
STUDIES: dict[str, Study] = {
    preset: Study(
        (Sweep(preset, (preset,), {}, numerics=None),),
        partial(_with_agreement_plot, f"docs/results/{preset}-agreement.png"),
        f"Seed paper reproduction: masked CliffWalking-v1 (`{preset}`)",
        f"masked CliffWalking, the seed paper's protocol ({preset} settings)",
        paper_glance,
        seeds=10,
        readme=paper_headline if preset == "paper-text" else None,
        plot=("paper_agreement.png", f"{preset}-agreement.png"),
        cells_explained=True,
    )
    for preset in PAPER_PRESETS.values()
}
