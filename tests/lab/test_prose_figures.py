# ruff: noqa: E501 (the figures' regexes read whole phrases, and the stale sentences are verbatim copies)
"""Every figure the prose restates from a study or a benchmark holds to its source (issue 60).

README.md, the CHANGELOG's newest entry, runs/README.md and the hand-written pages of the docs
restate figures of the record (``runs/sweeps/``) and of BENCHMARKS.md. Each such figure is either
written by a generator, and a test fails while the generated text is stale (the study pages, the
results at a glance and the README's study blocks: ``tests/lab/test_docs.py``; runs/README.md's size:
:mod:`dospcot_lab.record`, below), or it is listed in :data:`FIGURES`: the file, a regex that finds
its sentence, one that reads the figure(s) in that sentence, and a function that computes the true
value(s). A figure that no longer matches fails, naming the file, the figure found and the true value.

The true values come from the record read directly (:class:`dospcot_lab.record.Record`: runs,
sweeps, seeds, CPU time, labels bought), from BENCHMARKS.md's table, or, for a figure of a study's
table, from the study's generated page, which ``tests/lab/test_docs.py`` rebuilds from the record (so a
page's figure is the record's). A figure is equal where it is the true value rounded to the digits
the prose gives.

Left unchecked, with no source in the record or BENCHMARKS.md to check them against: the CHANGELOG's
counts of a study part-way through (its "250 of about 480", "332" and "450" runs: history), a
checkpoint's size, the presets' tuning probes and docs/your_env.md's probes (runs outside the
record), docs/guide/big-machines.md (issue 59's measurements, in no BENCHMARKS.md row),
docs/guide/profile.md (written whole by ``scripts/profile_round.py``) and docs/batched_seeds.md's
phase table (``scripts/batched_phases.py``).

The stale figures issue 60 found at commit 700346f are kept below (:data:`STALE`) as they stood
there, and each must fail its check.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from statistics import mean

import pytest

from dospcot_lab.bench_measure import NOT_RECORDED, Provenance
from dospcot_lab.record import SIZE_BLOCK, Record, english, read_block

ROOT = Path(__file__).resolve().parents[2]
NUMBER_WORDS = {w: i for i, w in enumerate("zero one two three four five six seven eight nine ten".split())}


def flat(text: str) -> str:
    """``text`` with every run of white space one space: a sentence reads the same across line breaks."""
    return re.sub(r"\s+", " ", text)


class Sources:
    """Where the true values come from, each read once: the record, BENCHMARKS.md and the study pages."""

    @cached_property
    def record(self) -> Record:
        return Record(ROOT)

    @cached_property
    def bench_rows(self) -> list[list[str]]:
        """BENCHMARKS.md's table rows, as cells."""
        lines = (ROOT / "BENCHMARKS.md").read_text().splitlines()
        return [cells(line) for line in lines if line.startswith("| ") and not line.startswith("| benchmark")]

    def bench(self, title: str, setting: str = "") -> list[str]:
        """The one row of BENCHMARKS.md whose title starts ``title`` and setting ``setting``."""
        found = [row for row in self.bench_rows if row[0].startswith(title) and row[1].startswith(setting)]
        assert len(found) == 1, f"BENCHMARKS.md: {len(found)} rows {title!r} {setting!r}"
        return found[0]

    def ratio(self, title: str, setting: str = "") -> float:
        return float(self.bench(title, setting)[4])

    def target(self, title: str, setting: str = "") -> float:
        return float(self.bench(title, setting)[5].split()[1])

    def gpu(self, title: str, setting: str = "") -> tuple[float, float, float]:
        """The GPU cell's ratio and its two medians (ours, the peer's)."""
        cell = self.bench(title, setting)[-1]
        ratio, ours, peer = re.fullmatch(r"([\d.]+), \w+ \(([\d,.]+) \S+ vs ([\d,.]+) \S+\)", cell).groups()
        return float(ratio), number(ours), number(peer)

    def ours(self, title: str, setting: str = "") -> float:
        return number(self.bench(title, setting)[2].split()[0])

    def page(self, study: str) -> str:
        return flat((ROOT / "docs" / "results" / f"{study}.md").read_text())

    def page_figure(self, study: str, pattern: str) -> tuple[str, ...]:
        """The groups of ``pattern`` on study ``study``'s generated page (its only match)."""
        found = re.findall(pattern, self.page(study))
        assert len(found) == 1, f"docs/results/{study}.md: {len(found)} matches of {pattern!r}"
        return found[0] if isinstance(found[0], tuple) else (found[0],)

    def page_cell(self, study: str, table: str, row: str, column: str) -> float:
        """The mean in a cell of a table of study ``study``'s page: the table whose header's first cell
        is ``table``, its row ``row`` and its column ``column``."""
        lines = (ROOT / "docs" / "results" / f"{study}.md").read_text().splitlines()
        at = lines.index(next(line for line in lines if line.startswith(f"| {table} | ")))
        header = cells(lines[at])
        table_rows = []
        for line in lines[at + 2 :]:
            if not line.startswith("| "):
                break
            table_rows.append(cells(line))
        rows = {r[0]: r for r in table_rows}
        return number(rows[row][header.index(column)].split()[0])

    def sweeps_of_page(self, study: str) -> list[str]:
        """The sweeps a study's page says its runs come from (its generated header)."""
        header = self.page_figure(study, r"runs of sweep\(s\) (.*?); seeds")[0]
        return re.findall(r"`runs/sweeps/([\w-]+)`", header)

    def runs_of(self, sweeps: list[str]) -> list[Path]:
        return [run for run in self.record.runs if self.record.sweep_of(run) in sweeps]

    def glance(self) -> dict[str, str]:
        """The README's results at a glance: each study's row."""
        block = read_block((ROOT / "README.md").read_text(), "results-at-a-glance")
        return {m.group(1): line for line in block.splitlines() if (m := re.match(r"\| \[([\w-]+)\]", line))}

    def labels_bought(self, sweep: str, strategies: set[str] | None = None) -> float:
        """The labels a run of ``sweep`` bought (``labelled_steps``), its active arms' mean: those whose
        label strategy is one of ``strategies`` (by default any but the uniform mask)."""
        values = []
        for run in self.runs_of([sweep]):
            strategy = json.loads((run / "trial.json").read_text())["params"].get("training.label_strategy")
            if strategy and strategy != "uniform" and (strategies is None or strategy in strategies):
                values.append(json.loads((run / "summary.json").read_text())["mean"]["labelled_steps"])
        return mean(values)

    def cpu_per_run(self, sweep: str, config: str) -> float:
        runs = [run for run in self.runs_of([sweep]) if run.parent.name == config]
        return mean(json.loads((run / "run_info.json").read_text())["cpu_time_s"] for run in runs)

    def seeds(self, sweeps: list[str]) -> int:
        """The seeds of ``sweeps``' cells (one number, which they share)."""
        counts = {
            len(json.loads((self.record.sweeps_dir / s / "sweep.json").read_text())["seeds"]) for s in sweeps
        }
        assert len(counts) == 1, counts
        return counts.pop()


def cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split(" | ")]


def number(text: str) -> float:
    return float(text.replace(",", "").rstrip("%"))


@dataclass(frozen=True)
class Figure:
    """A figure (or several) of one sentence, and where its truth comes from.

    ``sentence`` finds the sentence in the file (white space collapsed); ``figures`` reads the figures
    in it, a group each; ``truth`` computes one true value per group from the sources and the file's
    text (most ignore the text). A number is equal where it is the true value rounded to the digits
    written (``+``, ``%``, ``x`` and thousands' commas aside); a list of numbers where every number is;
    a string where it is the same; a set where the names in backticks and the link targets written are
    the set. ``required=False``: a sentence that may be absent (a claim a file must not make)."""

    name: str
    file: str
    sentence: str
    figures: str
    truth: Callable[[Sources, str], tuple]
    source: str
    required: bool = True


def changelog_newest(text: str) -> str:
    """The CHANGELOG's newest entry: from ``## [Unreleased]`` (or the first release) to the next."""
    heads = [m.start() for m in re.finditer(r"^## \[", text, flags=re.MULTILINE)]
    return text[heads[0] : heads[1] if len(heads) > 1 else None]


def repetitions_of(sources: Sources, text: str) -> tuple:
    """The repetition counts a BENCHMARKS.md's rows were measured with: each row's *made by* cell,
    and each "Rerun alone by" line's ``--repeats`` (3 where it gives none). A header that claims one
    count must find only that one."""
    counts = set()
    for line in text.splitlines():
        if line.startswith("| ") and not line.startswith(("| benchmark", "|---")):
            made = cells(line)[-2]
            if "repetition" in made and Provenance.parse(made).repetitions != NOT_RECORDED:
                counts.add(int(Provenance.parse(made).repetitions))
        if line.startswith("Rerun alone by"):
            repeats = re.search(r"--repeats (\d+)", line)
            counts.add(int(repeats.group(1)) if repeats else 3)
    return (sorted(counts),)


def queries_q_verdicts(s: Sources, _: str) -> tuple:
    lines = re.findall(r"- (Q\d) \([^)]*\)[^*]*\*\*(not met|met|not decided yet[^*]*)\*\*", s.page("queries"))
    verdicts = {}
    for q, verdict in lines:
        verdicts.setdefault(q, set()).add(verdict)
    not_met = sorted(q for q, v in verdicts.items() if "not met" in v)
    return (english(not_met),)


def unpublished(s: Sources, _: str) -> tuple:
    names = [name for name, row in s.glance().items() if "unpublished" in row]
    word = next(w for w, i in NUMBER_WORDS.items() if i == len(names)).capitalize()
    return word, frozenset(names)


def queries_chosen_on_minigrid(s: Sources, _: str) -> tuple:
    shares = [
        s.page_cell("queries", f"{task}: queries", "dospcot disagreement @ 0.1", "chosen by the strategy")
        for task in ("MiniGrid-LavaGapS7-v0", "MiniGrid-DoorKey-5x5-v0")
    ]
    return min(shares), max(shares)


def q3_shares(s: Sources, _: str) -> tuple:
    def share(task: str) -> float:
        return float(s.page_figure("queries", rf"- Q3 \({task}\): DOSPCoT outcomes reaches (\d+)%")[0])

    return share("MiniGrid-LavaGapS7-v0"), share("MiniGrid-DoorKey-5x5-v0")


def descriptive(s: Sources, task: str, a: str, b: str) -> float:
    pattern = rf"- Descriptive, not registered \({re.escape(task)}\): success of {a} minus {b} \([^)]*\), paired: (-?[\d.]+) "
    return float(s.page_figure("queries", pattern)[0])


def queries_runs_and_hours(s: Sources, _: str) -> tuple:
    sweeps = s.sweeps_of_page("queries")
    return len(s.runs_of(sweeps)), s.record.cpu_seconds(sweeps) / 3600


def queries_highway(s: Sources, _: str) -> tuple:
    """The fast highway's queries study: its runs, the share of queries after round 1 (the active arms
    it names), success under the uniform masks, with uncertainty or disagreement and the oracle's, and
    its seeds."""

    def success(arm: str) -> float:
        return s.page_cell("queries-highway", "fast highway", arm, "success")

    after = [
        s.page_cell("queries-highway", "fast highway: queries", arm, "after round 1")
        for arm in ("dospcot disagreement @ 0.02", "ST uncertainty @ 0.02")
    ]
    uniform = [success(f"{m} uniform @ 0.02") for m in ("ST", "dospcot")]
    active = [
        success(arm)
        for arm in (
            "ST uncertainty @ 0.02",
            "dospcot uncertainty @ 0.02",
            "dospcot disagreement @ 0.02",
        )
    ]
    return (
        len(s.runs_of(HIGHWAY_QUERIES)),
        mean(after),
        min(uniform),
        max(uniform),
        min(active),
        max(active),
        success("oracle"),
        s.seeds(HIGHWAY_QUERIES),
    )


def reward_classes(s: Sources, _: str) -> tuple:
    """The co-trained runs that keep ``reward_classes.json``, all of them, and the sweeps of those that
    do not (they predate it)."""
    kept = set(s.record.with_file(s.record.cotrained, "reward_classes.json"))
    lacking = sorted({s.record.sweep_of(run) for run in s.record.cotrained if run not in kept})
    return len(kept), len(s.record.cotrained), english(lacking)


