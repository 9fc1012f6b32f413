"""Every published study, each one command: its sweeps (``dospcot sweep``), their reports
(``dospcot report``) and its tables.

    dospcot-lab study label-fraction --docs   # 4 presets x 6 label fractions x seeds 0-4 (~2.5 h)
    dospcot-lab study grid16 --docs           # 6 grid16 presets x seeds 0-9
    dospcot-lab study grid16-layouts --docs   # 3 grid16 presets x 3 unseen layouts x seeds 0-4
    dospcot-lab study grid32 --docs           # 4 grid32 presets x seeds 0-4
    dospcot-lab study grid16-tabular --docs   # the same with tabular agents (agent = "tabular")
    dospcot-lab study fasthighway --docs      # 4 fasthighway presets x seeds 0-4
    dospcot-lab study minigrid --docs         # 4 presets x LavaGapS7, DoorKey-5x5 x seeds 0-4
    dospcot-lab study highway --docs          # 4 highway presets (highway-fast-v0) x seeds 0-2
    dospcot-lab study paper-text --docs       # the seed paper's protocol x seeds 0-9 (~2 min)
    dospcot-lab study paper-published-code --docs   # the same with its published code's settings
    dospcot-lab study demo-labels --docs      # grid16-dospcot: 10 demonstrations + 1% vs 5% labels
    dospcot-lab study equal-effort --docs     # grid16-dospcot: per-step labels, segments, demos
    dospcot-lab study equal-effort-highway --docs  # the same on the fast highway, 5 seeds
    dospcot-lab study third-view-doorkey --docs    # DoorKey: m = 3 vs m = 2 at 100 labels, seeds 0-9
    dospcot-lab study second-view --docs      # docs/preregistration.md's grid settings x seeds 0-9
    dospcot-lab study second-view-highway --docs   # its highway monitor setting x seeds 0-4
    dospcot-lab study budget-explore --docs   # label budgets, schedules and peers on MiniGrid, seeds 0-2
    dospcot-lab study budget-explore-doorkey --docs   # its DoorKey arms on seeds 0-9, own draws, numerics 2
    dospcot-lab study budget-explore-admit --docs     # all of U in round 1: DoorKey, grid16, fast highway
    dospcot-lab study budget-explore-peers --docs     # the peers at 100 labels on DoorKey and LavaGap
    dospcot-lab study budget-explore-decay --docs     # a decaying schedule on DoorKey and LavaGap
    dospcot-lab study budget-explore-grid-highway --docs  # those settings on grid16 and the fast highway
    dospcot-lab study budget --docs           # docs/preregistration-budget.md: B1-B4, seeds 100-109
    dospcot-lab study numerics --docs         # numerics 2 vs 1: grid16-dospcot, DoorKey, seeds 0-19
    dospcot-lab study numerics-3 --docs       # numerics 3 vs 1: the same presets and seeds, adoption rule
    dospcot-lab study defaults-4 --docs       # version 4 (exploration by rounds) vs 3, the same seeds
    dospcot-lab study defaults-5 --docs       # version 5 (4 co-training passes a round) vs 3, likewise
    dospcot-lab study defaults-6 --docs       # version 6 (5 with the refit on a new class) vs 3, likewise
    dospcot-lab study defaults-7 --docs       # version 7 (6 with passes from round 2) vs 3, likewise
    dospcot-lab study defaults-8 --docs       # version 8 (7 with exploration by rounds) vs 3, likewise
    dospcot-lab study defaults-12 --docs      # version 12 (chosen labels, score passes) vs 3, likewise
    dospcot-lab study sizing --docs           # Unlock: 5 rounds vs capped at 20 with patience, seeds 100-104
    dospcot-lab study true-rewards --docs     # the co-training path fed the true rewards, 4 tasks
    dospcot-lab study untuned --docs          # 5 MiniGrid tasks no one tuned, env id and views only
    dospcot-lab study views --docs            # label curves: DOSPCoT, a twin, one-view peers, 5 tasks
    dospcot-lab study views-confirm --docs    # docs/preregistration-views.md: V1-V4, seeds 200-209

A study is one or more sweeps in ``runs/sweeps/``:
rerunning the command runs only the trials not yet finished, then rebuilds the tables from every
finished run folder (``--render-only`` trains nothing). The grid tables lead with success (the share
of seeds x agents whose greedy policy reaches the goal from the map's start) and optimal-action
agreement; the normalised score follows, with its caveat in each table's header (a policy that never
reaches the goal but avoids lava scores high).

With ``--docs`` the study's page ``docs/results/<study>.md`` is written: the prose of
``pages/<study>.md`` in this package with the tables in place (a study whose record holds no run
gets a page that says so), its plot goes to ``docs/results/``, its row of the results at a glance
is rewritten in README.md and ``docs/results/index.md`` (between the ``results-at-a-glance``
markers), and a study with a README block (the paper protocol's headline) rewrites it between its
``<!-- <study>-table:start -->`` and ``<!-- <study>-table:end -->`` markers. No number is typed by
hand.
"""

