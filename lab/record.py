"""The record's own figures, counted from its files (``runs/sweeps/``, runs/README.md): its sweeps,
runs, files and bytes, and how many co-trained runs keep ``reward_classes.json``; and the block of
runs/README.md they fill.

``dospcot-lab record --write`` writes the block (between its markers) from the record as it is;
``tests/lab/test_prose_figures.py`` fails while the block is stale, and checks the prose figures that
restate the record elsewhere against the functions here. Nothing here trains or imports torch.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections import Counter
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from dospcot.config.choices import method_name

SIZE_BLOCK = "record-size"
"""The generated block of runs/README.md: the record's size."""
BLOCK = 4096
"""The disk block the size's last figure counts in (bytes)."""


@dataclass(frozen=True)
class Record:
    """The record under ``root`` (a checkout): what its sweeps and runs hold, read from its files."""

    root: Path

    @property
    def sweeps_dir(self) -> Path:
        """``runs/sweeps/``: a folder per sweep."""
        return self.root / "runs" / "sweeps"

    @cached_property
    def sweeps(self) -> list[Path]:
        """The sweeps: the folders of ``runs/sweeps/`` that hold a ``sweep.json``."""
        return sorted(p.parent for p in self.sweeps_dir.glob("*/sweep.json"))

    @cached_property
    def runs(self) -> list[Path]:
        """The runs: the trial folders (``<sweep>/trials/<config>/<trial>/``) of finished trials, those
        holding ``summary.json``, written last (a trial of the paper's protocol is one seed's 26 tabular
        runs in one folder, and counts once)."""
        return sorted(p.parent for p in self.sweeps_dir.glob("*/trials/*/*/summary.json"))

    @cached_property
    def kept_names(self) -> list[str]:
        """The file names ``.gitignore`` lets through of the record (its ``!runs/sweeps/...`` lines)."""
        lines = (self.root / ".gitignore").read_text().splitlines()
        return [
            line.rsplit("/", 1)[1]
            for line in lines
            if line.startswith("!runs/sweeps/") and not line.endswith("/")
        ]

    @cached_property
    def files(self) -> list[Path]:
        """The record's files: those of the kept names where ``.gitignore`` lets them through (a clean
        checkout's ``git ls-files runs/sweeps``; ignored files a run left beside them are not counted)."""
        lines = (self.root / ".gitignore").read_text().splitlines()
        patterns = [line[1:] for line in lines if line.startswith("!runs/sweeps/") and not line.endswith("/")]
        return sorted({path for pattern in patterns for path in self.root.glob(pattern)})

    def method(self, run: Path) -> str:
        """A run's ``method`` (``dospcot``, ``oracle``, ...), from its ``config.toml``; ``"paper"`` for a
        seed of the paper's protocol, whose config has none."""
        config = tomllib.loads((run / "config.toml").read_text())
        return method_name(config.get("method", "paper"))

    @cached_property
    def cotrained(self) -> list[Path]:
        """The co-trained runs (``method = "dospcot"``: self-training, DOSPCoT and m >= 3 views): those
        with reward classifiers, which write ``reward_classes.json``."""
        return [run for run in self.runs if self.method(run) == "dospcot"]

    def with_file(self, runs: list[Path], name: str) -> list[Path]:
        """The runs of ``runs`` that keep file ``name``."""
        return [run for run in runs if (run / name).is_file()]

    def sweep_of(self, run: Path) -> str:
        """The name of the sweep a run belongs to."""
        return run.relative_to(self.sweeps_dir).parts[0]

    def seeds_per_cell(self) -> list[int]:
        """The distinct numbers of seeds the record's sweeps give each cell (``sweep.json``'s seeds)."""
        counts = {len(json.loads((sweep / "sweep.json").read_text())["seeds"]) for sweep in self.sweeps}
        return sorted(counts)

    def cpu_seconds(self, sweeps: list[str]) -> float:
        """The CPU seconds the finished runs of ``sweeps`` trained for (``run_info.json``'s
        ``cpu_time_s``; ``ValueError`` where a run did not record it)."""
        total = 0.0
        for run in self.runs:
            if self.sweep_of(run) in sweeps:
                info = json.loads((run / "run_info.json").read_text())
                if "cpu_time_s" not in info:
                    raise ValueError(f"{run} recorded no cpu_time_s")
                total += info["cpu_time_s"]
        return total

    def size_paragraph(self) -> str:
        """The paragraph of runs/README.md that says how large the record is, from its files."""
        sizes = Counter()
        for path in self.files:
            sizes[path.name] += path.stat().st_size
        total = sum(sizes.values())
        per_name = ", ".join(f"`{name}` {_bytes(size)}" for name, size in sizes.most_common())
        folders = {parent for path in self.files for parent in path.relative_to(self.sweeps_dir).parents}
        blocks = sum(math.ceil(path.stat().st_size / BLOCK) for path in self.files) + len(folders)
        run = _bytes(total / len(self.runs))
        disk = blocks * BLOCK / 2**20
        return (
            "**Its size**, counted from its files by `dospcot-lab record --write` (which writes "
            f"this paragraph; a test fails while it is stale): {len(self.sweeps)} sweeps, "
            f"{len(self.runs):,} runs, {len(self.files):,} files, {_bytes(total)} of content, about {run} a "
            f"run ({per_name}). On a disk with {BLOCK // 1024} kB blocks, each file and folder rounded up "
            f"to whole blocks, that takes about {disk:.0f} MiB (`du -sh runs/sweeps` on such a disk, which "
            "also counts any ignored files a run left there). "
            f"{self.reward_classes_sentence()}"
        )

    def reward_classes_sentence(self) -> str:
        """How many co-trained runs keep ``reward_classes.json``, and the sweeps of those that predate
        it."""
        kept = set(self.with_file(self.cotrained, "reward_classes.json"))
        lacking = sorted({self.sweep_of(run) for run in self.cotrained if run not in kept})
        predate = f" (the {english(lacking)} runs predate it)" if lacking else ""
        return (
            f"`reward_classes.json`: {len(kept):,} of the record's {len(self.cotrained):,} co-trained "
            f"runs have it{predate}."
        )


def english(items: list[str]) -> str:
    """``["a", "b", "c"]`` as ``"a, b and c"``."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def _bytes(size: float) -> str:
    """``size`` bytes in MB (at least 1 MB) or kB, as runs/README.md gives them."""
    if size >= 1e6:
        return f"{size / 1e6:.1f} MB"
    return f"{size / 1e3:.0f} kB" if size >= 1e4 else f"{size / 1e3:.1f} kB"


def markers(name: str) -> tuple[str, str]:
    """The start and end marker lines of the generated block ``name`` (as the study pages' blocks)."""
    return f"<!-- {name}:start -->", f"<!-- {name}:end -->"


def read_block(text: str, name: str) -> str:
    """The text between the markers of block ``name`` in ``text``; ``ValueError`` unless it holds the
    start marker once and, after it, the end marker once."""
    start, end = markers(name)
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise ValueError(f"needs one {start!r} line and, after it, one {end!r} line")
    return text.split(start)[1].split(end)[0].strip("\n")


def write_size(record: Record, readme: Path) -> None:
    """Write ``record``'s size paragraph into ``readme``'s block, keeping the rest."""
    text = readme.read_text()
    read_block(text, SIZE_BLOCK)  # checks the markers
    start, end = markers(SIZE_BLOCK)
    head, rest = text.split(start)
    _, tail = rest.split(end)
    readme.write_text(f"{head}{start}\n{record.size_paragraph()}\n{end}{tail}")