def batched_science(s: Sources, _: str) -> tuple:
    """The batched-seeds study's last seed, and the half-width every one of its differences held to
    (none where one did not hold)."""
    lines = re.findall(r"half-width is at most ([\d.]+): \*\*([\w ]+)\*\*", s.page("batched-seeds"))
    bounds = {float(bound) for bound, verdict in lines if verdict == "held"}
    held = len(lines) > 0 and all(verdict == "held" for _, verdict in lines) and len(bounds) == 1
    return int(s.page_figure("batched-seeds", r"; seeds 0-(\d+);")[0]), bounds.pop() if held else "not held"


def batched_saving(s: Sources, _: str) -> tuple:
    return tuple(
        sorted(
            s.cpu_per_run("batched-seeds-alone", config) / s.cpu_per_run("batched-seeds-batched", config)
            for config in ("grid16-dospcot", "grid16-oracle")
        )
    )


BATCHED = "`dospcot train --seeds`, one batch vs runs of their own: CPU time per seed"
WALL = "`dospcot sweep --workers 2 --batch-seeds K`"
MEMORY = "`dospcot train --seeds`, a batch's member"
STACKED = "One stacked gradient step of 10 members"
ESARSA_TARGET = "ExpectedSarsaDQN (target='expected_sarsa', greedy='target')"
NARROW, WIDE = (
    "CliffWalking-v1 one-hot, 20,000 steps, MlpPolicy [64, 64]",
    "CliffWalking-v1 one-hot, 20,000 steps, MlpPolicy [256, 256]",
)
HIGHWAY_QUERIES = [
    "queries-fasthighway-oracle",
    "queries-fasthighway-self-training",
    "queries-fasthighway-dospcot",
]
GRID_Q = "grid16, layouts 101, 202, 303"
LAVAGAP, DOORKEY = "MiniGrid-LavaGapS7-v0", "MiniGrid-DoorKey-5x5-v0"


def grid16_batched(s: Sources) -> float:
    return s.ratio(BATCHED, "`grid16-dospcot`")


