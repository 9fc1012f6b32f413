"""The README's neural studies, each one command: a ``dospcot sweep`` and its ``dospcot report``.

    python scripts/study.py label-fraction --docs   # 4 presets x 6 label fractions x seeds 0-4 (~2.5 h)
    python scripts/study.py grid16 --docs           # 6 grid16 presets x seeds 0-9
    python scripts/study.py grid16-layouts --docs   # 3 grid16 presets x 3 unseen layouts x seeds 0-4
    python scripts/study.py grid32 --docs           # 4 grid32 presets x seeds 0-4
    python scripts/study.py grid16-tabular --docs   # the same with tabular agents (agent = "tabular")
    python scripts/study.py fasthighway --docs      # 4 fasthighway presets x seeds 0-4
    python scripts/study.py minigrid --docs         # 4 presets x LavaGapS7, DoorKey-5x5 x seeds 0-4
    python scripts/study.py highway --docs          # 4 highway presets (highway-fast-v0) x seeds 0-2
    python scripts/study.py paper-text --docs       # the seed paper's protocol x seeds 0-9 (~2 min)
    python scripts/study.py paper-published-code --docs   # the same with its published code's settings
    python scripts/study.py demo-labels --docs      # grid16-dospcot: 10 demonstrations + 1% vs 5% labels
    python scripts/study.py equal-effort --docs     # grid16-dospcot: per-step labels, segments, demos
    python scripts/study.py equal-effort-highway --docs  # the same on the fast highway, 5 seeds
    python scripts/study.py second-view --docs      # docs/preregistration.md's grid settings x seeds 0-9
    python scripts/study.py second-view-highway --docs   # its highway monitor setting x seeds 0-4

A study is one or more sweeps in ``runs/sweeps/``: rerunning the command runs only the trials not yet
finished, then rebuilds the tables from every finished run folder (``--render-only`` trains nothing).
The grid tables lead with success (the share of seeds x agents whose greedy policy reaches the goal
from the map's start) and optimal-action agreement; the normalised score follows, with its caveat in
each table's header (a policy that never reaches the goal but avoids lava scores high).
With ``--docs`` the tables go to ``docs/<study>.md`` and into README.md between the study's
``<!-- <study>-table:start -->`` and ``<!-- <study>-table:end -->`` markers, and the label-fraction
plot to ``docs/label-fraction.png``; for the paper studies the README gets an excerpt (paper accuracy
and Table 3 of optimal-action agreement) and the docs page every table. No number is typed by hand.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import re
import shlex
import shutil
import sys
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from readme_block import check_readme_block, replace_readme_block

from dospcot.config.loading import load_config
from dospcot.config.presets import PAPER_PRESETS
from dospcot.experiment.report import TrialRun, cells, load_runs, paper_report_tables, write_report
from dospcot.experiment.run_folder import REWARD_CLASSES_FILE
from dospcot.experiment.sweep import SweepError, SweepSpec, check_not_stale, run_sweep
from dospcot.metrics import SeedSummary

ROOT = Path(__file__).resolve().parent.parent
GRID_METHODS = {
    "oracle": "oracle (all rewards)",
    "masked-zero": "masked-zero",
    "labels-only": "labels-only",
    "self-training": "self-training (m = 1, patch)",
    "dospcot": "DOSPCoT (m = 2, patch + rays)",
    "m3": "m = 3 (patch + rays + coords)",
}
METHODS = {
    **{f"{grid}-{method}": label for grid in ("grid16", "grid32") for method, label in GRID_METHODS.items()},
    **{
        f"{base}-{method}": label
        for base in ("highway", "fasthighway")
        for method, label in {
            "oracle": "oracle (all rewards)",
            "masked-zero": "masked-zero",
            "self-training": "self-training (m = 1, kinematics)",
            "dospcot": "DOSPCoT (m = 2, kinematics + occupancy)",
        }.items()
    },
}
MINIGRID_TASKS = {"lavagap": "MiniGrid-LavaGapS7-v0", "doorkey": "MiniGrid-DoorKey-5x5-v0"}
METHODS.update(
    {
        f"minigrid-{task}-{method}": label
        for task in MINIGRID_TASKS
        for method, label in {
            "oracle": "oracle (all rewards)",
            "masked-zero": "masked-zero",
            "self-training": "self-training (m = 1, image)",
            "dospcot": "DOSPCoT (m = 2, image + egocentric map)",
        }.items()
    }
)
COLUMNS = {
    "success": "success",
    "agreement": "optimal-action agreement",
    "normalised_score": "normalised score",
    "pseudo_accuracy": "pseudo-reward accuracy",
    "worst_class_precision": "worst-class precision",
    "coverage": "coverage",
}
WORST_CLASS = (
    "Worst-class precision: among the admitted pseudo-rewards of one reward class, the share that is "
    "right, for the class where it is lowest (lava given to ordinary steps lowers it; the mean accuracy "
    "hides it, as lava steps are few)."
)
LAYOUT_COLUMNS = ("success", "agreement", "normalised_score", "pseudo_accuracy", "worst_class_precision")
FRACTION = "training.label_fraction"
GRID16_PRESETS = tuple(name for name in METHODS if name.startswith("grid16-"))
UNSEEN_LAYOUTS = ("101", "202", "303")
"""Layout seeds of the grid16-layouts study, fixed before any run on them: no preset was tuned there."""
LAYOUT = "env.layout_seed"


def header(runs: list[TrialRun], command: str, sweep_dirs: list[Path]) -> list[str]:
    """Where the figures come from; on a grid, what a lava-free timeout scores on this map."""
    first = runs[0]
    info = [json.loads((r.run_dir / "run_info.json").read_text()) for r in runs]
    seeds = sorted({r.trial.seed for r in runs})
    sweeps = ", ".join(f"`{d}`" for d in sweep_dirs)
    lines = [
        f"Generated by `{command}` on {datetime.now(UTC):%Y-%m-%d} ({platform.machine()}, "
        f"Python {platform.python_version()}) from {len(runs)} runs of sweep(s) {sweeps}; seeds "
        f"{seeds[0]}-{seeds[-1]}; {_training_time(info)}; {_commits(info)}{_cpus(info)}.",
        "Each cell: mean over seeds [95% bootstrap interval] of the run's mean over its agents, last round.",
    ]
    if first.summary.get("task") == "paper":  # its tables explain their cells themselves
        return lines[:1]
    if len({r.summary.get("optimal_return") for r in runs}) > 1 or "optimal_return" not in first.summary:
        return lines  # several maps, or no exact optimum
    return [*lines, f"The map's {_score_floor(first)}."]


def _training_time(info: list[dict[str, Any]]) -> str:
    """The runs' training time: CPU time where every run recorded it, else wall time, which counts a
    run's waits for a core it shared."""
    if all("cpu_time_s" in i for i in info):
        cpu = sum(i["cpu_time_s"] for i in info)
        return f"{cpu / 60:.0f} CPU-minutes of training (one torch thread per run)"
    wall = sum(i["wall_time_s"] for i in info)
    return f"{wall / 60:.0f} minutes of training, the runs' wall times summed (one torch thread per run)"


