"""Where a DOSPCoT run's CPU goes, phase by phase, against a self-training run.

Trains one seed of each of four DOSPCoT presets and of its self-training peer, each in its own
subprocess (one at a time, one torch thread, as ``dospcot train --threads 1``), through ``dospcot
train``'s own driver (a run folder in a temporary directory, checkpoints included), shortened to
``--rounds`` rounds at the presets' full steps per round. Each phase of a round is timed with
``time.process_time`` by wrapping the library's methods from here (no timing code in the library);
a phase counts its own CPU seconds, not those of the phases it calls, so the phases add up to the
run. Each subprocess's peak resident memory comes from ``os.wait4``.

Usage::

    python scripts/profile_round.py                       # all four pairs, 2 rounds, seed 0
    python scripts/profile_round.py --rounds 3 --out docs/guide/profile.md --json profile.json
    python scripts/profile_round.py --family lavagap --baseline before.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

FAMILIES: dict[str, tuple[str, str]] = {
    "grid16": ("grid16-dospcot", "grid16-self-training"),
    "doorkey": ("minigrid-doorkey-dospcot", "minigrid-doorkey-self-training"),
    "lavagap": ("minigrid-lavagap-dospcot", "minigrid-lavagap-self-training"),
    "fasthighway": ("fasthighway-dospcot", "fasthighway-self-training"),
}
"""Each task's DOSPCoT preset and its self-training peer."""

PHASES = (
    "set-up (task, agents)",
    "agents: collect & learn",
    "agents: policy update",
    "pool & features",
    "fit, view 1",
    "fit, view 2",
    "scoring (scores, class losses)",
    "selection & consensus",
    "co-trainer, other",
    "pseudo-rewards & round stats",
    "evaluation",
    "run folder (files, checkpoint)",
    "other",
)
"""The rows of the table, in a round's order."""


NOTES = "\n<!-- notes: written by hand, kept when the script rewrites the tables above -->\n"