FIGURES = [
    # README.md
    Figure(
        "batched CPU per seed",
        "README.md",
        r"\[batched seeds\]\(docs/batched_seeds\.md\); .*? short of its \d+x aim",
        r"([\d.]+)x less CPU per seed .*? short of its (\d+)x aim",
        lambda s, _: (1 / grid16_batched(s), 1 / s.target(BATCHED, "`grid16-dospcot`")),
        "BENCHMARKS.md's grid16 batched-seeds row (1 / its ratio, 1 / its target)",
    ),
    Figure(
        "seeds per cell",
        "README.md",
        r"\*\*Small evidence\.\*\* [^.]*? seeds per cell\.",
        r"\*\*Small evidence\.\*\* (.*?) seeds per cell",
        lambda s, _: (s.record.seeds_per_cell(),),
        "record (each sweep.json's seeds)",
    ),
    Figure(
        "pre-registered studies",
        "README.md",
        r"Only the [^.]*? fixed before (?:its|their) runs \(.*?\)\.",
        r"(.*)",
        lambda s, _: (frozenset(f"docs/{p.name}" for p in (ROOT / "docs").glob("preregistration*.md")),),
        "docs/preregistration*.md (each study's pre-registration)",
    ),
    Figure(
        "unpublished studies",
        "README.md",
        r"\*\*\w+ stud(?:y is|ies are) unpublished\.\*\* .*? ha(?:s|ve) no runs",
        r"\*\*(\w+) stud(?:y is|ies are) unpublished\.\*\* (.*?) ha(?:s|ve) no runs",
        unpublished,
        "results at a glance (the studies the record holds no run of)",
        required=False,  # every study has runs now: the sentence may come back with a study that has none
    ),
    # docs/results/index.md: "The studies in brief", moved there from the README
    Figure(
        "queries runs and CPU-hours",
        "docs/results/index.md",
        r"pre-registered `queries` study \([^)]*\)",
        r"\((\d[\d,]*) runs, (\d+) CPU-hours\)",
        queries_runs_and_hours,
        "record (the queries page's sweeps: finished runs, run_info.json's cpu_time_s)",
    ),
    Figure(
        "queries verdicts",
        "docs/results/index.md",
        r"whole in the record: Q\d(?:, Q\d)*(?: and Q\d)? are not met",
        r"(Q\d(?:, Q\d)*(?: and Q\d)?) are not met",
        queries_q_verdicts,
        "docs/results/queries.md's hypothesis lines",
    ),
    Figure(
        "co-testing on MiniGrid",
        "docs/results/index.md",
        r"co-testing barely acted \(.*?\)",
        r"(\d+)-(\d+)% of its queries on MiniGrid",
        queries_chosen_on_minigrid,
        "docs/results/queries.md (MiniGrid, DOSPCoT disagreement, chosen by the strategy)",
    ),
    Figure(
        "outcomes' share of the oracle",
        "docs/results/index.md",
        r"DOSPCoT reached \d+% \(LavaGap\) and \d+% \(DoorKey\) of the oracle's success",
        r"reached (\d+)% \(LavaGap\) and (\d+)% \(DoorKey\)",
        q3_shares,
        "docs/results/queries.md's Q3 lines",
    ),
    Figure(
        "outcomes against the uniform mask",
        "docs/results/index.md",
        r"`outcomes` beat DOSPCoT's uniform mask .*? on the grid",
        r"\(\+([\d.]+) and \+([\d.]+) success, intervals above 0\), but lost ([\d.]+) on the grid",
        lambda s, _: (
            descriptive(s, LAVAGAP, "dospcot outcomes", "dospcot uniform"),
            descriptive(s, DOORKEY, "dospcot outcomes", "dospcot uniform"),
            -descriptive(s, GRID_Q, "dospcot outcomes", "dospcot uniform"),
        ),
        "docs/results/queries.md's descriptive lines",
    ),
    Figure(
        "fast highway labels",
        "docs/results/index.md",
        r"On the fast highway, whose budget grows every round, .*? excludes 0\.",
        r"DOSPCoT's arms bought ([\d,]+) labels a run and self-training's ([\d,]+)",
        lambda s, _: (
            s.labels_bought("queries-fasthighway-dospcot"),
            s.labels_bought("queries-fasthighway-self-training"),
        ),
        "record (labelled_steps of the active arms' runs)",
    ),
    Figure(
        "fast highway seeds",
        "docs/results/index.md",
        r"On the fast highway, whose budget grows every round, .*? excludes 0\.",
        r"with (\d+) seeds no difference",
        lambda s, _: (s.seeds(HIGHWAY_QUERIES),),
        "record (queries-fasthighway sweeps' seeds)",
    ),
    # README.md again
    Figure(
        "fast highway headline labels",
        "README.md",
        r"\| \[queries-highway\]\(docs/results/queries-highway\.md\) \| .*? paired: ",
        r"DOSPCoT disagreement \(([\d,]+) labels a run\) minus self-training uncertainty \(([\d,]+)\)",
        lambda s, _: (
            s.labels_bought("queries-fasthighway-dospcot", {"disagreement"}),
            s.labels_bought("queries-fasthighway-self-training", {"uncertainty"}),
        ),
        "record (labelled_steps of the two arms' runs)",
    ),
    # The CHANGELOG's newest entry
    Figure(
        "defaults study's grid16 success",
        "CHANGELOG.md",
        r"The defaults study's grid16 half has run, .*? pseudo-reward accuracy held\.",
        r"version 2 minus version 1 in success is ([-\d.]+) \[([-\d.]+), ([-\d.]+)\]",
        lambda s, _: tuple(
            float(x)
            for x in s.page_figure(
                "defaults", r"`grid16-dospcot` success: ([-\d.]+) \[([-\d.]+), ([-\d.]+)\] over 20 seeds"
            )
        ),
        "docs/results/defaults.md (grid16's paired difference in success)",
    ),
    Figure(
        "batched-seeds study's saving",
        "CHANGELOG.md",
        r"The batched-seeds study \(.*? short of the \d+x aimed at",
        r"the saving is ([\d.]+)x-([\d.]+)x CPU",
        batched_saving,
        "record (batched-seeds runs' cpu_time_s, alone over batched, per preset)",
    ),
    Figure(
        "batched-seeds study's seeds",
        "CHANGELOG.md",
        r"The batched-seeds study \(\d+ seeds",
        r"\((\d+) seeds",
        lambda s, _: (s.seeds(["batched-seeds-alone", "batched-seeds-batched"]),),
        "record (batched-seeds sweeps' seeds)",
    ),
    Figure(
        "GPU column",
        "CHANGELOG.md",
        r"Measured on an H100 \(issue 48's GPU column\): .*? the target is [\d.]+\)",
        r"the stacked step of 10 members ([\d.]+)x each member's `train\(\)` \(([\d.]+)x on the CPU\).*?"
        r"took ([\d.]+) of the time per seed .*? \(([\d.]+) on the CPU; the target is ([\d.]+)\)",
        lambda s, _: (
            s.gpu(STACKED)[0],
            s.ratio(STACKED),
            s.gpu(BATCHED, "`grid16-dospcot`")[0],
            grid16_batched(s),
            s.target(BATCHED, "`grid16-dospcot`"),
        ),
        "BENCHMARKS.md (stacked-update and grid16 batched-seeds rows, GPU column)",
    ),
    Figure(
        "queries study whole",
        "CHANGELOG.md",
        r"The active-queries study is whole in the record .*? \(queries\)\.",
        r"\((\d+) runs\): the grid's oracle reached the goal in ([\d.]+) of its runs on the unseen layouts, "
        r"DOSPCoT at 2% ([\d.]+) \(uniform mask\) and ([\d.]+) \(queries\)",
        lambda s, _: (
            len(s.runs_of(s.sweeps_of_page("queries"))),
            s.page_cell("queries", GRID_Q, "oracle", "success"),
            s.page_cell("queries", GRID_Q, "dospcot uniform @ 0.02", "success"),
            s.page_cell("queries", GRID_Q, "dospcot disagreement @ 0.02", "success"),
        ),
        "record (the queries page's sweeps) and docs/results/queries.md's grid table",
    ),
    Figure(
        "queries-highway",
        "CHANGELOG.md",
        r"The fast highway's active-queries study .*? over \d+ seeds\.",
        r"\(`queries-highway`, (\d+) runs, no hypothesis\).*? so (\d+)% of the queries came after round 1 .*?"
        r"success \(no crash\) ([\d.]+)-([\d.]+) under the uniform masks, ([\d.]+)-([\d.]+) with uncertainty "
        r"or disagreement, ([\d.]+) for the oracle, no paired interval excluding 0 over (\d+) seeds",
        queries_highway,
        "record and docs/results/queries-highway.md's tables",
    ),
    Figure(
        "queries study's MiniGrid",
        "CHANGELOG.md",
        r"On MiniGrid `outcomes` labelled the goal on every seed but .*? its queries there",
        r"reached (\d+)% \(LavaGap\) and (\d+)% \(DoorKey\) of the oracle's success; co-testing chose (\d+)-(\d+)%",
        lambda s, _: (*q3_shares(s, _), *queries_chosen_on_minigrid(s, _)),
        "docs/results/queries.md (Q3 lines; MiniGrid, DOSPCoT disagreement, chosen by the strategy)",
    ),
    Figure(
        "queries study's descriptive arms",
        "CHANGELOG.md",
        r"on the grid `outcomes` starved the step-cost class .*? of \d+ seeds\.",
        r"\(worst-class precision ([\d.]+)\) and lost -([\d.]+) success .*? grid runs \((\d+)/(\d+)\), and on "
        r"LavaGap `disagreement` and `uncertainty` did on (\d+) of (\d+) seeds",
        lambda s, _: (
            s.page_cell("queries", GRID_Q, "dospcot outcomes @ 0.02", "worst_class_precision"),
            -descriptive(s, GRID_Q, "dospcot outcomes", "dospcot uniform"),
            *map(
                int,
                s.page_figure(
                    "queries",
                    rf"Identical runs \({GRID_Q}\): dospcot disagreement @ 0.02 and dospcot random @ 0.02 trained "
                    r"byte-identical runs \(metrics.csv\) on (\d+) of their (\d+) pairs",
                ),
            ),
            *map(
                int,
                s.page_figure(
                    "queries",
                    rf"Identical runs \({LAVAGAP}\): dospcot disagreement @ 0.1 and dospcot uncertainty @ 0.1 "
                    r"trained byte-identical runs \(metrics.csv\) on (\d+) of their (\d+) pairs",
                ),
            ),
        ),
        "docs/results/queries.md (grid table, descriptive and identical-runs lines)",
    ),
    Figure(
        "outcomes against the uniform mask (CHANGELOG)",
        "CHANGELOG.md",
        r"`outcomes` beat the uniform mask by .*? success",
        r"by \+([\d.]+) \(LavaGap\) and \+([\d.]+) \(DoorKey\) success",
        lambda s, _: (
            descriptive(s, LAVAGAP, "dospcot outcomes", "dospcot uniform"),
            descriptive(s, DOORKEY, "dospcot outcomes", "dospcot uniform"),
        ),
        "docs/results/queries.md's descriptive lines",
    ),
    # runs/README.md
    Figure(
        "the record's size",
        "runs/README.md",
        r"\*\*Its size\*\*.*?\d files",
        r"(\d[\d,]*) sweeps, (\d[\d,]*) runs, (\d[\d,]*) files",
        lambda s, _: (len(s.record.sweeps), len(s.record.runs), len(s.record.files)),
        "record (folders with sweep.json, trials with summary.json, the files .gitignore keeps)",
    ),
    Figure(
        "runs with reward classes",
        "runs/README.md",
        r"[\d,]+ of the record's [\d,]+ co-trained runs have it \(.*?\)",
        r"([\d,]+) of the record's ([\d,]+) co-trained runs have it \(the (.*?) runs predate it\)",
        reward_classes,
        "record (co-trained runs: method dospcot; those with reward_classes.json)",
    ),
    Figure(
        "kept file names",
        "runs/README.md",
        r"except the folders and the \w+ file names above",
        r"the (\w+) file names above",
        lambda s, _: (next(w for w, i in NUMBER_WORDS.items() if i == len(s.record.kept_names)),),
        ".gitignore's record files",
    ),
    # BENCHMARKS.md and the guide's page on it
    Figure(
        "one repetition count for every row",
        "BENCHMARKS.md",
        r"median of \d+ repetitions \[min, max\]",
        r"median of (\d+) repetitions",
        repetitions_of,
        "BENCHMARKS.md's rows (made-by cells, rerun lines)",
        required=False,
    ),
    Figure(
        "one repetition count for every row (guide)",
        "docs/guide/benchmarks.md",
        r"median of \d+ repetitions",
        r"median of (\d+) repetitions",
        lambda s, _: repetitions_of(s, (ROOT / "BENCHMARKS.md").read_text()),
        "BENCHMARKS.md's rows (made-by cells, rerun lines)",
        required=False,
    ),
    # docs/batched_seeds.md
    Figure(
        "batched-seeds rows",
        "docs/batched_seeds.md",
        r"On this project's 2-core machine, 10 seeds of a shortened .*? asked: (?:met|not met)\)",
        r"took ([\d.]+) of the CPU time per seed of runs of their own \(([\d.]+)x; (\d+)x was asked\), the fast "
        r"highway ([\d.]+) \(([\d.]+)x; (\d+)x asked\), and the cell's wall time as two batch processes ([\d.]+) "
        r"of .*? \(([\d.]+)x; (\d+)x asked\)\. A member adds ([\d.]+) of the memory a run of its own adds "
        r"\(at most ([\d.]+)x asked: (met|not met)\)",
        lambda s, _: (
            grid16_batched(s),
            1 / grid16_batched(s),
            1 / s.target(BATCHED, "`grid16-dospcot`"),
            s.ratio(BATCHED, "`fasthighway-dospcot`"),
            1 / s.ratio(BATCHED, "`fasthighway-dospcot`"),
            1 / s.target(BATCHED, "`fasthighway-dospcot`"),
            s.ratio(WALL),
            1 / s.ratio(WALL),
            1 / s.target(WALL),
            s.ratio(MEMORY),
            s.target(MEMORY),
            "met" if s.bench(MEMORY)[6] == "yes" else "not met",
        ),
        "BENCHMARKS.md's batched-seeds rows",
    ),
    Figure(
        "batched-seeds study's science",
        "docs/batched_seeds.md",
        r"Over seeds 0-\d+ of `grid16-dospcot` and `grid16-oracle`, trained both ways, every difference .*? wide on each side",
        r"Over seeds 0-(\d+) of .*? holds 0 and is at most ([\d.]+) wide",
        batched_science,
        "docs/results/batched-seeds.md (its last seed; the bound its differences all held to)",
    ),
    Figure(
        "batched-seeds study's CPU time",
        "docs/batched_seeds.md",
        r"a batched `grid16-dospcot` run took .*? and [\d.]+x\.",
        r"took (\d+) CPU-seconds against (\d+) alone, and `grid16-oracle` (\d+) against (\d+): ([\d.]+)x and ([\d.]+)x",
        lambda s, _: (
            s.cpu_per_run("batched-seeds-batched", "grid16-dospcot"),
            s.cpu_per_run("batched-seeds-alone", "grid16-dospcot"),
            s.cpu_per_run("batched-seeds-batched", "grid16-oracle"),
            s.cpu_per_run("batched-seeds-alone", "grid16-oracle"),
            *batched_saving(s, _),
        ),
        "record (batched-seeds runs' cpu_time_s)",
    ),
    Figure(
        "GPU figures",
        "docs/batched_seeds.md",
        r"On one H100, the stacked gradient step .*? per CPU-second on the CPU\.",
        r"did ([\d.]+)x the member updates .*? \(([\d.]+)x on the CPU\).*? the stacked step's ([\d,]+) updates per "
        r"second are below the ([\d,]+) per CPU-second .*? ran at (\d+) env steps per second on the H100 against "
        r"([\d,]+) per CPU-second",
        lambda s, _: (
            s.gpu(STACKED)[0],
            s.ratio(STACKED),
            s.gpu(STACKED)[1],
            s.ours(STACKED),
            s.gpu(ESARSA_TARGET, WIDE)[1],
            s.ours(ESARSA_TARGET, WIDE),
        ),
        "BENCHMARKS.md (stacked-update and [256, 256] ExpectedSarsaDQN rows, GPU column)",
    ),
    Figure(
        "batched-seeds row on the GPU",
        "docs/batched_seeds.md",
        r"The batched-seeds row on the H100 .*? still short of the issue's [\d.]+",
        r"\((\w+) repetitions?, wall time\).*? took ([\d.]+) s per seed against ([\d.]+) s for each run of its own, "
        r"a ratio of ([\d.]+) where the CPU row reads ([\d.]+); still short of the issue's ([\d.]+)",
        lambda s, _: (
            next(
                w
                for w, i in NUMBER_WORDS.items()
                if i
                == int(
                    re.search(
                        r"median of (\d+) repetitions\) on [\d-]+ [\d:]+ UTC: batched_seeds\.",
                        (ROOT / "BENCHMARKS.md").read_text(),
                    ).group(1)
                )
            ),
            s.gpu(BATCHED, "`grid16-dospcot`")[1],
            s.gpu(BATCHED, "`grid16-dospcot`")[2],
            s.gpu(BATCHED, "`grid16-dospcot`")[0],
            grid16_batched(s),
            s.target(BATCHED, "`grid16-dospcot`"),
        ),
        "BENCHMARKS.md (the grid16 batched-seeds row and its GPU line)",
    ),
    # The guides and the other hand-written pages
    Figure(
        "ExpectedSarsaDQN against DQN",
        "docs/guide/agent.md",
        r"BENCHMARKS\.md times it against SB3's DQN \(.*?batch 256\)",
        r"target: at least ([\d.]+) of DQN's env steps per second of CPU time; (met|not met) at \[64, 64\]",
        lambda s, _: (
            s.target(ESARSA_TARGET, NARROW),
            "met"
            if s.bench(ESARSA_TARGET, NARROW)[6] == s.bench(ESARSA_TARGET, WIDE)[6] == "yes"
            else "not met",
        ),
        "BENCHMARKS.md's two greedy='target' ExpectedSarsaDQN rows",
    ),
    Figure(
        "fast highway's speed",
        "docs/guide/highway.md",
        r"64 at once step [\w ]+ times faster: BENCHMARKS\.md",
        r"step ([\w ]+) times faster",
        lambda s, _: ("several hundred" if 200 <= s.ratio("FastHighwayVec") < 1000 else "other",),
        "BENCHMARKS.md's FastHighwayVec row (its ratio, in hundreds)",
    ),
    Figure(
        "MiniGrid wrappers' speed",
        "docs/your_env.md",
        r"\(BENCHMARKS\.md, [\d.]+ of the bare env's speed against at least [\d.]+\)",
        r"([\d.]+) of the bare env's speed against at least ([\d.]+)",
        lambda s, _: (s.ratio("MiniGrid-LavaGapS7-v0 through"), s.target("MiniGrid-LavaGapS7-v0 through")),
        "BENCHMARKS.md's MiniGrid row",
    ),
    Figure(
        "MiniGrid study's oracle image agent",
        "docs/your_env.md",
        r"where the image agent's study mean is [\d.]+ \(DoorKey\) and [\d.]+ \(LavaGap\)",
        r"is ([\d.]+) \(DoorKey\) and ([\d.]+) \(LavaGap\)",
        lambda s, _: tuple(
            float(s.page_figure("minigrid", rf"\| {task} \| oracle \| image \| ([\d.]+) ")[0])
            for task in (DOORKEY, LAVAGAP)
        ),
        "docs/results/minigrid.md's per-view table (the oracle's image agent)",
    ),
    Figure(
        "MiniGrid study's LavaGap oracle",
        "docs/your_env.md",
        r"at the oracle's level \([\d.]+ in the study\)",
        r"\(([\d.]+) in the study\)",
        lambda s, _: (
            float(
                s.page_figure(
                    "minigrid",
                    rf"\| {LAVAGAP} \| oracle \| `minigrid-lavagap-oracle` \| ([\d.]+) ",
                )[0]
            ),
        ),
        "docs/results/minigrid.md (LavaGap's oracle)",
    ),
    Figure(
        "MiniGrid study's worst class",
        "docs/your_env.md",
        r"the worst class's precision is [\d.]+ in the study's DOSPCoT runs",
        r"precision is ([\d.]+) in",
        lambda s, _: (
            float(
                s.page_figure(
                    "minigrid",
                    rf"\| {LAVAGAP} \| DOSPCoT[^|]* \| `minigrid-lavagap-dospcot` \|(?: [^|]* \|){{3}} ([\d.]+) ",
                )[0]
            ),
        ),
        "docs/results/minigrid.md (LavaGap's DOSPCoT worst-class precision)",
    ),
    Figure(
        "seeds per cell (statistics)",
        "docs/design.md",
        r"With \d+ (?:or|to) \d+ seeds many cells",
        r"With (\d+) (?:or|to) (\d+) seeds",
        lambda s, _: (min(s.record.seeds_per_cell()), max(s.record.seeds_per_cell())),
        "record (each sweep.json's seeds)",
    ),
    Figure(
        "seeds per interval (statistics)",
        "docs/design.md",
        r"A percentile interval from \d+-\d+ seeds",
        r"from (\d+)-(\d+) seeds",
        lambda s, _: (min(s.record.seeds_per_cell()), max(s.record.seeds_per_cell())),
        "record (each sweep.json's seeds)",
    ),
    Figure(
        "second-view highway's rerun",
        "docs/preregistration.md",
        r"\*Second run\*, the study's result .*? both holding 0\.",
        r"self-training \(occupancy\) minus masked-zero \(occupancy\) (-?[\d.]+ \[-?[\d.]+, -?[\d.]+\]), DOSPCoT minus "
        r"masked-zero (-?[\d.]+ \[-?[\d.]+, -?[\d.]+\])",
        lambda s, _: s.page_figure(
            "second-view-highway",
            r"greedy return, self-training \(occupancy\) minus masked-zero \(occupancy\) \(paired by seed\): "
            r"(-?[\d.]+ \[-?[\d.]+, -?[\d.]+\]) - greedy return, DOSPCoT minus masked-zero \(occupancy\) "
            r"\(paired by seed\): (-?[\d.]+ \[-?[\d.]+, -?[\d.]+\])",
        ),
        "docs/results/second-view-highway.md's H3 lines",
    ),
]
"""The prose figures checked against their source, by file."""