def _commits(info: list[dict[str, Any]]) -> str:
    """Which source trained the runs (``run_info.json``'s commit, shortened), with how many runs each:
    a study that resumed across sessions may mix commits, and this line shows it. A run resumed
    under other code than it started with counts under its sessions' commits in order ("a then b")."""
    counts = Counter(_run_commits(i) for i in info)
    return f"source commit{'s' if len(counts) > 1 else ''} {_counted(counts)}"


def _cpus(info: list[dict[str, Any]]) -> str:
    """The torch CPU kernels that trained the runs, with how many runs each (``run_info.json``'s
    ``cpu``; another instruction set may end a seed elsewhere); nothing where no run recorded it."""
    if not any("cpu" in i for i in info):
        return ""
    counts = Counter(i["cpu"].rpartition("torch kernels ")[2] if "cpu" in i else "not recorded" for i in info)
    return f"; torch CPU kernels {_counted(counts)}"


def _counted(counts: Counter[str]) -> str:
    """``"a (2), b (1)"``: each value with its number of runs, in sorted order."""
    return ", ".join(f"{value} ({n})" for value, n in sorted(counts.items()))


def _run_commits(info: dict[str, Any]) -> str:
    sessions = [_short_commit(c) for c in info.get("session_commits", [info.get("commit")])]
    return " then ".join(dict.fromkeys(sessions))  # distinct, in order


def _short_commit(commit: str | None) -> str:
    if not commit:  # runs that predate the field, or an installed wheel
        return "not recorded"
    sha, _, dirty = commit.partition("+")
    return sha[:7] + (" with uncommitted changes" if dirty else "")


def _score_floor(run: TrialRun) -> str:
    """The map's optimal and random returns, and what a lava-free timeout scores there."""
    horizon = load_config(str(run.run_dir / "config.toml")).env.episode_steps
    optimum, random = run.summary["optimal_return"], run.summary["random_return"]
    timeout = (-horizon - random) / (optimum - random)  # every step costs 1: no lava, no goal
    return (
        f"optimal return is {optimum:.0f} and the random policy's {random:.0f}, so a greedy "
        f"policy that avoids lava but never reaches the goal ({-horizon} over {horizon} steps) scores "
        f"{timeout:.3f}"
    )


HIGHWAY_COLUMNS = {
    "greedy_return": "greedy return",
    "success": "no-crash episodes",
    "pseudo_accuracy": "pseudo-reward accuracy (bin)",
    "coverage": "coverage",
}


def _by_method(runs: list[TrialRun]) -> dict[tuple[str, tuple], list[TrialRun]]:
    """The sweep cells in the order of :data:`METHODS`, then by rounds."""
    order = list(METHODS)
    return dict(
        sorted(cells(runs).items(), key=lambda item: (order.index(item[0][0]), item[1][0].summary["rounds"]))
    )


def _labels(grouped: dict[tuple[str, tuple], list[TrialRun]]) -> dict[tuple[str, tuple], str]:
    """Each cell's method, in words; with its rounds where the cells differ in them."""
    rounds = {key: members[0].summary["rounds"] for key, members in grouped.items()}
    with_rounds = len(set(rounds.values())) > 1
    suffix = {key: f", {n} rounds" if with_rounds else "" for key, n in rounds.items()}
    return {key: METHODS.get(key[0], key[0]) + suffix[key] for key in grouped}


def _over_seeds(members: list[TrialRun], key: str, view: str | None = None) -> str:
    """A metric over the seeds of a cell, of the run mean or (``view``) of one view's agent."""
    # Runs written before a metric existed read NaN there, which the summary leaves out.
    return str(
        SeedSummary.of(
            [(r.summary["per_view"][view] if view else r.summary["mean"]).get(key, math.nan) for r in members]
        )
    )


def _per_view_rows(
    grouped: dict[tuple[str, tuple], list[TrialRun]],
    keys: list[str],
    first: Callable[[str], str] | None = None,
) -> list[str]:
    """One table row per method and view: ``keys`` over seeds; ``first`` gives a leading cell from
    the preset's name (a task column)."""
    labels = _labels(grouped)
    return [
        ("" if first is None else f"| {first(key[0])} ")
        + f"| {labels[key]} | {view} | "
        + " | ".join(_over_seeds(members, k, view) for k in keys)
        + " |"
        for key, members in grouped.items()
        for view in members[0].summary["views"]
    ]


def _oracle_mean(grouped: dict[tuple[str, tuple], list[TrialRun]], metric: str) -> float:
    """``metric``'s mean over the seeds of the oracle cells (NaN without one)."""
    values = [r.summary["mean"][metric] for (n, _), m in grouped.items() if n.endswith("-oracle") for r in m]
    return SeedSummary.of(values).mean if values else math.nan


