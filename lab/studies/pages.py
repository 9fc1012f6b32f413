"""A study's page and its row in the results at a glance, both generated: the page is the prose of
``pages/<study>.md`` with the study's tables where its ``<!-- table -->`` line stands; the row is the
study's headline comparison, read from the same runs."""

from __future__ import annotations

import re
from pathlib import Path

from dospcot.sweeps.report import TrialRun
from dospcot_lab.repository import Repository
from dospcot_lab.studies.declaration import EXPLORATORY, NOT_MEASURED, Study
from dospcot_lab.studies.readme import read_block, replace_block

PAGES = Path(__file__).resolve().parent / "pages"
"""The prose of each study's page, ``<study>.md``: what it runs above the table, its reading and
history below."""
TABLE = "<!-- table -->"
"""The line of a page's prose that the generated tables replace."""
GLANCE = "results-at-a-glance"
"""The generated block of README.md and docs/results/index.md: one row per study."""
GLANCE_HEAD = (
    "| study | task | headline comparison: mean [95% interval] | seeds | verdict |",
    "|---|---|---|---|---|",
)


def page_prose(name: str) -> str:
    """The prose of study ``name``'s page; ``ValueError`` unless it holds the table line once."""
    prose = (PAGES / f"{name}.md").read_text()
    if prose.splitlines().count(TABLE) != 1:
        raise ValueError(f"{PAGES / name}.md needs one {TABLE!r} line, where the tables go")
    return prose


def page(name: str, study: Study, table: str | None) -> str:
    """Study ``name``'s page: its title, then its prose with ``table`` (the study's tables, as
    :func:`dospcot_lab.studies.run_study` prints them) in place, or, where the record holds no
    run of the study (``None``), a notice that says so and how to produce it."""
    body = unpublished(name, study) if table is None else table.replace("](docs/results/", "](")
    return f"# {study.title}\n\n" + page_prose(name).replace(TABLE, body.rstrip("\n"))


UNPUBLISHED = "**Unpublished: the record holds no runs of this study**"
"""How a page that the record cannot rebuild begins its notice."""


def is_published(path: Path) -> bool:
    """Whether the study page at ``path`` exists and publishes tables (it is no unpublished notice)."""
    return path.is_file() and UNPUBLISHED not in path.read_text()


def unpublished(name: str, study: Study) -> str:
    """The notice in place of a table that the record cannot rebuild."""
    sweeps = ", ".join(f"`{sweep.name}`" for sweep in study.sweeps)
    seeds = f"{study.first_seed}-{study.first_seed + study.seeds - 1}"
    return (
        f"{UNPUBLISHED}, so this page shows no table and no "
        "figure of it (a table is published only where `--render-only` rebuilds it from the runs in "
        f"`runs/sweeps/`). `dospcot-lab study {name} --docs` trains it into `runs/sweeps/` "
        f"({len(study.sweeps)} sweep(s), seeds {seeds}: {sweeps}; several CPU-hours on 2 "
        "cores) and writes this page with its tables."
    )


VERSUS_SELF_TRAINING = re.compile(r"DOSPCoT(?: \([^)]*\))? minus self-training")
"""A headline of DOSPCoT minus self-training, the labels each spent named or not ("DOSPCoT (4,006 labels a
run) minus self-training (2,019)")."""
UNPUBLISHED_CELL = "unpublished: the record holds no runs of it"
"""The headline cell of a study the record holds no run of."""


def glance_cells(study: Study, runs: list[TrialRun]) -> list[str]:
    """The study's cells in the results at a glance, after its name: task, headline, seeds, verdict."""
    if not runs:
        return [study.task, UNPUBLISHED_CELL, "", "no verdict"]
    glance = study.glance(runs)
    seeds = sorted(glance.seeds or {run.trial.seed for run in runs})
    return [study.task, glance.headline, f"{len(seeds)} ({seeds[0]}-{seeds[-1]})", glance.verdict]


def glance_table(rows: dict[str, list[str]], order: list[str], link: str, brief: bool = False) -> str:
    """The results at a glance: a row per study of ``order`` (``rows`` holds each one's cells; a study
    without them is named with the command that renders it), each study linked to its page under
    ``link`` (``docs/results/`` from the README, nothing beside the pages), and a line that counts the
    studies whose headline finds DOSPCoT above self-training. ``brief`` (the README's) leaves out the
    rows of exploratory studies and of studies not run yet (no runs, or none of the pairs their rule
    names), and says where they are."""
    lines = list(GLANCE_HEAD)
    exploratory, not_run = [], []
    for name in order:
        render = f"`dospcot-lab study {name} --render-only --docs`"
        cells = rows.get(name) or ["", "not rendered yet", "", render]
        if brief and cells[3] == EXPLORATORY:
            exploratory.append(name)
        elif brief and (cells[1] == UNPUBLISHED_CELL or cells[3] == NOT_MEASURED):
            not_run.append(name)
        else:
            lines.append(f"| [{name}]({link}{name}.md) | " + " | ".join(cells) + " |")
    if exploratory or not_run:
        kinds = [f"{len(exploratory)} exploratory studies"] if exploratory else []
        kinds += [f"{len(not_run)} registered and not run yet ({', '.join(not_run)})"] if not_run else []
        lines += ["", f"And {' and '.join(kinds)}, in the [full table]({link}index.md)."]
    paired = [cells for cells in rows.values() if VERSUS_SELF_TRAINING.search(cells[1])]
    above = [cells for cells in paired if "DOSPCoT above self-training" in cells[3]]
    lines += [
        "",
        f"Of the {len(paired)} studies whose headline is DOSPCoT minus self-training, the interval lies "
        f"above 0 in {len(above)}.",
    ]
    return "\n".join(lines)


def glance_rows(text: str) -> dict[str, list[str]]:
    """The rows of a results-at-a-glance table (:func:`glance_table`) by study name."""
    rows = {}
    for line in text.splitlines()[len(GLANCE_HEAD) :]:
        match = re.match(r"\| \[([^\]]+)\]\([^)]*\) \| (.*) \|$", line)
        if match:
            rows[match.group(1)] = match.group(2).split(" | ")
    return rows


def write_glance(repo: Repository, name: str, cells: list[str], order: list[str]) -> None:
    """Replace study ``name``'s row of the results at a glance in ``repo``'s docs/results/index.md and
    README.md (without the exploratory rows), keeping the other studies' rows as their last render
    wrote them."""
    rows = glance_rows(read_block(repo.results / "index.md", GLANCE))
    rows[name] = cells
    replace_block(repo.readme, GLANCE, glance_table(rows, order, "docs/results/", brief=True))
    replace_block(repo.results / "index.md", GLANCE, glance_table(rows, order, ""))
