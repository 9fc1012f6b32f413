"""The files of a run folder (docs/design.md section 5), each written atomically.

Every file is written to a temporary name in the same folder and renamed over its target with
:func:`os.replace`, so a run killed at any moment leaves each file either whole and old or whole and
new, never half-written.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import pickle
import platform
import subprocess
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import cache, partial
from pathlib import Path
from typing import IO, Any

import stable_baselines3
import tomli_w
import torch

import dospcot

CONFIG_FILE = "config.toml"
METRICS_FILE = "metrics.csv"
SUMMARY_FILE = "summary.json"
REWARD_CLASSES_FILE = "reward_classes.json"
QUERIES_FILE = "queries.csv"
"""Every label a rater gave: round, sample, how it was chosen, answer (active label strategies)."""
PSEUDO_REWARDS_FILE = "pseudo_rewards.csv"
"""Each round's pseudo-rewards per hidden reward class (runs that learn rewards, single-step labels)."""
CHECKPOINT_FILE = "checkpoint.pkl"
CHECKPOINT_FORMAT = 1
LOCK_FILE = ".lock"
TMP_SUFFIX = ".partial"
"""The ending of a run folder still being made (:func:`new_run_dir`)."""
BATCH_FILE = "batch.json"
"""In each member's folder while its batch is unfinished: every member's folder (resume reads it)."""


class RunFolderError(RuntimeError):
    """A run folder that cannot be read: missing, incomplete or corrupt files (message is one line)."""


