"""The checkout of the dospcot repository that the lab reads and writes: its README, its study pages
(``docs/results/``), its record (``runs/sweeps/``) and its BENCHMARKS.md. The lab finds it from the
working folder (or ``--repo``), never from where its own code lies, so an installed lab writes into no
checkout it was not pointed at."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path


class NotARepository(ValueError):
    """A folder that is not (inside) a checkout of the dospcot repository."""


@dataclass(frozen=True)
class Repository:
    """A checkout of the dospcot repository, rooted at ``root``."""

    root: Path

    @property
    def readme(self) -> Path:
        """README.md: its results at a glance and its paper-protocol block are generated."""
        return self.root / "README.md"

    @property
    def results(self) -> Path:
        """``docs/results/``: a page per study and ``index.md``, the results at a glance."""
        return self.root / "docs" / "results"

    @property
    def runs_readme(self) -> Path:
        """``runs/README.md``: what the record holds, and its size."""
        return self.root / "runs" / "README.md"

    @property
    def benchmarks(self) -> Path:
        """BENCHMARKS.md: the benchmark rows."""
        return self.root / "BENCHMARKS.md"


def is_repository(folder: Path) -> bool:
    """Whether ``folder`` is the root of a checkout of the dospcot repository: its ``pyproject.toml``
    names the ``dospcot`` project and the lab's own lies in ``lab/``."""
    try:
        project = tomllib.loads((folder / "pyproject.toml").read_text()).get("project", {})
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return project.get("name") == "dospcot" and (folder / "lab" / "pyproject.toml").is_file()


def find_repository(start: Path | None = None) -> Repository:
    """The checkout holding ``start`` (default: the working folder), found by walking up from it.

    :raises NotARepository: no folder from ``start`` up is a checkout of the repository.
    """
    start = (start or Path.cwd()).resolve()
    for folder in (start, *start.parents):
        if is_repository(folder):
            return Repository(folder)
    raise NotARepository(
        f"{start} is not inside a checkout of the dospcot repository (a folder whose pyproject.toml names "
        "the dospcot project, with lab/ beside it): run from the checkout, or give --repo"
    )


def repository_at(root: Path) -> Repository:
    """The checkout rooted at ``root`` exactly (``--repo``).

    :raises NotARepository: ``root`` is not the root of a checkout.
    """
    if not is_repository(root):
        raise NotARepository(
            f"--repo {root}: not the root of a checkout of the dospcot repository (its pyproject.toml "
            "names the dospcot project, with lab/ beside it)"
        )
    return Repository(root.resolve())