def highway_tables(runs: list[TrialRun]) -> list[str]:
    """Per method: return, success and pseudo-reward quality over seeds, and the share of the oracle's
    mean return; then per view."""
    grouped = _by_method(runs)
    oracle_mean = max(_oracle_mean(grouped, "greedy_return"), 1e-12)
    first = runs[0].summary
    episodes = load_config(str(runs[0].run_dir / "config.toml")).highway.eval_episodes
    # Each seed's evaluation episodes start from its own traffic, so the random floor differs by seed.
    random = {r.trial.seed: r.summary["random_return"] for r in runs}
    lines = [
        f"Evaluation: {episodes} greedy episodes of at most {first['max_return']:.0f} steps per agent "
        f"(reward per step in [0, 1]); a uniformly random policy returns "
        f"{sum(random.values()) / len(random):.1f} on average over the seeds "
        f"({min(random.values()):.1f} to {max(random.values()):.1f}).",
        "",
        "| method | preset | " + " | ".join(HIGHWAY_COLUMNS.values()) + " | share of oracle return |",
        "|---|---|" + "---|" * (len(HIGHWAY_COLUMNS) + 1),
    ]
    for (name, _), members in grouped.items():
        stats = [_over_seeds(members, key) for key in HIGHWAY_COLUMNS]
        share = SeedSummary.of([r.summary["mean"]["greedy_return"] for r in members]).mean / oracle_mean
        lines.append(f"| {METHODS.get(name, name)} | `{name}` | " + " | ".join(stats) + f" | {share:.1%} |")
    lines += ["", "Per view (greedy return, no-crash episodes):", "", "| method | view | return | no crash |"]
    lines.append("|---|---|---|---|")
    return lines + _per_view_rows(grouped, ["greedy_return", "success"])


MINIGRID_COLUMNS = {
    "success": "success",
    "greedy_return": "greedy return",
    "pseudo_accuracy": "pseudo-reward accuracy",
    "worst_class_precision": "worst-class precision",
}


def minigrid_tables(runs: list[TrialRun]) -> list[str]:
    """Per task and method: success (the share of evaluation episodes that reach the goal), return
    and pseudo-reward quality over seeds, and the share of the oracle's mean success; then per view."""
    grouped = _by_method(runs)
    episodes = load_config(str(runs[0].run_dir / "config.toml")).gym.eval_episodes
    lines = [
        f"Evaluation: {episodes} greedy episodes per agent from the task's own start, each on a new map; "
        "success is the share that reach the goal, and the return is MiniGrid's (1 - 0.9 t / T at the "
        "goal). The label fraction is the share of (state, action) pairs whose reward is revealed.",
        "",
        "| task | method | preset | "
        + " | ".join(MINIGRID_COLUMNS.values())
        + " | share of oracle success |",
        "|---|---|---|" + "---|" * (len(MINIGRID_COLUMNS) + 1),
    ]
    for task, env_id in MINIGRID_TASKS.items():
        cells_of_task = {key: m for key, m in grouped.items() if key[0].startswith(f"minigrid-{task}-")}
        oracle_mean = _oracle_mean(cells_of_task, "success")
        for (name, _), members in cells_of_task.items():
            stats = [_over_seeds(members, key) for key in MINIGRID_COLUMNS]
            mean = SeedSummary.of([r.summary["mean"]["success"] for r in members]).mean
            share = f"{mean / oracle_mean:.0%}" if oracle_mean > 0 else "n/a (oracle 0)"
            lines.append(f"| {env_id} | {METHODS[name]} | `{name}` | " + " | ".join(stats) + f" | {share} |")
    lines += ["", *_goal_label_lines(grouped)]
    lines += [
        "",
        "Per view (the same runs; each cell over seeds):",
        "",
        "| task | method | view | success | greedy return |",
        "|---|---|---|---|---|",
    ]
    return lines + _per_view_rows(
        grouped, ["success", "greedy_return"], lambda name: MINIGRID_TASKS[name.split("-")[1]]
    )


def _goal_label_lines(grouped: dict[tuple[str, tuple], list[TrialRun]]) -> list[str]:
    """Per task, the seeds whose DOSPCoT run met a labelled pair that reaches the goal, read from its
    ``reward_classes.json`` (a second class exists only then). The labelled pairs are fixed by the
    seed, and on a seed whose runs meet none no co-trained method can learn the goal."""
    lines = []
    for task, env_id in MINIGRID_TASKS.items():
        members = [r for (name, _), rs in grouped.items() if name == f"minigrid-{task}-dospcot" for r in rs]
        if not members:
            continue
        seeds = sorted(r.trial.seed for r in members)
        labelled = sorted(
            r.trial.seed
            for r in members
            if len(json.loads((r.run_dir / REWARD_CLASSES_FILE).read_text())["rewards"]) > 1
        )
        met = ", ".join(map(str, labelled)) or "none"
        lines.append(
            f"- {env_id}: seeds whose DOSPCoT run met a labelled goal pair: {met} "
            f"(of {', '.join(map(str, seeds))})."
        )
    return lines


def grid16_tables(runs: list[TrialRun]) -> list[str]:
    """Per method: every column over seeds; then per method and view."""
    grouped = _by_method(runs)
    lines = [
        WORST_CLASS,
        "",
        "| method | preset | " + " | ".join(COLUMNS.values()) + " |",
        "|---|---|" + "---|" * len(COLUMNS),
    ]
    labels = _labels(grouped)
    for (name, params), members in grouped.items():
        stats = [_over_seeds(members, key) for key in COLUMNS]
        lines.append(f"| {labels[name, params]} | `{name}` | " + " | ".join(stats) + " |")
    per_view = list(COLUMNS)[:3]
    lines += [
        "",
        "Per view (the same runs; each cell over seeds):",
        "",
        "| method | view | " + " | ".join(COLUMNS[key] for key in per_view) + " |",
        "|---|---|" + "---|" * len(per_view),
    ]
    return lines + _per_view_rows(grouped, per_view)