# The package: each study is declared once, beside its tables, in the module of its group (grid,
# highway, minigrid, label_sources, second_view, paper), with its page's prose in pages/<study>.md;
# declaration.py says what a study is, tables.py and provenance.py hold what their tables share,
# pages.py makes a page and a row of the results at a glance, readme.py where --docs writes. This
# module gathers them into STUDIES and runs one (:func:`run_study`, behind ``dospcot-lab study``).

from __future__ import annotations

import argparse
import contextlib
import shlex
import shutil
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from dospcot.config.presets import did_you_mean
from dospcot.run.interrupts import Interrupted
from dospcot.run.run_folder import PACKAGE_DIR, source_commit
from dospcot.sweeps.report import TrialRun, load_runs, write_report
from dospcot.sweeps.sweep import SweepError, SweepSpec, check_not_stale, run_sweep
from dospcot_lab.repository import Repository
from dospcot_lab.studies import (
    batched_seeds,
    budget_classes,
    budget_confirm,
    budget_explore,
    defaults,
    defaults_4,
    defaults_5,
    defaults_6,
    defaults_7,
    defaults_8,
    defaults_12,
    defaults_13,
    defaults_14,
    grid_studies,
    highway_studies,
    label_sources,
    minigrid,
    numerics,
    paper,
    queries,
    second_view,
    sizing,
    step_class,
    true_rewards,
    untuned,
    views,
    views_confirm,
)
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.pages import GLANCE, glance_cells, is_published, page, page_prose, write_glance
from dospcot_lab.studies.preregistration import added_in, preregistered_line
from dospcot_lab.studies.provenance import header
from dospcot_lab.studies.readme import read_block, replace_block

__all__ = [
    "STUDIES",
    "Glance",
    "Rendered",
    "Study",
    "Sweep",
    "check_record",
    "get_study",
    "header",
    "header_command",
    "render_study",
    "run_study",
    "study_runs",
    "study_table",
    "sweep_spec",
]

STUDIES: dict[str, Study] = {
    **grid_studies.STUDIES,
    **highway_studies.STUDIES,
    **minigrid.STUDIES,
    **label_sources.STUDIES,
    **second_view.STUDIES,
    **paper.STUDIES,
    **queries.STUDIES,
    **batched_seeds.STUDIES,
    **budget_explore.STUDIES,
    **budget_classes.STUDIES,
    **budget_confirm.STUDIES,
    **numerics.STUDIES,
    **defaults.STUDIES,
    **defaults_4.STUDIES,
    **defaults_5.STUDIES,
    **defaults_6.STUDIES,
    **defaults_7.STUDIES,
    **defaults_8.STUDIES,
    **defaults_12.STUDIES,
    **defaults_13.STUDIES,
    **defaults_14.STUDIES,
    **sizing.STUDIES,
    **true_rewards.STUDIES,
    **untuned.STUDIES,
    **views.STUDIES,
    **views_confirm.STUDIES,
    **step_class.STUDIES,
}
"""Every study by name, in the order the command's help lists them."""


def get_study(name: str) -> Study:
    """The study called ``name``; ``ValueError``, naming every study, where there is none."""
    try:
        return STUDIES[name]
    except KeyError:
        raise ValueError(f"no study {name!r}{did_you_mean(name, STUDIES, 'the studies', None)}") from None


def header_command(program: Sequence[str], study: str, options: Sequence[str]) -> str:
    """The command a study's header names: ``program``, the study and its options, less
    ``--render-only`` and ``--sweep NAME``, so that tables rebuilt from finished runs name the command
    that trains all of them."""
    kept: list[str] = []
    names_a_sweep = False  # the option before was --sweep: this one is its name
    for option in options:
        if names_a_sweep:
            names_a_sweep = False
        elif option == "--sweep":
            names_a_sweep = True
        elif option != "--render-only" and not option.startswith("--sweep="):
            kept.append(option)
    return shlex.join([*program, study, *kept])


