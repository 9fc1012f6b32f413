"""Copy a `dospcot reproduce-paper` run's tables into the repository's docs and README.

    python scripts/paper_tables_to_docs.py runs/paper/<stamp> [--preset-doc docs/paper-reproduction.md]

The full tables.md goes to ``docs/paper-reproduction-<preset>.md``; for the paper-text preset, the
target line and the paper-accuracy and agreement tables also replace the block between the
``<!-- paper-tables:start -->`` and ``<!-- paper-tables:end -->`` markers of README.md. No number is
typed by hand.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from readme_block import replace_readme_block

ROOT = Path(__file__).resolve().parent.parent
START, END = "<!-- paper-tables:start -->", "<!-- paper-tables:end -->"


def section(text: str, heading: str) -> str:
    """The markdown from ``heading`` to the next heading of the same or a higher level."""
    level = heading.split(" ")[0]
    start = text.index(heading)
    rest = text[start + len(heading) :]
    match = re.search(rf"^#{{1,{len(level)}}} ", rest, flags=re.MULTILINE)
    return (heading + (rest[: match.start()] if match else rest)).strip()


def demote(markdown: str, levels: int = 2) -> str:
    """Push every heading ``levels`` deeper, so the tables nest under the README's own headings."""
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m.group(1)) + levels) + " ", markdown, flags=re.MULTILINE)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run_dir", type=Path)
    args = parser.parse_args()
    tables = (args.run_dir / "tables.md").read_text()
    config = json.loads((args.run_dir / "config.json").read_text())
    preset = config["preset"]
    (ROOT / "docs" / f"paper-reproduction-{preset}.md").write_text(tables + "\n")
    if preset != "paper-text":
        return
    header = tables.split("## ")[0].replace("# Seed paper reproduction: masked CliffWalking-v1", "").strip()
    accuracy = section(tables, "## Paper accuracy")
    agreement = section(tables, "## Optimal-action agreement")
    block = "\n\n".join(
        [
            header,
            demote(accuracy),
            "#### Optimal-action agreement, Table 3 (after 5 rounds)",
            section(agreement, "### Table 3").split("\n", 1)[1].strip(),
        ]
    )
    replace_readme_block(START, END, block)


if __name__ == "__main__":
    main()