def layout_tables(runs: list[TrialRun]) -> list[str]:
    """Per layout and method: success, agreement, score and pseudo-reward quality over seeds (each
    cell over seeds of the run's mean over its agents)."""
    grouped = _by_method(runs)
    by_layout = sorted(grouped.items(), key=lambda item: int(dict(item[0][1])[LAYOUT]))
    floors = {dict(params)[LAYOUT]: _score_floor(members[0]) for (_, params), members in by_layout}
    lines = [f"Layout {layout}: the map's {floor}." for layout, floor in floors.items()]
    lines += [
        WORST_CLASS,
        "",
        "| layout seed | method | preset | " + " | ".join(COLUMNS[key] for key in LAYOUT_COLUMNS) + " |",
        "|---|---|---|" + "---|" * len(LAYOUT_COLUMNS),
    ]
    for (name, params), members in by_layout:
        stats = [_over_seeds(members, key) for key in LAYOUT_COLUMNS]
        lines.append(f"| {dict(params)[LAYOUT]} | {METHODS[name]} | `{name}` | " + " | ".join(stats) + " |")
    return lines


def label_fraction_tables(runs: list[TrialRun]) -> list[str]:
    """Per metric, a method x label-fraction table."""
    grouped = cells(runs)
    names = list(dict.fromkeys(name for name, _ in grouped))
    fractions = list(dict.fromkeys(dict(params)[FRACTION] for _, params in grouped))
    lines = ["", "![normalised score and success against label fraction](docs/label-fraction.png)"]
    for key in ("normalised_score", "success", "agreement"):
        lines += [
            "",
            f"{COLUMNS[key].capitalize()} by label fraction:",
            "",
            "| method | " + " | ".join(fractions) + " |",
            "|---|" + "---|" * len(fractions),
        ]
        for name in names:
            stats = [_over_seeds(grouped.get((name, ((FRACTION, f),)), []), key) for f in fractions]
            lines.append(f"| {METHODS.get(name, name)} | " + " | ".join(stats) + " |")
    return lines


def _section(text: str, heading: str) -> str:
    """The markdown from ``heading`` to the next heading of the same or a higher level."""
    level = heading.split(" ")[0]
    start = text.index(heading)
    rest = text[start + len(heading) :]
    match = re.search(rf"^#{{1,{len(level)}}} ", rest, flags=re.MULTILINE)
    return (heading + (rest[: match.start()] if match else rest)).strip()


def _demote(markdown: str, levels: int = 2) -> str:
    """Push every heading ``levels`` deeper, so the tables nest under the README's own headings."""
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m.group(1)) + levels) + " ", markdown, flags=re.MULTILINE)


def _with_agreement_plot(plot: str, runs: list[TrialRun]) -> list[str]:
    """The paper tables, after the plot of optimal-action agreement against round."""
    return [
        "",
        f"![optimal-action agreement against round, per agent kind and method]({plot})",
        "",
        *paper_report_tables(runs)[0],
    ]


def paper_readme(table: str) -> str:
    """The README's excerpt of the paper tables: the header and target line, every paper-accuracy
    table, and Table 3 of optimal-action agreement."""
    agreement = _section(table, "## Optimal-action agreement")
    return "\n\n".join(
        [
            table.split("\n## ")[0].strip(),
            _demote(_section(table, "## Paper accuracy")),
            "#### Optimal-action agreement, Table 3 (after 5 rounds)",
            _section(agreement, "### Table 3").split("\n", 1)[1].strip(),
        ]
    )


# The second-view study (docs/preregistration.md, committed before any of its runs): its settings,
# seeds, metrics, test and smallest effects are that file's; nothing here may differ from it.
SECOND_VIEW_SETTINGS: dict[str, dict[str, str]] = {
    "independent errors": {"env.blind_spot_rate": "0.5", "env.blind_spots": "independent"},
    "identical errors": {"env.blind_spot_rate": "0.5", "env.blind_spots": "identical"},
    "monitor": {"env.monitored_columns": "8", FRACTION: "0.02"},
    "highway monitor": {"highway.reveal_first_steps": "10", FRACTION: "0.02"},
}
SMALLEST_EFFECT = {"pseudo_accuracy": 0.01, "success": 0.1}
"""The smallest paired difference that counts (H1), by metric."""
SECOND_VIEW_COLUMNS = ("success", "pseudo_accuracy", "agreement", "worst_class_precision")
HIGHWAY_SECOND_VIEW_COLUMNS = ("greedy_return", "success", "pseudo_accuracy")
AGENT_WORDS = {"dqn": "neural (DQN)", "tabular": "tabular"}


def _setting(run: TrialRun) -> str:
    """The second-view setting whose keys a run's grid values hold."""
    params = run.trial.params
    return next(
        name
        for name, keys in SECOND_VIEW_SETTINGS.items()
        if all(params.get(k) == v for k, v in keys.items())
    )


def _method(run: TrialRun) -> str:
    """A run's method in the second-view tables; self-training and single-view baselines name their view."""
    name = run.trial.params.get("method") or run.trial.name.split("-", 1)[1]
    views = json.loads(run.trial.params["views"]) if "views" in run.trial.params else None
    return f"{name} ({views[0]})" if views else name


def _by_seed(runs: list[TrialRun]) -> dict[str, dict[tuple[str, str], dict[int, TrialRun]]]:
    """setting -> (agent kind, method) -> seed -> run."""
    table: dict[str, dict[tuple[str, str], dict[int, TrialRun]]] = {}
    for run in runs:
        agent = run.trial.params.get("agent", "dqn")
        table.setdefault(_setting(run), {}).setdefault((agent, _method(run)), {})[run.trial.seed] = run
    return table


def _value(run: TrialRun, metric: str) -> float:
    return run.summary["mean"].get(metric, math.nan)