class PhaseTimer:
    """Exclusive CPU seconds per phase: a phase entered inside another is subtracted from it."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = defaultdict(float)
        self.children: list[float] = []

    def wrap(self, name: str | Callable[..., str], function: Callable) -> Callable:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            label = name(*args) if callable(name) else name
            self.children.append(0.0)
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                elapsed = time.process_time() - start
                inner = self.children.pop()
                self.totals[label] += elapsed - inner
                if self.children:
                    self.children[-1] += elapsed

        return wrapper


def instrument(timer: PhaseTimer) -> None:
    """Wrap the phases of a co-training run (dospcot.core.sb3_round) and of its driver."""
    from dospcot.adapters.grid_adapter import GridAdapter
    from dospcot.adapters.sensor_adapter import SensorAdapter
    from dospcot.core import self_paced
    from dospcot.core.classifier import BatchedRewardClassifier
    from dospcot.core.sb3_round import CoTrainingRun
    from dospcot.policies import ExpectedSarsaDQN
    from dospcot.run.run_session import RunSession

    view_of: dict[int, str] = {}

    def patch(owner: Any, attr: str, name: str | Callable[..., str]) -> None:
        setattr(owner, attr, timer.wrap(name, getattr(owner, attr)))

    patch(RunSession, "__init__", "set-up (task, agents)")
    patch(ExpectedSarsaDQN, "learn", "agents: collect & learn")
    patch(ExpectedSarsaDQN, "update", "agents: policy update")
    for task in (GridAdapter, SensorAdapter):
        patch(task, "pool", "pool & features")
        patch(task, "true_class", "pseudo-rewards & round stats")
    patch(BatchedRewardClassifier, "fit", lambda clf, *_: view_of.get(id(clf), "fit, other"))
    patch(BatchedRewardClassifier, "scores", "scoring (scores, class losses)")
    patch(self_paced, "_class_losses", "scoring (scores, class losses)")
    patch(self_paced, "spamco_select", "selection & consensus")
    patch(self_paced, "consensus_labels", "selection & consensus")
    patch(self_paced.SelfPacedCoTrainer, "step", "co-trainer, other")
    patch(CoTrainingRun, "label_and_cotrain", "pseudo-rewards & round stats")
    patch(CoTrainingRun, "cotrain", "pseudo-rewards & round stats")
    patch(CoTrainingRun, "evaluate_policies", "evaluation")
    patch(RunSession, "after_round", "run folder (files, checkpoint)")
    patch(RunSession, "finish", "run folder (files, checkpoint)")

    built = CoTrainingRun.__init__

    def init(run: CoTrainingRun, *args: Any, **kwargs: Any) -> None:
        built(run, *args, **kwargs)
        if run.trainer is not None:
            for j, clf in enumerate(run.trainer.classifiers):
                view_of[id(clf)] = f"fit, view {j + 1}"

    CoTrainingRun.__init__ = init


def child(preset: str, rounds: int, seed: int, overrides: list[str]) -> dict[str, Any]:
    """Train one shortened run here; CPU seconds per phase and in all."""
    import torch

    torch.set_num_threads(1)
    from dospcot.run.train import train
    from dospcot.tasks import load_config

    cfg = load_config(preset, [f"training.rounds={rounds}", f"seed={seed}", *overrides])
    timer = PhaseTimer()
    instrument(timer)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.process_time()
        run_dir = train(cfg, Path(tmp), show_progress=False, command="profile_round")
        total = time.process_time() - start
        views = list(cfg.views)
        summary = json.loads((run_dir / "summary.json").read_text())
    phases = dict(timer.totals)
    phases["other"] = total - sum(phases.values())
    return {"preset": preset, "views": views, "total": total, "phases": phases, "summary_keys": len(summary)}


def run_case(preset: str, rounds: int, seed: int, overrides: list[str]) -> dict[str, Any]:
    """:func:`child` in a subprocess; with its process's CPU seconds and peak resident memory (MB)."""
    command = [sys.executable, __file__, "--child", preset, "--rounds", str(rounds), "--seed", str(seed)]
    command += [arg for override in overrides for arg in ("--set", override)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    process = subprocess.Popen(command, stdout=subprocess.PIPE, env=env)
    out = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode:
        raise SystemExit(f"{preset}: the run failed (exit {process.returncode})")
    result = json.loads(out.decode().strip().splitlines()[-1])
    result["process_cpu"] = usage.ru_utime + usage.ru_stime
    result["peak_rss_mb"] = usage.ru_maxrss / 1024  # Linux: KiB
    return result


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def _cell(value: float | None, before: float | None = None) -> str:
    if value is None:
        return "-"
    if before is None:
        return f"{value:.1f}"
    return f"{before:.1f} → {value:.1f}"


def table(results: dict[str, dict], baseline: dict[str, dict] | None) -> list[str]:
    """One markdown table per family: phases (CPU s) of the DOSPCoT run and its self-training peer."""
    lines: list[str] = []
    for family, (dospcot_preset, self_preset) in FAMILIES.items():
        if dospcot_preset not in results:
            continue
        pair = [results[dospcot_preset], results[self_preset]]
        old = [baseline.get(p["preset"]) if baseline else None for p in pair]
        views = pair[0]["views"]
        lines += [f"### {family}: `{dospcot_preset}` (views {', '.join(views)}) vs `{self_preset}`", ""]
        head = "before → after, " if baseline else ""
        lines += [f"| phase ({head}CPU s) | DOSPCoT | self-training |", "|---|---|---|"]
        for phase in PHASES:
            cells = []
            for run, before in zip(pair, old, strict=True):
                value = run["phases"].get(phase)
                prior = before["phases"].get(phase) if before else None
                cells.append("-" if value is None and prior is None else _cell(value or 0.0, prior))
            lines.append(f"| {phase} | {cells[0]} | {cells[1]} |")
        totals = [_cell(r["total"], b["total"] if b else None) for r, b in zip(pair, old, strict=True)]
        lines.append(f"| **run, all phases** | **{totals[0]}** | **{totals[1]}** |")
        rss = [
            _cell(r["peak_rss_mb"], b["peak_rss_mb"] if b else None) for r, b in zip(pair, old, strict=True)
        ]
        lines.append(f"| peak RSS (MB) | {rss[0]} | {rss[1]} |")
        ratio = pair[0]["total"] / pair[1]["total"]
        learning = sum(pair[0]["phases"].get(p, 0.0) for p in PHASES[1:3])
        text = f"DOSPCoT / self-training: **{ratio:.2f}x**"
        if all(old):
            text += f" (before: {old[0]['total'] / old[1]['total']:.2f}x)"
        text += f"; the agents' learning is {learning / pair[0]['total']:.0%} of the DOSPCoT run."
        lines += ["", text, ""]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--family", action="append", choices=sorted(FAMILIES), help="only this task")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of each run (default 2)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="write the markdown page here")
    parser.add_argument("--json", type=Path, help="write the raw figures here")
    parser.add_argument("--baseline", type=Path, help="raw figures of an earlier profile: before → after")
    parser.add_argument("--results", type=Path, help="render figures --json wrote, not train")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a key in every run, e.g. --set cotraining.numerics=2 (repeatable)",
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.rounds, args.seed, args.overrides)))
        return 0
    families = args.family or list(FAMILIES)
    results: dict[str, dict] = json.loads(args.results.read_text()) if args.results else {}
    for family in [] if args.results else families:
        for preset in FAMILIES[family]:
            results[preset] = run_case(preset, args.rounds, args.seed, args.overrides)
            print(f"{preset}: {results[preset]['total']:.1f} CPU s", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    baseline = json.loads(args.baseline.read_text()) if args.baseline else None
    command = "python scripts/profile_round.py " + " ".join(a for a in (argv or sys.argv[1:]))
    head = [
        "# Profile of a DOSPCoT round",
        "",
        f"Generated by `{command.strip()}` on {time.strftime('%Y-%m-%d')}; CPU: {cpu_model()}, one torch "
        f"thread, one run at a time, `nice -n 10` on a shared machine. Seed {args.seed}; every run "
        f"**shortened to {args.rounds} rounds** at its preset's full steps per round (the pool, and with "
        "it the co-training round, grows every round, so a full-length run's share of co-training is "
        "larger). CPU seconds from `time.process_time` inside `dospcot train`'s driver; each phase "
        "counts its own time, not that of the phases it calls. Peak RSS: the run's process, from "
        "`os.wait4`.",
        "",
        "Phases: *collect & learn* is the agents' `learn()` (acting, env steps, store writes and the "
        "gradient steps taken while collecting); *policy update* the gradient steps after co-training; "
        "*pool & features* the task's `pool()`; *fit, view j* view j's reward classifier's fits; "
        "*scoring* their scores and class losses; *co-trainer, other* the rest of the co-trainer's step "
        "(its inputs' conversion); *pseudo-rewards & round stats* the reward table and the round's "
        "metrics; *run folder* `metrics.csv`, agents, classifiers and the checkpoint every round.",
        "",
    ]
    page = "\n".join([*head, *table(results, baseline)])
    print(page)
    if args.out:
        # What the page says below the marker is written by hand: kept as it is.
        kept = args.out.read_text().partition(NOTES)[2] if args.out.is_file() else ""
        args.out.write_text(page + (NOTES + kept if kept else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