def same(written: str, true: object) -> bool:
    """Whether the figure ``written`` states ``true`` (see :class:`Figure`)."""
    if isinstance(true, frozenset):
        return set(re.findall(r"`([^`]+)`", written)) | set(re.findall(r"\]\(([^)]+)\)", written)) == true
    if isinstance(true, list):
        found = re.findall(r"\d[\d,]*(?:\.\d+)?", written)
        return len(found) == len(true) and all(same(f, t) for f, t in zip(found, true, strict=True))
    if isinstance(true, str):
        return written == true
    text = written.strip().lstrip("+").rstrip(".%x").replace(",", "")  # a figure ends its sentence: "0.25."
    if text.lower() in NUMBER_WORDS:
        return NUMBER_WORDS[text.lower()] == true
    decimals = len(text.split(".")[1]) if "." in text else 0
    return abs(float(text) - float(true)) <= 0.5 * 10**-decimals + 1e-9


def problems(figure: Figure, text: str, sources: Sources) -> list[str]:
    """What is wrong with ``figure`` in ``text`` (the file's text): each problem names the file, the
    figure found and the true value; none where every figure holds."""
    body = flat(changelog_newest(text) if figure.file == "CHANGELOG.md" else text)
    sentences = [m.group(0) for m in re.finditer(figure.sentence, body)]
    if not sentences:
        return (
            []
            if not figure.required
            else [f"{figure.file}: {figure.name}: its sentence is not there ({figure.sentence!r})"]
        )
    out = []
    for sentence in sentences:
        match = re.search(figure.figures, sentence)
        if match is None:
            out.append(
                f"{figure.file}: {figure.name}: «{sentence[:200]}» states no figure of the form {figure.figures!r}"
            )
            continue
        truth = figure.truth(sources, text)
        assert len(truth) == len(match.groups()), (
            f"{figure.name}: {len(truth)} true values, {len(match.groups())} figures"
        )
        for written, true in zip(match.groups(), truth, strict=True):
            if not same(written, true):
                shown = (
                    f"{true:.4g}"
                    if isinstance(true, float)
                    else sorted(true)
                    if isinstance(true, frozenset)
                    else true
                )
                out.append(
                    f"{figure.file}: {figure.name}: «{sentence[:200]}» says {written!r}; the {figure.source} gives {shown}"
                )
    return out