def _paired(a: dict[int, TrialRun], b: dict[int, TrialRun], metric: str) -> SeedSummary:
    """``metric`` of a minus b, paired by seed: mean and 95% bootstrap interval over the seeds both ran."""
    return SeedSummary.of([_value(a[s], metric) - _value(b[s], metric) for s in sorted(set(a) & set(b))])


def _better_view(methods: dict[str, dict[int, TrialRun]], method: str, metric: str) -> str | None:
    """Of ``method``'s rows (one per view, or one), the one with the higher mean over seeds of
    ``metric``: the comparison then favours that method."""
    means = {
        name: float(np.nanmean([_value(r, metric) for r in seeds.values()]))
        for name, seeds in methods.items()
        if name == method or name.startswith(f"{method} (")
    }
    return max(means, key=means.__getitem__) if means else None


def _verdict(ok: bool | None) -> str:
    return "not yet run" if ok is None else ("**confirmed**" if ok else "**not confirmed**")


SECOND_VIEW_ORDER = ("oracle", "masked-zero", "labels-only", "self-training", "dospcot", "m3")
SECOND_VIEW_WORDS = {"dospcot": "DOSPCoT (m = 2)", "m3": "m = 3 (+ coords, error-free)"}


def second_view_tables(runs: list[TrialRun], columns: tuple[str, ...] = SECOND_VIEW_COLUMNS) -> list[str]:
    """Per setting and agent kind: every method's metrics over seeds, then the pre-registered paired
    differences and each hypothesis marked confirmed or not (docs/preregistration.md)."""
    titles = {**COLUMNS, **(HIGHWAY_COLUMNS if "greedy_return" in columns else {})}
    lines = []
    for setting, by_method in _by_seed(runs).items():
        for agent in sorted({agent for agent, _ in by_method}):
            methods = {m: seeds for (a, m), seeds in by_method.items() if a == agent}
            lines += [
                "", f"**{setting}, {AGENT_WORDS[agent]} agents**", "",
                "| method | " + " | ".join(titles[c] for c in columns) + " |",
                "|---|" + "---|" * len(columns),
            ]  # fmt: skip
            for method in sorted(methods, key=lambda m: (SECOND_VIEW_ORDER.index(m.split(" (")[0]), m)):
                cells = [_over_seeds(list(methods[method].values()), c) for c in columns]
                lines.append(f"| {SECOND_VIEW_WORDS.get(method, method)} | " + " | ".join(cells) + " |")
            lines += ["", *_hypothesis_lines(setting, methods, columns[0], titles)]
    return lines


def _hypothesis_lines(
    setting: str, methods: dict[str, dict[int, TrialRun]], outcome: str, titles: dict[str, str]
) -> list[str]:
    """The paired differences of a setting and the verdict of its hypothesis; under a monitor, also
    DOSPCoT minus the better self-training view, which no hypothesis tests there."""
    lines, verdicts = [], []
    if setting in ("monitor", "highway monitor"):
        zero = _better_view(methods, "masked-zero", outcome)
        best = _better_view(methods, "self-training", outcome)
        for name, seeds in ((best, methods.get(best or "")), ("DOSPCoT", methods.get("dospcot"))):
            if seeds is None or zero is None:
                verdicts.append(None)
                continue
            diff = _paired(seeds, methods[zero], outcome)
            lines.append(f"- {titles[outcome]}, {name} minus {zero} (paired by seed): {diff}")
            verdicts.append(diff.low > 0)
        ok = None if None in verdicts else all(verdicts)
        lines.append(f"- H3 (masked-zero below self-training and DOSPCoT): {_verdict(ok)}")
        for metric in ("pseudo_accuracy", outcome):
            if (found := _versus_self_training(methods, metric, titles)) is not None:
                lines.append(found[0] + " (no hypothesis)")
        return lines
    for metric in ("pseudo_accuracy", "success"):
        found = _versus_self_training(methods, metric, titles)
        if found is None:
            verdicts.append(None)
            continue
        line, diff = found
        lines.append(line)
        if setting == "independent errors":
            verdicts.append(diff.low > 0 and diff.mean >= SMALLEST_EFFECT[metric])
        else:
            verdicts.append(diff.low <= 0 <= diff.high)
    ok = None if None in verdicts else all(verdicts)
    if setting == "independent errors":
        return [*lines, f"- H1 (DOSPCoT above the better self-training view in both): {_verdict(ok)}"]
    return [*lines, f"- H2 (no difference: both intervals hold 0): {_verdict(ok)}"]


def _versus_self_training(
    methods: dict[str, dict[int, TrialRun]], metric: str, titles: dict[str, str]
) -> tuple[str, SeedSummary] | None:
    """``metric`` of DOSPCoT minus the better self-training view, paired by seed, as a line and the
    difference; None while either has not run."""
    best = _better_view(methods, "self-training", metric)
    dospcot = methods.get("dospcot")
    if best is None or dospcot is None:
        return None
    diff = _paired(dospcot, methods[best], metric)
    return f"- {titles[metric]}, DOSPCoT minus {best} (the better view, paired by seed): {diff}", diff


def _second_view_sweeps() -> tuple[Sweep, ...]:
    """Per grid setting: the presets with neural and tabular agents, and self-training on each view."""
    presets = tuple(p for p in GRID16_PRESETS if p != "grid16-self-training")
    views = {"views": ('["patch"]', '["rays"]')}
    sweeps = []
    for setting in ("independent errors", "identical errors", "monitor"):
        keys = SECOND_VIEW_SETTINGS[setting]
        grid = {**{key: (value,) for key, value in keys.items()}, "agent": ("dqn", "tabular")}
        slug = setting.split()[0]
        sweeps.append(Sweep(f"second-view-{slug}", presets, grid))
        sweeps.append(
            Sweep(f"second-view-{slug}-self-training", ("grid16-self-training",), {**grid, **views})
        )
    return tuple(sweeps)


