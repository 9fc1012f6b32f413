"""The seed paper's protocol on masked CliffWalking-v1: a sweep of one paper preset over seeds, which
``dospcot report`` tables; the README gets an excerpt, the docs page every table."""

from __future__ import annotations

import re
from functools import partial

from dospcot.config.presets import PAPER_PRESETS
from dospcot.experiment.report import TrialRun, paper_report_tables
from dospcot.experiment.studies.declaration import Study, Sweep


def _section(text: str, heading: str) -> str:
    """The markdown from ``heading`` to the next heading of the same or a higher level."""
    level = heading.split(" ")[0]
    start = text.index(heading)
    rest = text[start + len(heading) :]
    match = re.search(rf"^#{{1,{len(level)}}} ", rest, flags=re.MULTILINE)
    return (heading + (rest[: match.start()] if match else rest)).strip()


def _demote(markdown: str, levels: int = 2) -> str:
    """Push every heading ``levels`` deeper, so the tables nest under the README's own headings."""
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m.group(1)) + levels) + " ", markdown, flags=re.MULTILINE)


def _with_agreement_plot(plot: str, runs: list[TrialRun]) -> list[str]:
    """The paper tables, after the plot of optimal-action agreement against round."""
    return [
        "",
        f"![optimal-action agreement against round, per agent kind and method]({plot})",
        "",
        *paper_report_tables(runs)[0],
    ]


def paper_readme(table: str) -> str:
    """The README's excerpt of the paper tables: the header and target line, every paper-accuracy
    table, and Table 3 of optimal-action agreement."""
    agreement = _section(table, "## Optimal-action agreement")
    return "\n\n".join(
        [
            table.split("\n## ")[0].strip(),
            _demote(_section(table, "## Paper accuracy")),
            "#### Optimal-action agreement, Table 3 (after 5 rounds)",
            _section(agreement, "### Table 3").split("\n", 1)[1].strip(),
        ]
    )


# The seed paper's protocol: a sweep of one paper preset over seeds; `dospcot report` tables it.
STUDIES: dict[str, Study] = {
    preset: Study(
        (Sweep(preset, (preset,), {}),),
        partial(_with_agreement_plot, f"docs/{preset}-agreement.png"),
        f"Seed paper reproduction: masked CliffWalking-v1 (`{preset}`)",
        seeds=10,
        readme=paper_readme if preset == "paper-text" else None,
        plot=("paper_agreement.png", f"{preset}-agreement.png"),
    )
    for preset in PAPER_PRESETS.values()
}
