"""Where ``--docs`` writes: the checkout's ``docs/`` and the generated blocks of its README.md, the
text between a start and an end marker."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
"""The checkout this package sits in (an editable install): ``--docs`` writes its docs/ and README.md."""
README = ROOT / "README.md"


def check_readme_block(start: str, end: str) -> None:
    """Raise ``ValueError`` unless README.md holds the ``start`` marker once, then ``end`` once."""
    readme = README.read_text()
    if readme.count(start) != 1 or readme.count(end) != 1 or readme.index(start) > readme.index(end):
        raise ValueError(f"README.md needs one {start!r} line and, after it, one {end!r} line")


def replace_readme_block(start: str, end: str, text: str) -> None:
    """Put ``text`` between the ``start`` and ``end`` marker lines of README.md, keeping the rest."""
    check_readme_block(start, end)
    head, rest = README.read_text().split(start)
    _, tail = rest.split(end)
    README.write_text(f"{head}{start}\n{text.rstrip()}\n{end}{tail}")
