"""How a big machine is best used: one cell's seeds swept four ways, timed side by side.

Sweeps ``--seeds`` seeds of the bench's shortened ``grid16-dospcot`` (the overrides of
``BATCHED_CELLS`` in ``lab/bench_batched.py``) with ``dospcot sweep``, each way in a fresh folder under
a temporary directory, one after another:

- ``alone``: every seed a process of its own, as many workers as seeds (or cores);
- ``cpu-batches``: a quarter of the workers, each training batches of 4 seeds on the CPU;
- ``gpu-batches``: the same with ``dqn.device = "cuda"``, the processes sharing the GPU;
- ``gpu-batch``: one process training every seed as one batch on the GPU.

Each way's wall time comes from ``time.perf_counter`` around its ``dospcot sweep`` subprocess, and
its CPU seconds (every process it started, workers included) from ``resource.getrusage``. A way
counts only if its sweep finished every seed. The GPU ways are skipped where torch sees no GPU.
The figures go to ``--json`` after every way (so a run stopped early keeps the ways it finished),
and ``--guide`` rewrites the measured table of ``docs/guide/big-machines.md`` from that file.

Usage::

    python scripts/big_machine.py --json big-machines.json           # on the machine to measure
    python scripts/big_machine.py --only gpu-batch --json gpu-batch.json  # one way, on the same machine
    python scripts/big_machine.py --render big-machines.json gpu-batch.json --guide docs/guide/big-machines.md
    python scripts/big_machine.py --seeds 2 --steps-per-round 500 --json /tmp/b.json   # a quick check
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guide" / "big-machines.md"
BEGIN = "<!-- measured: written by scripts/big_machine.py from big-machines.json -->"
END = "<!-- end of measured -->"
PRESET = "grid16-dospcot"
SHORT = ("training.rounds=2", "training.steps_per_round=3000", "training.update_steps=500")
"""``BATCHED_CELLS[PRESET]`` (kept literal so that this script imports nothing of the library, and
so runs with the ``dospcot`` of whichever Python it is given)."""


def ways(seeds: int, cores: int) -> dict[str, dict[str, Any]]:
    """The four ways to sweep ``seeds`` seeds on ``cores`` cores: workers, seeds per batch, device."""
    quarter = max(1, seeds // 4)
    return {
        "alone": {"workers": min(seeds, cores), "batch": 1, "device": "cpu"},
        "cpu-batches": {"workers": quarter, "batch": min(4, seeds), "device": "cpu"},
        "gpu-batches": {"workers": quarter, "batch": min(4, seeds), "device": "cuda"},
        "gpu-batch": {"workers": 1, "batch": seeds, "device": "cuda"},
    }


def machine() -> dict[str, Any]:
    """What the figures were measured on: the GPU (if torch sees one), the CPU and the software."""
    import torch

    cpu = "unknown CPU"
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        found = re.search(r"^model name\s*:\s*(.+)$", cpuinfo.read_text(), re.MULTILINE)
        cpu = found.group(1).strip() if found else cpu
    return {
        "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
        "cpu": cpu,
        "cores": len(os.sched_getaffinity(0)),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "date": datetime.date.today().isoformat(),
    }


def sweep_once(name: str, way: dict[str, Any], seeds: int, short: list[str], root: Path) -> dict[str, Any]:
    """Time one way's ``dospcot sweep`` (wall and CPU seconds); ``finished``: seeds with a summary."""
    command = [
        sys.executable, "-m", "dospcot", "sweep", PRESET, "--seeds", str(seeds),
        *(arg for key in [*short, f"dqn.device={way['device']}"] for arg in ("--set", key)),
        "--workers", str(way["workers"]), "--batch-seeds", str(way["batch"]),
        "--runs-dir", str(root), "--name", name, "--no-progress",
    ]  # fmt: skip
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    finished = len(list((root / name).glob("trials/*/*/summary.json")))
    result = {**way, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1), "finished": finished}
    if done.returncode != 0 or finished < seeds:
        result["error"] = (done.stderr or done.stdout)[-2000:]
    return result


def measure(seeds: int, short: list[str], only: list[str] | None, out: Path | None) -> dict[str, Any]:
    """Sweep each way in turn, writing the figures so far to ``out`` after each."""
    record = {"preset": PRESET, "overrides": short, "seeds": seeds, "machine": machine(), "ways": {}}
    planned = ways(seeds, record["machine"]["cores"])
    with tempfile.TemporaryDirectory() as tmp:
        for name, way in planned.items():
            if only and name not in only:
                continue
            if way["device"] == "cuda" and record["machine"]["gpu"] is None:
                record["ways"][name] = {**way, "skipped": "torch sees no GPU"}
                continue
            record["ways"][name] = sweep_once(name, way, seeds, short, Path(tmp))
            print(name, json.dumps(record["ways"][name])[:400], flush=True)
            if out:
                out.write_text(json.dumps(record, indent=1) + "\n")
    return record