@pytest.fixture(scope="module")
def sources() -> Sources:
    return Sources()


@pytest.mark.parametrize("figure", FIGURES, ids=[f"{f.file}: {f.name}" for f in FIGURES])
def test_every_prose_figure_holds_to_its_source(figure, sources):
    assert problems(figure, (ROOT / figure.file).read_text(), sources) == []


@pytest.mark.parametrize(
    "figure", [f for f in FIGURES if f.required], ids=[f.name for f in FIGURES if f.required]
)
def test_each_check_fails_on_a_changed_figure(figure, sources):
    """No check passes whatever the prose says: its first figure changed, the check fails."""
    text = (ROOT / figure.file).read_text()
    body = flat(changelog_newest(text) if figure.file == "CHANGELOG.md" else text)
    sentence = re.search(figure.sentence, body)
    found = re.search(figure.figures, sentence.group(0))
    start = sentence.start() + found.start(1)
    changed = body[:start] + "987654" + body[sentence.start() + found.end(1) :]
    assert problems(figure, changed, sources) != []


def test_runs_readme_size_is_the_records():
    """runs/README.md's size paragraph is what ``dospcot-lab record --write`` writes now."""
    block = read_block((ROOT / "runs" / "README.md").read_text(), SIZE_BLOCK)
    assert block == Record(ROOT).size_paragraph(), "stale: run `dospcot-lab record --write`"


