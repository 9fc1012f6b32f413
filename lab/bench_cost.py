"""The cost rows of ``dospcot-lab bench``: a DOSPCoT run against its agents trained alone (a
self-training run on each of its views), and this release against the last, in CPU time and peak memory
of whole ``dospcot train`` runs.

Each run is a ``dospcot train`` subprocess on one torch thread, in a temporary folder, at its preset's
full length (``--quick``: two rounds). Its CPU time (user + system) and peak resident memory come from
``os.wait4``, so they count the run from the interpreter's start, imports included, as a user's run
costs. The last release runs from its own install: the source of commit :data:`LAST_RELEASE`
(``git archive``) installed once with ``pip install --no-deps --target`` into a folder under the
user's cache, put first on ``PYTHONPATH``. A run trained for one row serves every row that needs it
(the same preset, seed and release), so the three rows of a task cost one set of runs.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from dospcot.tasks import load_config
from dospcot_lab.bench_measure import Row
from dospcot_lab.repository import find_repository

LAST_RELEASE = "700346f"
"""The last release before the agents' cost work, the peer of the release rows."""
COST_TASKS: dict[str, tuple[str, str]] = {
    "grid16": ("grid16-dospcot", "grid16-self-training"),
    "doorkey": ("minigrid-doorkey-dospcot", "minigrid-doorkey-self-training"),
    "lavagap": ("minigrid-lavagap-dospcot", "minigrid-lavagap-self-training"),
    "fasthighway": ("fasthighway-dospcot", "fasthighway-self-training"),
}
"""Each task's DOSPCoT preset and its one-agent peer, trained on each of the DOSPCoT preset's views."""
COST_TARGET = 1.15
"""A DOSPCoT run's CPU time over the sum of its views' self-training runs, at most: co-training may add
at most 15% to what its agents cost alone (the agents-cost issue's bar)."""
RELEASE_TARGETS = {"grid16": 1.0, "doorkey": 0.5, "lavagap": 0.5, "fasthighway": 0.5}
"""This release's CPU per DOSPCoT run over the last release's, at most: at least 2x less on the MiniGrid
tasks and the fast highway (the agents-cost issue's bar), no slower on grid16."""
MEMORY_TARGET = 1 / 3
"""A LavaGap DOSPCoT run's peak memory over the last release's, at most (3x less)."""
QUICK = ("training.rounds=2",)
SEEDS, QUICK_SEEDS = 3, 1


def release_site(commit: str = LAST_RELEASE) -> Path:
    """A folder holding ``commit``'s package, installed once (``pip --target``) into the cache.

    :raises RuntimeError: the checkout the working folder lies in does not hold ``commit``, or the
        install fails.
    :raises NotARepository: the working folder lies in no checkout of the repository.
    """
    site = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dospcot" / "releases" / commit
    if (site / "dospcot").is_dir():
        return site
    root = find_repository().root
    with tempfile.TemporaryDirectory() as source:
        archive = subprocess.run(["git", "-C", str(root), "archive", commit], capture_output=True)
        if archive.returncode != 0:
            raise RuntimeError(
                f"the release rows install commit {commit} from this checkout's git history, which "
                f"{root} lacks: {archive.stderr.decode().strip()}"
            )
        subprocess.run(["tar", "-x", "-C", source], input=archive.stdout, check=True)
        pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation"]
        installed = subprocess.run([*pip, "--target", str(site), source], capture_output=True, text=True)
        if installed.returncode != 0:
            raise RuntimeError(f"installing {commit} into {site} failed: {installed.stderr.strip()}")
    return site


@functools.cache
def trained(
    preset: str, seed: int, release: str | None, quick: bool, views: tuple[str, ...] = ()
) -> tuple[float, float]:
    """CPU seconds and peak resident MiB of one ``dospcot train`` run of ``preset`` at ``seed``, by
    this code (``release`` None) or by commit ``release``'s install (:func:`release_site`).

    :param views: the views the run trains on, in place of the preset's (none: the preset's).
    """
    env = dict(os.environ)
    if release is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(release_site(release)), env.get("PYTHONPATH")]))
    overrides = [f"seed={seed}", *(QUICK if quick else ())]
    if views:
        overrides.append("views=[" + ", ".join(f'"{view}"' for view in views) + "]")
    with tempfile.TemporaryDirectory() as folder:
        command = [sys.executable, "-m", "dospcot", "train", preset, "--runs-dir", folder, "--no-progress"]
        command += [arg for key in overrides for arg in ("--set", key)]
        log = Path(folder) / "stderr.txt"
        # The folder as the working directory: a checkout's own dospcot/ must not shadow the install.
        with log.open("w") as stderr:
            process = subprocess.Popen(command, cwd=folder, env=env, stdout=subprocess.DEVNULL, stderr=stderr)
            _, status, usage = os.wait4(process.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            what = release or "this release"
            raise RuntimeError(f"{' '.join(command)} failed ({what}): {log.read_text()[-2000:]}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024  # Linux gives ru_maxrss in KiB


def _seeds(quick: bool) -> range:
    return range(QUICK_SEEDS if quick else SEEDS)


def _length(quick: bool) -> str:
    return "two rounds (`--quick`)" if quick else "the preset's full length"


def bench_cost(task: str, quick: bool, repeats: int) -> Row:
    """A DOSPCoT run's CPU time against its agents' trained alone: per seed, the sum of a self-training
    run on each of its views (``repeats`` unused: the seeds are the repetitions)."""
    dospcot, single = COST_TASKS[task]
    views = load_config(dospcot).views
    ours = [trained(dospcot, seed, None, quick)[0] for seed in _seeds(quick)]
    peer = [sum(trained(single, seed, None, quick, (view,))[0] for view in views) for seed in _seeds(quick)]
    return Row.measured(
        "A DOSPCoT run vs its agents alone (a self-training run per view): CPU time per run",
        f"`{dospcot}` vs `{single}` on {' and '.join(f'`{view}`' for view in views)}, summed per seed, "
        f"{_length(quick)}, seeds 0-{len(ours) - 1}, `dospcot train` on one thread",
        "s",
        ours,
        peer,
        higher_is_better=False,
        target=COST_TARGET,
    )


def bench_release(task: str, quick: bool, repeats: int, memory: bool = False) -> Row:
    """This release's CPU time (or, ``memory``, peak resident memory) per DOSPCoT run of ``task``
    against the last release's, the same seeds (``repeats`` unused: the seeds are the repetitions)."""
    dospcot, figure = COST_TASKS[task][0], int(memory)
    ours = [trained(dospcot, seed, None, quick)[figure] for seed in _seeds(quick)]
    peer = [trained(dospcot, seed, LAST_RELEASE, quick)[figure] for seed in _seeds(quick)]
    what, how = (
        ("peak memory", "the process's peak resident memory")
        if memory
        else ("CPU time", "`dospcot train` on one thread")
    )
    return Row.measured(
        f"This release vs the last ({LAST_RELEASE}): {what} per DOSPCoT run",
        f"`{dospcot}`, {_length(quick)}, seeds 0-{len(ours) - 1}, {how}",
        "MiB" if memory else "s",
        ours,
        peer,
        higher_is_better=False,
        target=round(MEMORY_TARGET, 3) if memory else RELEASE_TARGETS[task],
    )
