"""The generated blocks that ``--docs`` writes into README.md and ``docs/results/index.md``: each the
text between a start and an end marker line."""

from __future__ import annotations

from pathlib import Path


def markers(name: str) -> tuple[str, str]:
    """The start and end marker lines of the generated block ``name``."""
    return f"<!-- {name}:start -->", f"<!-- {name}:end -->"


def read_block(path: Path, name: str) -> str:
    """The text between the markers of block ``name`` in ``path``; ``ValueError`` unless the file holds
    the start marker once and, after it, the end marker once."""
    start, end = markers(name)
    text = path.read_text()
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise ValueError(f"{path.name} needs one {start!r} line and, after it, one {end!r} line")
    return text.split(start)[1].split(end)[0].strip("\n")


def replace_block(path: Path, name: str, text: str) -> None:
    """Put ``text`` between the markers of block ``name`` in ``path``, keeping the rest."""
    read_block(path, name)  # checks the markers
    start, end = markers(name)
    head, rest = path.read_text().split(start)
    _, tail = rest.split(end)
    path.write_text(f"{head}{start}\n{text.rstrip()}\n{end}{tail}")