def test_the_reward_classes_sentence_counts_by_hand(tmp_path):
    """Two co-trained runs (one keeps ``reward_classes.json``, one in an older sweep does not) and an
    oracle run: 1 of 2, and the older sweep named."""
    for sweep, trial, method, classes in (
        ("old", "a", "dospcot", False),
        ("new", "b", "dospcot", True),
        ("new", "c", "oracle", False),
    ):
        run = tmp_path / "runs" / "sweeps" / sweep / "trials" / "cfg" / trial
        run.mkdir(parents=True)
        (run / "config.toml").write_text(f'method = "{method}"\n')
        (run / "summary.json").write_text("{}")
        if classes:
            (run / "reward_classes.json").write_text("[0, 1]")
    assert Record(tmp_path).reward_classes_sentence() == (
        "`reward_classes.json`: 1 of the record's 2 co-trained runs have it (the old runs predate it)."
    )


def test_every_benchmark_row_says_how_it_was_made():
    """Each row of BENCHMARKS.md names its benchmark, repetitions, date and commit (its CPU model may
    be not recorded, for rows measured before it was), and the header claims no one repetition count."""
    text = (ROOT / "BENCHMARKS.md").read_text()
    rows = [
        cells(line)
        for line in text.splitlines()
        if line.startswith("| ") and not line.startswith(("| benchmark", "|---"))
    ]
    assert rows
    for row in rows:
        made = Provenance.parse(row[-2])
        assert NOT_RECORDED not in (made.bench, made.repetitions, made.date, made.commit), row[:2]
        assert re.fullmatch(r"\d+", made.repetitions) and re.fullmatch(
            r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", made.date
        )
    assert not re.search(r"median of \d+ repetitions \[min, max\]", text)


def test_each_headline_of_the_results_at_a_glance_is_stated_by_the_page_it_links(sources):
    """Every interval a row of the README's results at a glance gives stands on the study page the
    row links to."""
    assert headline_problems(sources.glance(), lambda study: sources.page(study)) == []
    # A page that lacks its row's interval fails: grid16's page without its headline line.
    page = sources.page("grid16")
    assert "0.100 [0.000, 0.300]" in sources.glance()["grid16"]
    without = page.replace("0.100 [0.000, 0.300]", "")
    assert headline_problems({"grid16": sources.glance()["grid16"]}, lambda _: without) != []


