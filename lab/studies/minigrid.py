"""The MiniGrid study: four presets on LavaGapS7 and DoorKey-5x5."""

from __future__ import annotations

import json

from dospcot.run.run_folder import REWARD_CLASSES_FILE
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot.tasks import load_run_config
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.tables import (
    LABELS_COLUMN,
    LABELS_EXPLAINED,
    METHODS,
    MINIGRID_TASKS,
    by_method,
    labels_cell,
    mean_over_oracles,
    over_seeds,
    per_view_rows,
    verdict,
    versus,
    views_line,
    with_headline,
)

MINIGRID_COLUMNS = dict(
    success="success",
    greedy_return="greedy return",
    pseudo_accuracy="pseudo-reward accuracy",
    worst_class_precision="worst-class precision",
)


def minigrid_tables(runs: list[TrialRun]) -> list[str]:
    """Per task and method: success (the share of evaluation episodes that reach the goal), return
    and pseudo-reward quality over seeds, and the share of the oracle's mean success; then per view."""
    grouped = by_method(runs)
    episodes = load_run_config(runs[0].run_dir / "config.toml").gym.eval_episodes
    lines = [
        f"Evaluation: {episodes} greedy episodes per agent from the task's own start, each on a new map; "
        "success is the share that reach the goal, and the return is MiniGrid's (1 - 0.9 t / T at the "
        "goal). The label fraction is the share of (state, action) pairs whose reward is revealed.",
        views_line(grouped),
        LABELS_EXPLAINED,
        "",
        "| task | method | preset | "
        + " | ".join([*MINIGRID_COLUMNS.values(), "share of oracle success", LABELS_COLUMN])
        + " |",
        "|---|---|---|" + "---|" * (len(MINIGRID_COLUMNS) + 2),
    ]
    for task, env_id in MINIGRID_TASKS.items():
        cells_of_task = {key: m for key, m in grouped.items() if key[0].startswith(f"minigrid-{task}-")}
        oracle_mean = mean_over_oracles(cells_of_task, "success")
        for (name, _), members in cells_of_task.items():
            stats = [over_seeds(members, key) for key in MINIGRID_COLUMNS]
            mean = SeedSummary.of([r.summary["mean"]["success"] for r in members]).mean
            share = f"{mean / oracle_mean:.0%}" if oracle_mean > 0 else "n/a (oracle 0)"
            lines.append(
                f"| {env_id} | {METHODS[name]} | `{name}` | "
                + " | ".join([*stats, share, labels_cell(members)])
                + " |"
            )
    lines += ["", *_goal_label_lines(grouped)]
    lines += [
        "",
        "Per view (the same runs; each cell over seeds):",
        "",
        f"| task | method | view | success | greedy return | {LABELS_COLUMN} |",
        "|---|---|---|---|---|---|",
    ]
    return lines + per_view_rows(
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


def minigrid_glance(runs: list[TrialRun]) -> Glance:
    """Per task, success of DOSPCoT minus self-training, paired by seed."""
    diffs = {
        env_id.removeprefix("MiniGrid-").removesuffix("-v0"): versus(
            runs, f"minigrid-{task}-dospcot", f"minigrid-{task}-self-training", "success"
        )
        for task, env_id in MINIGRID_TASKS.items()
    }
    return Glance(
        "success, DOSPCoT minus self-training, paired by seed: "
        + "; ".join(f"{task} {diff}" for task, diff in diffs.items()),
        "; ".join(f"{task}: {verdict(diff)}" for task, diff in diffs.items()),
    )


STUDIES: dict[str, Study] = {
    "minigrid": Study(
        tuple(
            Sweep(
                f"minigrid-{task}",
                tuple(f"minigrid-{task}-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")),
                {},
            )
            for task in MINIGRID_TASKS
        ),
        with_headline(minigrid_tables, minigrid_glance),
        "MiniGrid: LavaGapS7 and DoorKey-5x5",
        "MiniGrid LavaGapS7 and DoorKey-5x5, 10% of pairs labelled",
        minigrid_glance,
    ),
}