def study_runs(
    study: Study, runs_dir: Path, suffix: str = ""
) -> tuple[list[TrialRun], list[Path], list[str]]:
    """The finished runs of ``study``'s sweeps under ``runs_dir`` (each sweep's folder name plus
    ``suffix``; of a sweep it reuses for some configs, those it reads), the sweep folders that hold
    them, and each sweep not finished, in words (never started, or how many of its trials have
    finished)."""
    runs, sweep_dirs, unfinished = [], [], []
    for sweep in study.sweeps:
        sweep_dir = runs_dir / f"{sweep.name}{suffix}"
        try:
            spec, finished = load_runs(sweep_dir)
        except SweepError:  # never started, or no trial finished yet: the study was cut short there
            unfinished.append(f"`{sweep_dir.name}`")
            continue
        read = sweep.reads or spec.configs
        finished = [run for run in finished if run.trial.config in read]
        runs += finished
        sweep_dirs.append(sweep_dir)
        planned = len([t for t in spec.trials(check_task=False) if t.config in read])
        if len(finished) < planned:
            unfinished.append(f"`{sweep_dir.name}` ({len(finished)} of its {planned} runs)")
    return runs, sweep_dirs, unfinished


def study_table(
    study: Study, runs: list[TrialRun], command: str, sweep_dirs: list[Path], unfinished: list[str]
) -> str:
    """The study's tables as text: the header (where the figures come from), then its tables."""
    # By name: where the runs folder lies is the reader's, and a sweep not begun has no folder to cite.
    missing = (
        [f"Not finished yet, in the runs folder: sweep(s) {', '.join(unfinished)}."] if unfinished else []
    )
    preregistered = (
        [preregistered_line(runs, study.preregistration, runs[0].run_dir)] if study.preregistration else []
    )
    lines = [*header(runs, command, sweep_dirs, study.cells_explained), *preregistered, *missing]
    return "\n".join([*lines, *study.tables(runs)]) + "\n"


def sweep_spec(sweep: Sweep, seeds: int, overrides: Sequence[str] = (), first_seed: int = 0) -> SweepSpec:
    """The spec of one of a study's sweeps over ``seeds`` seeds from ``first_seed``, with ``overrides``
    (``--set``)."""
    return SweepSpec(
        sweep.configs,
        sweep.grid,
        tuple(range(first_seed, first_seed + (sweep.seeds or seeds))),
        (*sweep.overrides(), *overrides),
        sweep.defaults,
    )


def check_record(
    study: Study, runs_dir: Path, seeds: int, overrides: Sequence[str] = (), suffix: str = ""
) -> None:
    """Raise :class:`SweepError` where a finished trial of the study was trained under another config
    than its preset and overrides give now: the record cannot stand for the study then."""
    for sweep in study.sweeps:
        sweep_dir = runs_dir / f"{sweep.name}{suffix}"
        if sweep_dir.is_dir():  # a sweep never started has nothing stale
            spec = sweep_spec(sweep, seeds, overrides, study.first_seed)
            check_not_stale(sweep_dir, spec.trials(check_task=False))


@dataclass(frozen=True)
class Rendered:
    """What ``--docs`` writes of a study: its tables (None where the record holds no run), its page,
    its cells in the results at a glance, and its README block (None where it has none)."""

    table: str | None
    page: str
    glance: list[str]
    readme: str | None


def render_study(name: str, runs_dir: Path, command: str, suffix: str = "") -> Rendered:
    """Study ``name`` rendered from the finished runs under ``runs_dir``, with ``command`` in its
    header; nothing is trained or written."""
    study = get_study(name)
    runs, sweep_dirs, unfinished = study_runs(study, runs_dir, suffix)
    table = study_table(study, runs, command, sweep_dirs, unfinished) if runs else None
    readme = study.readme(table) if study.readme is not None and table is not None else None
    return Rendered(table, page(name, study, table), glance_cells(study, runs), readme)