def atomic_write(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` through ``write(file)`` into a temporary file, then rename it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes files private; run files are for sharing
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def remove_stale_temporaries(folder: Path) -> None:
    """Delete the temporary files of writes that a kill interrupted (never a finished file)."""
    for path in folder.glob(".*.tmp"):
        path.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (:func:`atomic_write`)."""
    atomic_write(path, lambda handle: handle.write(text.encode()))


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` to ``path`` as indented JSON, atomically."""
    write_text(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def write_toml(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` to ``path`` as TOML, atomically."""
    write_text(path, tomli_w.dumps(data))


def write_csv(path: Path, rows: Sequence[dict[str, Any]], columns: Sequence[str] = ()) -> None:
    """One row per dict; the columns are ``columns`` and then every row's keys in order of first
    appearance, a row's missing ones left empty (a run resumed from a checkpoint written before a
    column existed)."""
    text = io.StringIO()
    writer = csv.DictWriter(
        text,
        fieldnames=list(dict.fromkeys([*columns, *(k for row in rows for k in row)])),
        lineterminator="\n",
    )
    writer.writeheader()
    writer.writerows(rows)
    write_text(path, text.getvalue())


PACKAGE_DIR = Path(dospcot.__file__).resolve().parent
"""Where the running dospcot package lies."""


@cache
def source_commit(source: Path = PACKAGE_DIR) -> str | None:
    """The git commit of the checkout holding ``source`` (the dospcot package that is running),
    ``"+dirty"`` appended when tracked files other than the run records under ``runs/`` differ from
    it (a study rerun into its record rewrites tracked records, not code); None when ``source`` does
    not lie in a git checkout (an installed wheel).

    Asked once per process: a process runs the code it imported, whatever the checkout holds later
    (a sweep's worker trains many trials), and a batch of seeds writes one ``run_info.json`` each.
    """
    try:
        commit = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        changed = subprocess.run(
            [
                "git",
                "-C",
                str(source),
                "status",
                "--porcelain",
                "--untracked-files=no",
                "--",
                ":(top,exclude)runs",
            ],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return commit + ("+dirty" if changed else "")


@cache
def cpu_description() -> str:
    """The CPU's model and the instruction set torch's CPU kernels use (e.g. ``AVX512``). Runs are
    deterministic for a seed on one CPU model; another model rounds otherwise, even with the same
    instruction set, and an RL run amplifies the smallest difference, so the same seed may end
    elsewhere there."""
    model = platform.processor() or platform.machine()
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
        model = next(line.split(":", 1)[1].strip() for line in lines if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{model}, torch kernels {torch.backends.cpu.get_cpu_capability()}"


def write_run_info(run_dir: Path, command: str, wall_time_s: float, **extra: Any) -> None:
    """``run_info.json``: the command, the wall time (s), any ``extra`` fields (a training run's
    ``cpu_time_s``: its process's CPU seconds, every session summed, which other processes on the
    machine do not inflate) and what ran it (versions, the source's git commit, machine and CPU). Kept
    out of ``summary.json`` so that a resumed run's summary equals the uninterrupted run's."""
    write_json(
        run_dir / "run_info.json",
        {
            "command": command,
            "wall_time_s": round(wall_time_s, 2),
            **extra,
            "dospcot": dospcot.__version__,
            "commit": source_commit(),
            "cpu": cpu_description(),
            "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__,
            "python": platform.python_version(),
            "machine": f"{platform.machine()} {platform.system()}, {torch.get_num_threads()} torch threads",
        },
    )


def new_run_dir(root: Path, name: str, config: dict[str, Any] | None = None) -> Path:
    """``root/name/<stamp>/``, created atomically with its ``config.toml`` (``config``; None: an empty
    folder): the folder is made and filled under a temporary name, then renamed, so a run folder never
    exists half made. The stamp is the local time, made unique with a suffix."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    parent = root / name
    if parent.exists() and not parent.is_dir():  # mkdir would call it "File exists"
        raise RunFolderError(f"cannot make a run folder under {root}: Not a directory")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        partial_dir = Path(tempfile.mkdtemp(prefix=f".{stamp}.", suffix=TMP_SUFFIX, dir=parent))
        partial_dir.chmod(0o755)  # mkdtemp makes folders private; run folders are for sharing
    except OSError as err:  # root is a file, or cannot be created
        raise RunFolderError(f"cannot make a run folder under {root}: {err.strerror or err}") from None
    if config is not None:
        write_toml(partial_dir / CONFIG_FILE, config)
    for k in range(1000):
        run_dir = parent / (stamp if k == 0 else f"{stamp}-{k}")
        try:
            partial_dir.rename(run_dir)  # fails where the name is taken (a non-empty folder)
            return run_dir
        except OSError:
            if not run_dir.exists():
                raise
    raise RunFolderError(f"cannot make a new run folder under {parent}")


def config_digest(run_dir: Path) -> str:
    """The SHA-256 of a run folder's ``config.toml``: a checkpoint keeps it, and a resume refuses a
    config edited since."""
    return hashlib.sha256((run_dir / CONFIG_FILE).read_bytes()).hexdigest()


def batch_members(run_dir: Path) -> list[Path] | None:
    """The folders (absolute) of the unfinished batch ``run_dir`` belongs to (its ``batch.json``), or
    None."""
    path = run_dir / BATCH_FILE
    return [Path(p) for p in json.loads(path.read_text())["members"]] if path.is_file() else None


@contextmanager
def run_lock(
    run_dir: Path, doing: str = "trained", error: type[Exception] = RunFolderError
) -> Iterator[None]:
    """Hold ``run_dir/.lock`` (the process id) while training: a second process on the same folder
    stops with one line naming the holder (``error``: the folder "is being ``doing`` by process N").
    A lock whose process is gone is taken over."""
    lock = run_dir / LOCK_FILE
    for _ in range(2):
        try:
            descriptor = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            holder = _lock_holder(lock)
            if holder is not None:
                raise error(_held_line(run_dir, doing, holder)) from None
            lock.unlink(missing_ok=True)  # its process is gone
            continue
        with os.fdopen(descriptor, "w") as handle:
            started = process_start(os.getpid())
            handle.write(f"{os.getpid()} {started}" if started is not None else str(os.getpid()))
        try:
            yield
        finally:
            lock.unlink(missing_ok=True)
        return
    raise RunFolderError(f"cannot take the lock {lock}")  # pragma: no cover - a race lost twice


def _held_line(run_dir: Path, doing: str, pid: int) -> str:
    """What the lock of ``run_dir`` held by the live process ``pid`` tells: a dospcot process is waited
    for; another (its id reused since a dospcot run died) holds nothing, and its lock can go."""
    command = process_command(pid)
    lock = run_dir / LOCK_FILE
    if command is None:  # nothing to judge the process by: say both
        return (
            f"{run_dir} is being {doing} by process {pid} (its {LOCK_FILE}); wait for it or stop it, then "
            f"resume; if process {pid} is no dospcot run, remove {lock}"
        )
    if "dospcot" in command or "python" in command:
        return f"{run_dir} is being {doing} by process {pid} ({command}); wait for it or stop it, then resume"
    return (
        f"{lock} names process {pid}, which is no dospcot run ({command}): a run that died left it; "
        f"remove {lock} and resume"
    )


def process_command(pid: int, width: int = 80) -> str | None:
    """The command line of the process ``pid`` (shortened to ``width`` characters), or None where the
    system does not say: no ``/proc``, or an empty line (a process part-way through starting a new
    program, or one that has exited but not been reaped), which names no program to judge by."""
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None
    command = " ".join(part.decode(errors="replace") for part in raw.split(b"\0") if part)
    if not command:
        return None
    return command if len(command) <= width else command[: width - 3] + "..."


def process_start(pid: int) -> int | None:
    """When the process ``pid`` started (clock ticks since boot, ``/proc/<pid>/stat``), or None where
    the system does not say: with its id, it names one process, as an id alone, once reused, does not."""
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[19])
    except (OSError, ValueError, IndexError):
        return None


def _lock_holder(lock: Path) -> int | None:
    """The live process that holds ``lock``, or None (gone, its id taken by a process started since,
    or the lock unreadable). A lock holds the id and, where the system says, the start time."""
    try:
        pid_text, _, started = lock.read_text().partition(" ")
        pid = int(pid_text)
        os.kill(pid, 0)
    except (OSError, ValueError):
        return None
    if started.strip().isdigit() and process_start(pid) not in (None, int(started)):
        return None  # the id was reused: the process that wrote the lock is gone
    return pid


def write_checkpoint(run_dir: Path, state: dict[str, Any]) -> None:
    """Pickle the state of the last finished round to ``checkpoint.pkl``, atomically."""
    payload = {"format": CHECKPOINT_FORMAT, "state": state}
    atomic_write(run_dir / CHECKPOINT_FILE, partial(pickle.dump, payload, protocol=pickle.HIGHEST_PROTOCOL))


def read_checkpoint(run_dir: Path) -> dict[str, Any]:
    """The state :func:`write_checkpoint` saved.

    The checkpoint is a pickle: like SB3 zips, load it only from a source you trust.

    :raises RunFolderError: missing, truncated, corrupt or of another format.
    """
    path = run_dir / CHECKPOINT_FILE
    if not path.is_file():
        raise RunFolderError(f"{path} does not exist: the run finished no round, start it again")
    try:
        with path.open("rb") as handle:
            payload = pickle.load(handle)
    except Exception as err:  # any unpickling failure means the same here: truncated or corrupt
        reason = type(err).__name__
        raise RunFolderError(f"{path} is corrupt or truncated ({reason}); start the run again") from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise RunFolderError(f"{path} is not a dospcot checkpoint of format {CHECKPOINT_FORMAT}")
    return payload["state"]