def _second_view_highway_sweeps() -> tuple[Sweep, ...]:
    """The fast highway under the monitor: every single-view method on each view (the oracle per view
    is the control the highway study lacks), labels-only from the masked-zero preset, and DOSPCoT."""
    grid = {key: (value,) for key, value in SECOND_VIEW_SETTINGS["highway monitor"].items()}
    per_view = {**grid, "views": ('["kinematics"]', '["occupancy"]')}
    singles = ("fasthighway-oracle", "fasthighway-masked-zero", "fasthighway-self-training")
    return (
        Sweep("second-view-highway-single", singles, per_view),
        Sweep(
            "second-view-highway-labels-only",
            ("fasthighway-masked-zero",),
            {**per_view, "method": ("labels-only",)},
        ),
        Sweep("second-view-highway-dospcot", ("fasthighway-dospcot",), grid),
    )


# A first comparison of label sources: expert demonstrations with 1% per-step labels against 5% per-step
# labels, on grid16-dospcot, seeds 0-9. Each arm is a set of overrides of the preset, one sweep each.
DEMOS, MARGIN_WEIGHT, DEMO_LABELS = (
    "demonstrations.episodes",
    "demonstrations.margin_loss_weight",
    "demonstrations.labels",
)
DEMO_ARMS: dict[str, dict[str, str]] = {  # the target's two arms first: a partial sweep has them
    "labels 5%": {FRACTION: "0.05"},
    "labels 1% + 10 demonstrations": {FRACTION: "0.01", DEMOS: "10"},
    "labels 1%": {FRACTION: "0.01"},
    "labels 1% + 10 demonstrations, as labels only": {FRACTION: "0.01", DEMOS: "10", MARGIN_WEIGHT: "0"},
    "labels 1% + 10 demonstrations, margin loss only": {FRACTION: "0.01", DEMOS: "10", DEMO_LABELS: "false"},
}
DEMO_COLUMNS = ("success", "agreement", "pseudo_accuracy", "worst_class_precision")
DEMO_TARGET = ("labels 1% + 10 demonstrations", "labels 5%")
"""The target on grid16: the first arm's success at least the second's."""


def _by_arm(runs: list[TrialRun], arms: dict[str, dict[str, str]]) -> dict[str, dict[int, TrialRun]]:
    """The runs of each arm (its overrides of the preset), by seed; every run belongs to one."""
    by_arm: dict[str, dict[int, TrialRun]] = {}
    for run in runs:
        params = {k: v for k, v in run.trial.params.items() if k != "seed"}
        arm = next(name for name, keys in arms.items() if keys == params)
        by_arm.setdefault(arm, {})[run.trial.seed] = run
    return by_arm


def _arm_sweeps(
    prefix: str, arms: dict[str, dict[str, str]], shared: dict[str, str], preset: str = "grid16-dospcot"
) -> tuple[Sweep, ...]:
    """One sweep of ``preset`` per arm, named after it; ``shared`` names arms that another study's
    sweep already holds (the same trials: they run once)."""
    return tuple(
        Sweep(
            shared.get(arm) or prefix + re.sub(r"[^a-z0-9]+", "-", arm.lower()).strip("-"),
            (preset,),
            {key: (value,) for key, value in keys.items()},
        )
        for arm, keys in arms.items()
    )


def _arm_rows(
    by_arm: dict[str, dict[int, TrialRun]], arms: Sequence[str], columns: Sequence[str], names: dict[str, str]
) -> list[str]:
    """A table's header and one row per arm that ran: its seeds, then ``columns`` over seeds."""
    lines = [
        "| arm | seeds | " + " | ".join(names[c] for c in columns) + " |",
        "|---|---|" + "---|" * len(columns),
    ]
    for arm in arms:
        if arm in by_arm:
            cells_ = [_over_seeds(list(by_arm[arm].values()), c) for c in columns]
            lines.append(f"| {arm} | {len(by_arm[arm])} | " + " | ".join(cells_) + " |")
    return lines


def demonstration_tables(runs: list[TrialRun]) -> list[str]:
    """One row per arm over seeds, then the target's paired difference in success."""
    by_arm = _by_arm(runs, DEMO_ARMS)
    lines = [
        "Every arm is `grid16-dospcot` with the overrides named; demonstrations are value iteration's "
        "optimal episodes, the first from the map's start (docs/demonstrations.md).",
        "",
        *_arm_rows(by_arm, DEMO_ARMS, DEMO_COLUMNS, COLUMNS),
    ]
    ours, theirs = DEMO_TARGET
    if ours in by_arm and theirs in by_arm:
        diff = _paired(by_arm[ours], by_arm[theirs], "success")
        met = "**met**" if diff.mean >= 0 else "**not met**"
        lines += [
            "",
            f"- success, {ours} minus {theirs} (paired by seed): {diff}; target (at least 0): {met}",
        ]
    return lines


# Label sources at equal rater effort, counted in labelled env steps (docs/segments.md): per-step
# labels, segment sums (k = 4 and 8) and demonstrations, on grid16-dospcot, seeds 0-9.
SEGMENT = "training.segment_length"
EQUAL_EFFORT_FRACTION = "0.0006"
"""The segments' label fraction at the per-step arm's effort. A grid run's per-step labels reveal 5% of
the 1,024 (s, a) keys, each labelled once for every visit: at most 51 labelled steps. Its agents take
80,000 steps, so segments labelled with probability 0.0006 hold about 48 labelled steps, whatever k.
The table shows the effort each arm measured."""
EFFORT_ARMS: dict[str, dict[str, str]] = {  # the target's arms first: a partial study has them
    "per-step labels, 5% of keys": {FRACTION: "0.05"},
    "segments of 4, equal effort": {FRACTION: EQUAL_EFFORT_FRACTION, SEGMENT: "4"},
    "segments of 8, equal effort": {FRACTION: EQUAL_EFFORT_FRACTION, SEGMENT: "8"},
    "labels 1% + 10 demonstrations": {FRACTION: "0.01", DEMOS: "10"},
    "segments of 4, 5% of segments": {FRACTION: "0.05", SEGMENT: "4"},
}
EFFORT_SHARED = {"labels 1% + 10 demonstrations": "demonstrations-labels-1-10-demonstrations"}
EFFORT_COLUMNS = ("labelled_steps", "success", "agreement", "pseudo_accuracy")