def run_study(args: argparse.Namespace, command: str, repo: Repository | None, prog: str) -> None:
    """Run the study ``args.study`` (its unfinished trials; none with ``args.render_only``), then print
    its tables and, with ``args.docs``, write its page, plot, row of the results at a glance and README
    block into ``repo`` (its docs/results/ and README.md). ``command`` is the header's command line
    (:func:`header_command`); ``prog`` starts each one-line error, on which it exits with status 1.
    ``args`` holds what the lab's ``study`` command parses: study, seeds, workers, backend, overrides,
    runs_dir, docs, render_only and sweeps (the sweeps to train; empty: every one).

    Without ``--docs`` nothing is written outside ``args.runs_dir``. With it, a study whose runs folder
    holds no run of it keeps its published page: ``--docs`` then writes a page that says the study is
    unpublished only where the repository has no published page of it either."""
    study = get_study(args.study)
    block = f"{args.study}-table"
    if args.docs:
        if repo is None:
            sys.exit(f"{prog}: --docs writes into a checkout of the repository: run from one, or give --repo")
        try:  # before hours of training, not after
            page_prose(args.study)
            read_block(repo.readme, GLANCE)
            read_block(repo.results / "index.md", GLANCE)
            if study.readme is not None:
                read_block(repo.readme, block)
        except ValueError as err:
            sys.exit(f"{prog}: {err}")
    if study.confirmatory and not args.render_only:
        commit = source_commit()
        if commit is None or commit.endswith("+dirty"):
            where = "not from a git checkout" if commit is None else "with uncommitted changes"
            sys.exit(
                f"{prog}: {args.study} is confirmatory and trains only from a committed checkout with no "
                f"uncommitted change; this code runs {where} (commit it, or run from a clean clone)"
            )
    if (
        study.preregistration
        and not args.render_only
        and added_in(study.preregistration, PACKAGE_DIR) is None
    ):
        sys.exit(
            f"{prog}: {args.study} follows {study.preregistration}, which this checkout has not committed: "
            "commit the preregistration before any of its runs"
        )
    args.seeds = args.seeds or study.seeds
    # Another --seeds or --set is another sweep: it gets its own folder.
    default = (args.seeds, args.overrides) == (study.seeds, [])
    suffix = "" if default else f"-{args.seeds}seeds-{len(args.overrides)}sets"
    try:  # trials run under a preset that has changed since are neither resumed nor tabled
        if args.render_only:
            check_record(study, args.runs_dir, args.seeds, args.overrides, suffix)
        else:
            for sweep in (s for s in study.sweeps if not args.sweeps or s.name in args.sweeps):
                spec = sweep_spec(sweep, args.seeds, args.overrides, study.first_seed)
                sweep_dir = args.runs_dir / f"{sweep.name}{suffix}"
                failed = run_sweep(
                    sweep_dir,
                    spec,
                    backend=args.backend,
                    workers=args.workers,
                    batch_seeds=sweep.batch_seeds or args.batch_seeds,
                ).failed
                if failed:
                    sys.exit(f"{len(failed)} trials failed: {', '.join(failed)}")
    except SweepError as err:
        sys.exit(f"{prog}: {err}")
    except KeyboardInterrupt:  # a stop between two sweeps, or as one closed: no trial was mid-run
        raise Interrupted(f"every trial that finished, under {args.runs_dir}", command) from None
    written = []
    for sweep in study.sweeps:
        with contextlib.suppress(SweepError):  # a sweep not started has no report
            written += write_report(args.runs_dir / f"{sweep.name}{suffix}")
    rendered = render_study(args.study, args.runs_dir, command, suffix)
    if rendered.table is None and not (args.docs and args.render_only and default):
        sys.exit(f"{prog}: no finished run of this study under {args.runs_dir}; run it without --render-only")
    if rendered.table is None:
        assert repo is not None  # --docs
        if is_published(repo.results / f"{args.study}.md"):
            sys.exit(
                f"{prog}: no finished run of {args.study} under {args.runs_dir}, and "
                f"{repo.results / f'{args.study}.md'} publishes its tables: --docs keeps a published "
                "page; render from the runs folder that holds the study's runs (--runs-dir)"
            )
        print(f"no finished run of {args.study} under {args.runs_dir}: its page says it is unpublished")
    else:
        print(rendered.table)
    if args.docs:
        assert repo is not None
        (repo.results / f"{args.study}.md").write_text(rendered.page)
        plot = next((p for p in written if study.plot and p.name == study.plot[0]), None)
        if plot is not None:
            shutil.copyfile(plot, repo.results / study.plot[1])
        if study.figure is not None and rendered.table is not None:
            study.figure(study_runs(study, args.runs_dir, suffix)[0], repo.results / f"{args.study}.png")
        write_glance(repo, args.study, rendered.glance, list(STUDIES))
        if rendered.readme is not None:
            replace_block(repo.readme, block, rendered.readme)
