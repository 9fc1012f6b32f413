"""Replace a generated block of README.md, the text between a start and an end marker."""

from __future__ import annotations

from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def replace_readme_block(start: str, end: str, text: str) -> None:
    """Put ``text`` between the ``start`` and ``end`` marker lines of README.md, keeping the rest."""
    readme = README.read_text()
    head, rest = readme.split(start)
    _, tail = rest.split(end)
    README.write_text(f"{head}{start}\n{text.rstrip()}\n{end}{tail}")