def merged(records: list[dict[str, Any]]) -> dict[str, Any]:
    """One record of the ways measured by several runs (``--only``) on one machine, in the order of
    :func:`ways`; a way measured twice keeps its last figures."""
    first = records[0]
    same = ("gpu", "cpu", "cores", "torch")
    for other in records[1:]:
        if [other["machine"][key] for key in same] != [first["machine"][key] for key in same] or any(
            other[key] != first[key] for key in ("preset", "overrides", "seeds")
        ):
            raise SystemExit("--render: these files were measured on different machines or settings")
    found = {name: way for record in records for name, way in record["ways"].items()}
    order = [name for name in LABELS if name in found]
    return {**first, "ways": {name: found[name] for name in order}}


LABELS = {
    "alone": "{workers} worker(s), every seed alone",
    "cpu-batches": "{workers} worker(s), CPU batches of {batch} seeds",
    "gpu-batches": "{workers} worker(s), GPU batches of {batch} seeds",
    "gpu-batch": "1 worker, one GPU batch of {batch} seeds",
}


def render(record: dict[str, Any]) -> str:
    """The guide's measured table and the ratios read from it, as markdown."""
    box = record["machine"]
    setting = " ".join(f"--set {key}" for key in record["overrides"])
    lines = [
        f"Measured on {box['gpu'] or 'no GPU'} with {box['cores']} CPU cores ({box['cpu']}), Python "
        f"{box['python']}, torch {box['torch']}, on {box['date']}: {record['seeds']} seeds of the "
        f"shortened `{record['preset']}` (`{setting}`), each way a fresh `dospcot sweep`, one after "
        "another. *CPU* counts every process the sweep started. Measure it again with "
        "`python scripts/big_machine.py --json big-machines.json`.",
        "",
        "| how the seeds ran | wall time | CPU time | CPU per seed | `dospcot sweep` options |",
        "|---|---|---|---|---|",
    ]
    for name, way in record["ways"].items():
        options = f"--workers {way['workers']} --batch-seeds {way['batch']}"
        options += " --set dqn.device=cuda" if way["device"] == "cuda" else ""
        label = LABELS[name].format(**way)
        if "skipped" in way or "error" in way:
            why = way.get("skipped") or f"failed: {way['finished']} of {record['seeds']} seeds finished"
            lines.append(f"| {label} | {why} | | | `{options}` |")
            continue
        per_seed = way["cpu_s"] / record["seeds"]
        lines.append(
            f"| {label} | {way['wall_s']:.0f} s | {way['cpu_s']:.0f} s | {per_seed:.1f} s | `{options}` |"
        )
    lines += ["", *readings(record)]
    return "\n".join(lines)


def readings(record: dict[str, Any]) -> list[str]:
    """The ratios the guide's advice rests on, from the ways that finished."""
    ok = {name: way for name, way in record["ways"].items() if "wall_s" in way and "error" not in way}
    said = []
    if {"alone", "cpu-batches"} <= ok.keys():
        alone, batches = ok["alone"], ok["cpu-batches"]
        said.append(
            f"- The CPU batches took {batches['wall_s'] / alone['wall_s']:.1f}x the wall time of every "
            f"seed alone, and {batches['cpu_s'] / alone['cpu_s']:.2f}x its CPU time."
        )
    gpu = [name for name in ("gpu-batches", "gpu-batch") if name in ok]
    if "alone" in ok and gpu:
        ratios = ", ".join(f"{name} {ok[name]['wall_s'] / ok['alone']['wall_s']:.1f}x" for name in gpu)
        said.append(f"- Wall time of the GPU ways against every seed alone on the CPU: {ratios}.")
    return said


def write_guide(record: dict[str, Any], guide: Path) -> None:
    """Replace the text between the guide's markers with :func:`render`'s."""
    page = guide.read_text()
    if BEGIN not in page or END not in page:
        raise SystemExit(f"{guide} lacks the markers {BEGIN!r} and {END!r}")
    head, rest = page.split(BEGIN, 1)
    guide.write_text(f"{head}{BEGIN}\n{render(record)}\n{END}{rest.split(END, 1)[1]}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=16, help="seeds to sweep each way (default 16)")
    parser.add_argument(
        "--steps-per-round", type=int, default=3000, help="env steps per round (default 3000, the bench's)"
    )
    parser.add_argument("--only", nargs="+", choices=list(LABELS), help="sweep only these ways")
    parser.add_argument(
        "--json", type=Path, help="write the figures here (after every way; with --render, the merged ones)"
    )
    parser.add_argument(
        "--render", type=Path, nargs="+", help="render these JSON files (one machine's) instead of measuring"
    )
    parser.add_argument("--guide", type=Path, help=f"rewrite this page's measured table (e.g. {GUIDE})")
    args = parser.parse_args(argv)
    if args.render:
        record = merged([json.loads(path.read_text()) for path in args.render])
        if args.json:
            args.json.write_text(json.dumps(record, indent=1) + "\n")
    else:
        short = [SHORT[0], f"training.steps_per_round={args.steps_per_round}", *SHORT[2:]]
        record = measure(args.seeds, short, args.only, args.json)
    if args.guide:
        write_guide(record, args.guide)
    print(render(record))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