def effort_tables(
    runs: list[TrialRun],
    arms: dict[str, dict[str, str]] = EFFORT_ARMS,
    columns: tuple[str, ...] = EFFORT_COLUMNS,
    preset: str = "grid16-dospcot",
) -> list[str]:
    """One row per arm over seeds (effort first), then each arm's paired differences from the first
    arm (per-step labels) in the outcome columns (return, where shown, and success); the preset's
    oracle, where the study ran it, as a last row."""
    base = next(iter(arms))
    by_arm = _by_arm([run for run in runs if run.trial.config == preset], arms)
    oracle = [run for run in runs if run.trial.config != preset]
    names = {**COLUMNS, "labelled_steps": "labelled steps (effort)", "greedy_return": "return"}
    if preset.startswith("fasthighway"):
        names["success"] = "no-crash episodes"
    lines = [
        f"Every arm is `{preset}` with the overrides named. Effort is the labelled env steps a "
        "rater watched: labelled samples under per-step labels ((s, a) keys on the grid, steps on "
        "highway), the summed length of the labelled segments under segment labels, and the "
        "demonstrations' steps on top of their arm's labels (docs/segments.md). Under segment labels "
        "the pseudo-reward accuracy is that of the segments' sums (their quantile classes), not of "
        "single steps.",
        "",
        *_arm_rows(by_arm, arms, columns, names),
    ]
    if oracle:
        cells_ = [_over_seeds(oracle, c) if c != "labelled_steps" else "every step" for c in columns]
        lines.append(f"| oracle (`{oracle[0].trial.config}`) | {len(oracle)} | " + " | ".join(cells_) + " |")
    lines += [
        "",
        "n/a: not recorded before the effort column existed, or undefined (an oracle has no pseudo-rewards).",
    ]
    if base in by_arm:
        lines.append("")
        outcomes = [c for c in ("greedy_return", "success") if c in columns]
        for arm in arms:
            if arm != base and arm in by_arm:
                for column in outcomes:
                    diff = _paired(by_arm[arm], by_arm[base], column)
                    lines.append(f"- {names[column]}, {arm} minus {base} (paired by seed): {diff}")
    return lines


# The fast-highway half: labels reveal each step with probability p, so segments at the same p cost
# the same effort. The demonstrator is the study's own oracle run of seed 0 (its kinematics agent).
EXPERT = "runs/sweeps/effort-highway-oracle/trials/fasthighway-oracle/seed=0/agent_kinematics.zip"
EFFORT_HIGHWAY_ARMS: dict[str, dict[str, str]] = {
    "per-step labels, 5% of steps": {FRACTION: "0.05"},
    "segments of 4, 5% of segments": {FRACTION: "0.05", SEGMENT: "4"},
    "segments of 8, 5% of segments": {FRACTION: "0.05", SEGMENT: "8"},
    "labels 1% + 10 demonstrations": {FRACTION: "0.01", DEMOS: "10", "demonstrations.agent": f'"{EXPERT}"'},
}
EFFORT_HIGHWAY_COLUMNS = ("labelled_steps", "greedy_return", "success", "pseudo_accuracy")


@dataclass(frozen=True)
class Sweep:
    """One sweep of a study: its folder's name under --runs-dir, its configs and its grid."""

    name: str
    configs: tuple[str, ...]
    grid: dict[str, tuple[str, ...]]


@dataclass(frozen=True)
class Study:
    sweeps: tuple[Sweep, ...]
    tables: Callable[[list[TrialRun]], list[str]]
    title: str
    seeds: int = 5
    readme: Callable[[str], str] | None = lambda table: table
    """The README block from the study's table text; ``None``: the study has no README block."""
    plot: tuple[str, str] | None = None
    """A plot of the report that goes into ``docs/``: (its name in the sweep folder, its name there)."""


