"""Whether a confirmatory study's runs came after its preregistration: the commit that first added the
preregistration's page, and for each run whether every source commit that trained it descends from
that commit (``git merge-base --is-ancestor``). A run's source commits are its ``run_info.json``'s
(one per session that trained it)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.provenance import session_commits


def _git(checkout: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", "-C", str(checkout), *args], capture_output=True, text=True, check=False)


def added_in(page: str, checkout: Path) -> str | None:
    """The commit that first added ``page`` (a path from the repository's root) in the git history of
    the checkout holding ``checkout``; None where it was never committed, or no checkout holds it."""
    found = _git(checkout, "log", "--diff-filter=A", "--format=%H", "--", f":(top){page}")
    commits = found.stdout.split() if found.returncode == 0 else []
    return commits[-1] if commits else None


def descends(commit: str, ancestor: str, checkout: Path) -> bool:
    """Whether ``commit`` is ``ancestor`` or one of its descendants (False where either is unknown)."""
    return _git(checkout, "merge-base", "--is-ancestor", ancestor, commit).returncode == 0


def source_commits(run: TrialRun) -> list[str | None]:
    """The commits that trained ``run``, one per session (``"+dirty"`` dropped; None: not recorded)."""
    info = json.loads((run.run_dir / "run_info.json").read_text())
    return [c.partition("+")[0] if c else None for c in session_commits(info)]


def preregistered_line(runs: list[TrialRun], page: str, checkout: Path) -> str:
    """The page header's line on the preregistration: where it was first committed and how many of
    ``runs`` were trained only from source that descends from that commit, naming those that were not."""
    added = added_in(page, checkout)
    if added is None:
        return f"Preregistration: `{page}` is not committed; no run can be said to follow it."
    trained_by = {r.run_dir: source_commits(r) for r in runs}
    # One git call per distinct commit, not per run: a study's runs share a few commits.
    after = {c: descends(c, added, checkout) for c in {c for cs in trained_by.values() for c in cs if c}}
    late = [r for r in runs if not all(c is not None and after[c] for c in trained_by[r.run_dir])]
    line = (
        f"Preregistration: `{page}`, first committed in {added[:7]}; {len(runs) - len(late)} of "
        f"{len(runs)} runs trained only from source that descends from that commit"
    )
    if late:
        # A trial's folder lies at <sweep>/trials/<config>/<trial>.
        named = ", ".join(f"`{r.run_dir.parents[2].name}` seed {r.trial.seed}" for r in late[:5])
        line += f"; not: {named}" + (f" and {len(late) - 5} more" if len(late) > 5 else "")
    return line + "."
