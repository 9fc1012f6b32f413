"""A confirmatory study's preregistration check (lab/studies/preregistration.py), on a git history built
here: the commit that first added the page, and which runs were trained only from its descendants."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies.preregistration import added_in, descends, preregistered_line

PAGE = "docs/preregistration-x.md"


def _commit(repo: Path, message: str) -> str:
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-q", "--allow-empty", "-m", message], check=True)
    return subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()


def _run(repo: Path, seed: int, info: dict[str, object]) -> TrialRun:
    run_dir = repo / "runs" / "sweeps" / "confirm" / "trials" / "preset" / f"seed={seed}"
    run_dir.mkdir(parents=True)
    (run_dir / "run_info.json").write_text(json.dumps(info))
    return TrialRun(Trial("preset", "preset", {}, seed), {}, [], run_dir)


def test_runs_count_as_preregistered_only_when_every_session_descends_from_the_page(tmp_path):
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    (tmp_path / "code.py").write_text("x = 1\n")
    before = _commit(tmp_path, "code")
    assert added_in(PAGE, tmp_path) is None
    (tmp_path / "docs").mkdir()
    (tmp_path / PAGE).write_text("hypotheses\n")
    page = _commit(tmp_path, "preregistration")
    (tmp_path / PAGE).write_text("hypotheses, amended\n")  # a later edit does not move "first added"
    after = _commit(tmp_path, "more code")
    assert added_in(PAGE, tmp_path) == page
    assert added_in(PAGE, tmp_path / "docs") == page  # the path is from the root, wherever git is asked
    assert descends(after, page, tmp_path) and descends(page, page, tmp_path)
    assert not descends(before, page, tmp_path) and not descends("0" * 40, page, tmp_path)

    runs = [
        _run(tmp_path, 0, {"commit": after}),
        _run(tmp_path, 1, {"commit": before}),
        _run(tmp_path, 2, {"session_commits": [page, after + "+dirty"]}),
        _run(tmp_path, 3, {"session_commits": [before, after]}),  # resumed: one session came before
        _run(tmp_path, 4, {}),  # no commit recorded
    ]
    assert preregistered_line(runs, PAGE, runs[0].run_dir) == (
        f"Preregistration: `{PAGE}`, first committed in {page[:7]}; 2 of 5 runs trained only from "
        "source that descends from that commit; not: `confirm` seed 1, `confirm` seed 3, `confirm` seed 4."
    )
    assert preregistered_line(runs, "docs/other.md", tmp_path) == (
        "Preregistration: `docs/other.md` is not committed; no run can be said to follow it."
    )