def headline_problems(rows: dict[str, str], page: Callable[[str], str]) -> list[str]:
    out = []
    for study, row in rows.items():
        for interval in re.findall(r"-?\d+\.\d+ \[-?\d+\.\d+, -?\d+\.\d+\]", row.split(" | ")[2]):
            if interval not in page(study):
                out.append(
                    f"README.md: the results at a glance give {study}'s {interval}; docs/results/{study}.md does not"
                )
    return out


# --- the stale figures of commit 700346f ------------------------------------------------------------

STALE_BENCHMARKS = """\
# Benchmarks

Written by `dospcot-lab bench` on 2026-11-24 03:49 UTC.  
Machine: x86_64, torch threads: 1, Python 3.11.7, torch 2.13.0+cpu; no GPU.  
Each figure: median of 3 repetitions [min, max]; ours and the peer alternate in the same run.

Rerun alone by `dospcot-lab bench --only esarsa_dqn --only esarsa_dqn_wide --only esarsa_dqn_online_wide --only esarsa_dqn_q_target --repeats 5` on 2026-11-24 15:56 UTC: esarsa_dqn; esarsa_dqn_wide; esarsa_dqn_online_wide; esarsa_dqn_q_target.

Rerun alone by `dospcot-lab bench --only minigrid_wrappers` on 2026-11-25 04:57 UTC: minigrid_wrappers.

Rerun alone by `dospcot-lab bench --only batched_seeds --only batched_seeds_fasthighway --only batched_wall --only batched_memory --repeats 1` on 2026-11-26 08:31 UTC: batched_seeds; batched_seeds_fasthighway; batched_wall; batched_memory.
"""  # noqa: W291 (the header's lines end in two spaces, Markdown's line break, as the file wrote them)

STALE = [
    (
        "batched CPU per seed",
        ("'1.46'",),
        """seeds in one process, a run folder each ([batched seeds](docs/batched_seeds.md); 1.46x less CPU per
seed than runs of their own in `BENCHMARKS.md`, short of its 4x aim).""",
    ),
    (
        "batched-seeds study's saving",
        ("'1.5'",),
        """## [Unreleased]

- Batched seeds (issue 48, first part): `dospcot train CONFIG --seeds N` trains the seeds of one
  config in lock step in one process, a run folder each (docs/batched_seeds.md): the agents' networks
  stacked per view (`dospcot.policies.stacked_esarsa`), one Adam with a step count per member, each
  member's draws from its own streams; any member's folder resumes the batch. The update equals
  `ExpectedSarsaDQN.train` to 1e-5 for one member; members are independent bit for bit; a batch
  killed with SIGKILL resumes to the same files. `dospcot sweep` and `dospcot-lab study` take
  `--batch-seeds K`. The batched-seeds study (20 seeds of `grid16-dospcot` and `grid16-oracle`,
  alone and batched) finds the same science; the saving is 1.5x-1.9x CPU, short of the 4x aimed at
  (docs/batched_seeds.md). Not yet: batched envs and classifiers.
""",
    ),
    (
        "pre-registered studies",
        ("docs/preregistration-queries.md",),
        """- **Small evidence.** 5 or 10 seeds per cell. The intervals are percentile bootstraps over those
  seeds: wide, narrower than a true 95% interval at such sizes, and not corrected for the many
  comparisons a study makes. Only the second-view study's tests were fixed before its runs
  ([pre-registration](docs/preregistration.md)).""",
    ),
    (
        "seeds per cell",
        ("'5 or 10'", "[3, 5, 10, 20, 40, 100]"),
        """- **Small evidence.** 5 or 10 seeds per cell. The intervals are percentile bootstraps over those
  seeds: wide, narrower than a true 95% interval at such sizes, and not corrected for the many
  comparisons a study makes. Only the second-view study's tests were fixed before its runs
  ([pre-registration](docs/preregistration.md)).""",
    ),
    (
        "the record's size",
        ("'20'", "'850'", "'4,585'"),
        """**Its size** (measured on 2026-11-26 from a clean checkout, `git ls-files runs/sweeps | wc -l` and
the files' sizes summed): 20 sweeps, 850 runs, 4,585 files, 5.7 MB of content, about 6.7 kB a
run (`metrics.csv` 2.6 MB, `config.toml` 1.3 MB, `summary.json` 1.1 MB, `run_info.json` 0.37 MB,
`trial.json` 0.23 MB, `reward_classes.json` 16 kB, `sweep.json` 6 kB). On a disk with 4 kB blocks
that takes 23 MB (`du -sh runs/sweeps`, which also counts any ignored files a run left there).""",
    ),
    (
        "runs with reward classes",
        ("'315'", "'475'"),
        """| `reward_classes.json` | a co-trained run's reward value of each class | the MiniGrid table's goal-label line; 315 of the record's 475 co-trained runs have it (the grid16, grid16-layouts, grid32 and label-fraction runs predate it) |""",
    ),
    ("one repetition count for every row", ("'3'", "[1, 3, 5]"), STALE_BENCHMARKS),
    (
        "fast highway labels",
        ("states no figure",),
        """  On the fast highway, whose budget grows every round, the strategies did choose (`queries-highway`,
  no hypothesis): uncertainty and disagreement had the highest success after the oracle's, but with
  5 seeds no difference excludes 0.""",
    ),
    (
        "fast highway headline labels",
        ("states no figure",),
        """| [queries-highway](docs/results/queries-highway.md) | fast highway | success, DOSPCoT disagreement minus self-training uncertainty, paired: -0.030 [-0.170, 0.150] | 5 (0-4) | no hypothesis |""",
    ),
]
"""Each stale figure issue 60 lists, as its sentence stood at commit 700346f (``git show
700346f:<file>``): the check it must fail, and what the failure names."""


@pytest.mark.parametrize("name, named, stale", STALE, ids=[f"{n}: {w[0]}" for n, w, _ in STALE])
def test_each_stale_figure_of_700346f_fails_its_check(name, named, stale, sources):
    """The check fails on the sentence as it stood at 700346f, naming the stale figure (and the true
    value where it names one), and passes on the file as it is now."""
    figure = next(f for f in FIGURES if f.name == name)
    found = problems(figure, stale, sources)
    assert found, f"{figure.name}: the stale text passed"
    for words in named:
        assert any(words in problem for problem in found), (words, found)
    # The same check passes on the file as it is now.
    assert problems(figure, (ROOT / figure.file).read_text(), sources) == []
