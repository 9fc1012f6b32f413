"""The lab writes only where it is told: it finds the checkout from the working folder or ``--repo``,
never from where its code lies; run outside a checkout it writes nowhere but its runs folder; and
``--docs`` never replaces a published study page with an empty one."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from dospcot_lab.cli import main
from dospcot_lab.repository import NotARepository, find_repository, repository_at
from dospcot_lab.studies.pages import UNPUBLISHED

ROOT = Path(__file__).resolve().parents[2]


def _tree(folder: Path) -> dict[str, str]:
    return {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


def _checkout(folder: Path, page: str) -> Path:
    """A minimal checkout: what the lab reads to know one, the generated blocks, and grid16's page."""
    (folder / "lab").mkdir(parents=True)
    (folder / "pyproject.toml").write_text('[project]\nname = "dospcot"\n')
    (folder / "lab" / "pyproject.toml").write_text('[project]\nname = "dospcot-lab"\n')
    glance = "<!-- results-at-a-glance:start -->\n<!-- results-at-a-glance:end -->\n"
    (folder / "README.md").write_text(f"# dospcot\n\n{glance}")
    (folder / "docs" / "results").mkdir(parents=True)
    (folder / "docs" / "results" / "index.md").write_text(glance)
    (folder / "docs" / "results" / "grid16.md").write_text(page)
    return folder


def test_the_checkout_is_found_from_the_working_folder_not_from_the_code(tmp_path, monkeypatch):
    assert find_repository(ROOT / "docs" / "results").root == ROOT
    monkeypatch.chdir(tmp_path)
    with pytest.raises(NotARepository, match="not inside a checkout of the dospcot repository"):
        find_repository()
    with pytest.raises(NotARepository, match="--repo"):
        repository_at(tmp_path)
    assert repository_at(_checkout(tmp_path / "repo", "page")).root == (tmp_path / "repo").resolve()


def test_outside_a_checkout_a_study_writes_nowhere_but_its_runs_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["study", "grid16", "--render-only", "--docs"]) == 2
    assert "not inside a checkout of the dospcot repository" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="no finished run of this study under runs/sweeps"):
        main(["study", "grid16", "--render-only"])
    assert list(tmp_path.iterdir()) == []
    assert main(["record"]) == 2 and main(["bench", "--only", "tabular"]) == 2
    assert list(tmp_path.iterdir()) == []


def test_docs_keeps_a_published_page_when_the_runs_folder_lacks_the_studys_runs(tmp_path):
    repo = _checkout(tmp_path / "repo", "# The 16 x 16 grid study\n\n| published | table |\n")
    runs = tmp_path / "runs"
    runs.mkdir()
    before = _tree(repo)
    with pytest.raises(SystemExit, match="publishes its tables: --docs keeps a published page"):
        main(["--repo", str(repo), "study", "grid16", "--render-only", "--docs", "--runs-dir", str(runs)])
    assert _tree(repo) == before and list(runs.iterdir()) == []


def test_docs_writes_an_unpublished_page_only_over_an_unpublished_one(tmp_path):
    repo = _checkout(tmp_path / "repo", f"# The 16 x 16 grid study\n\n{UNPUBLISHED}, so this page ...\n")
    runs = tmp_path / "runs"
    runs.mkdir()
    assert (
        main(["--repo", str(repo), "study", "grid16", "--render-only", "--docs", "--runs-dir", str(runs)])
        == 0
    )
    page = (repo / "docs" / "results" / "grid16.md").read_text()
    assert UNPUBLISHED in page and "dospcot-lab study grid16 --docs" in page