LABEL_FRACTION = Sweep(
    "label-fraction",
    ("grid16-masked-zero", "grid16-self-training", "grid16-dospcot", "grid16-m3"),
    {FRACTION: ("0.01", "0.02", "0.05", "0.1", "0.25", "1.0")},
)
STUDIES = {
    "grid16": Study(
        (Sweep("grid16", GRID16_PRESETS, {}),), grid16_tables, "The 16 x 16 grid study", seeds=10
    ),
    # The presets on maps nobody tuned them on.
    "grid16-layouts": Study(
        (
            Sweep(
                "grid16-layouts",
                ("grid16-oracle", "grid16-self-training", "grid16-dospcot"),
                {LAYOUT: UNSEEN_LAYOUTS},
            ),
        ),
        layout_tables,
        "The 16 x 16 grid presets on three unseen layouts",
    ),
    "grid32": Study(
        (
            Sweep(
                "grid32",
                tuple(f"grid32-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")),
                {},
            ),
        ),
        grid16_tables,
        "The 32 x 32 grid study",
    ),
    # The same six presets with a Q-table over each agent's view in place of every ExpectedSarsaDQN.
    "grid16-tabular": Study(
        (
            Sweep("grid16-tabular", GRID16_PRESETS, {"agent": ("tabular",)}),
            # A co-trained agent learns from a round's pseudo-rewards only in the next round, so
            # rewards admitted late get few updates: the same runs with twice the rounds.
            Sweep(
                "grid16-tabular-10rounds", GRID16_PRESETS, {"agent": ("tabular",), "training.rounds": ("10",)}
            ),
        ),
        grid16_tables,
        "The 16 x 16 grid study with tabular agents",
    ),
    "label-fraction": Study(
        (LABEL_FRACTION,),
        label_fraction_tables,
        "Score against label fraction",
        plot=("score_vs_label_fraction.png", "label-fraction.png"),
    ),
    **{
        base: Study(
            (
                Sweep(
                    base,
                    tuple(f"{base}-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")),
                    {},
                ),
            ),
            highway_tables,
            f"The highway study on {env}",
            seeds=seeds,
        )
        for base, env, seeds in (
            ("highway", "highway-fast-v0", 3),
            ("fasthighway", "our fast highway env", 5),
        )
    },
    "minigrid": Study(
        tuple(
            Sweep(
                f"minigrid-{task}",
                tuple(f"minigrid-{task}-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")),
                {},
            )
            for task in MINIGRID_TASKS
        ),
        minigrid_tables,
        "MiniGrid: LavaGapS7 and DoorKey-5x5",
    ),
    "demo-labels": Study(
        _arm_sweeps("demonstrations-", DEMO_ARMS, {}),
        demonstration_tables,
        "Expert demonstrations against per-step labels (grid16)",
        seeds=10,
    ),
    "equal-effort": Study(
        _arm_sweeps("effort-", EFFORT_ARMS, EFFORT_SHARED),
        effort_tables,
        "Label sources at equal effort: per-step labels, segments, demonstrations (grid16)",
        seeds=10,
    ),
    "equal-effort-highway": Study(
        (
            Sweep("effort-highway-oracle", ("fasthighway-oracle",), {}),  # first: it trains the expert
            *_arm_sweeps("effort-highway-", EFFORT_HIGHWAY_ARMS, {}, "fasthighway-dospcot"),
        ),
        partial(
            effort_tables,
            arms=EFFORT_HIGHWAY_ARMS,
            columns=EFFORT_HIGHWAY_COLUMNS,
            preset="fasthighway-dospcot",
        ),
        "Label sources at equal effort: per-step labels, segments, demonstrations (fast highway)",
    ),
    "second-view": Study(
        _second_view_sweeps(), second_view_tables, "When does a second view help? (grid)", seeds=10
    ),
    "second-view-highway": Study(
        _second_view_highway_sweeps(),
        partial(second_view_tables, columns=HIGHWAY_SECOND_VIEW_COLUMNS),
        "When does a second view help? (fast highway)",
    ),
    # The seed paper's protocol: a sweep of one paper preset over seeds; `dospcot report` tables it.
    **{
        preset: Study(
            (Sweep(preset, (preset,), {}),),
            partial(_with_agreement_plot, f"docs/{preset}-agreement.png"),
            f"Seed paper reproduction: masked CliffWalking-v1 (`{preset}`)",
            seeds=10,
            readme=paper_readme if preset == "paper-text" else None,
            plot=("paper_agreement.png", f"{preset}-agreement.png"),
        )
        for preset in PAPER_PRESETS.values()
    },
}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("study", choices=list(STUDIES))
    parser.add_argument(
        "--seeds", type=int, help="seeds 0..N-1 (default: the study's, 5; highway 3, paper 10)"
    )
    parser.add_argument("--workers", type=int, default=2, help="trials at once (default 2)")
    parser.add_argument("--backend", choices=["local", "ray"], default="local")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--runs-dir", type=Path, default=Path("runs/sweeps"))
    parser.add_argument("--docs", action="store_true", help="also write docs/<study>.md and README.md")
    parser.add_argument("--render-only", action="store_true", help="train nothing: tables from finished runs")
    args = parser.parse_args()
    study = STUDIES[args.study]
    markers = (f"<!-- {args.study}-table:start -->", f"<!-- {args.study}-table:end -->")
    if args.docs and study.readme is not None:
        try:  # before hours of training, not after
            check_readme_block(*markers)
        except ValueError as err:
            sys.exit(f"study.py: {err}")
    args.seeds = args.seeds or study.seeds
    # Another --seeds or --set is another sweep: it gets its own folder.
    default = (args.seeds, args.overrides) == (study.seeds, [])
    suffix = "" if default else f"-{args.seeds}seeds-{len(args.overrides)}sets"
    runs, sweep_dirs, written, not_started = [], [], [], []
    for sweep in study.sweeps:
        sweep_dir = args.runs_dir / f"{sweep.name}{suffix}"
        spec = SweepSpec(sweep.configs, sweep.grid, tuple(range(args.seeds)), tuple(args.overrides))
        try:  # trials run under a preset that has changed since are neither resumed nor tabled
            if args.render_only:
                check_not_stale(sweep_dir, spec.trials())
            else:
                failed = run_sweep(sweep_dir, spec, backend=args.backend, workers=args.workers).failed
                if failed:
                    sys.exit(f"{len(failed)} trials failed: {', '.join(failed)}")
        except SweepError as err:
            sys.exit(f"study.py: {err}")
        try:
            written += write_report(sweep_dir)
        except SweepError:  # never started, or no trial finished yet: the study was cut short there
            not_started.append(sweep_dir)
            continue
        runs += load_runs(sweep_dir)[1]
        sweep_dirs.append(sweep_dir)
    if not runs:
        sys.exit(
            f"study.py: no finished run of this study under {args.runs_dir}; run it without --render-only"
        )
    options = [a for a in sys.argv[2:] if a != "--render-only"]
    command = shlex.join(["python", "scripts/study.py", args.study, *options])
    unfinished = ", ".join(f"`{d}`" for d in not_started)
    missing = [f"Not finished yet: sweep(s) {unfinished}."] if not_started else []
    table = "\n".join([*header(runs, command, sweep_dirs), *missing, *study.tables(runs)]) + "\n"
    print(table)
    if args.docs:
        docs_table = table.replace("](docs/", "](")  # the docs page sits beside the plot
        (ROOT / "docs" / f"{args.study}.md").write_text(f"# {study.title}\n\n{docs_table}")
        plot = next((p for p in written if study.plot and p.name == study.plot[0]), None)
        if plot is not None:
            shutil.copyfile(plot, ROOT / "docs" / study.plot[1])
        if study.readme is not None:
            replace_readme_block(*markers, study.readme(table))


if __name__ == "__main__":
    main()
