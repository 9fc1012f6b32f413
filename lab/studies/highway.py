"""The highway studies: four presets on highway-env's highway-fast-v0 and on our fast highway env."""

from __future__ import annotations

from functools import partial

from dospcot.lab.report import TrialRun
from dospcot.lab.studies.declaration import Study, Sweep
from dospcot.lab.studies.tables import (
    LABELS_COLUMN,
    LABELS_EXPLAINED,
    METHODS,
    by_method,
    glance_versus,
    labels_cell,
    mean_over_oracles,
    over_seeds,
    per_view_rows,
    with_headline,
)
from dospcot.metrics import SeedSummary
from dospcot.tasks import load_run_config

HIGHWAY_COLUMNS = {
    "greedy_return": "greedy return",
    "success": "no-crash episodes",
    "pseudo_accuracy": "pseudo-reward accuracy (bin)",
    "coverage": "coverage",
}


def highway_tables(runs: list[TrialRun]) -> list[str]:
    """Per method: return, success and pseudo-reward quality over seeds, and the share of the oracle's
    mean return; then per view."""
    grouped = by_method(runs)
    oracle_mean = max(mean_over_oracles(grouped, "greedy_return"), 1e-12)
    first = runs[0].summary
    episodes = load_run_config(runs[0].run_dir / "config.toml").highway.eval_episodes
    # Each seed's evaluation episodes start from its own traffic, so the random floor differs by seed.
    random = {r.trial.seed: r.summary["random_return"] for r in runs}
    lines = [
        f"Evaluation: {episodes} greedy episodes of at most {first['max_return']:.0f} steps per agent "
        f"(reward per step in [0, 1]); a uniformly random policy returns "
        f"{sum(random.values()) / len(random):.1f} on average over the seeds "
        f"({min(random.values()):.1f} to {max(random.values()):.1f}).",
        LABELS_EXPLAINED,
        "",
        "| method | preset | "
        + " | ".join([*HIGHWAY_COLUMNS.values(), "share of oracle return", LABELS_COLUMN])
        + " |",
        "|---|---|" + "---|" * (len(HIGHWAY_COLUMNS) + 2),
    ]
    for (name, _), members in grouped.items():
        stats = [over_seeds(members, key) for key in HIGHWAY_COLUMNS]
        share = SeedSummary.of([r.summary["mean"]["greedy_return"] for r in members]).mean / oracle_mean
        lines.append(
            f"| {METHODS.get(name, name)} | `{name}` | "
            + " | ".join([*stats, f"{share:.1%}", labels_cell(members)])
            + " |"
        )
    lines += [
        "",
        "Per view (greedy return, no-crash episodes):",
        "",
        f"| method | view | return | no crash | {LABELS_COLUMN} |",
        "|---|---|---|---|---|",
    ]
    return lines + per_view_rows(grouped, ["greedy_return", "success"])


STUDIES: dict[str, Study] = {
    base: Study(
        (
            Sweep(
                base,
                tuple(f"{base}-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")),
                {},
                numerics=numerics,
            ),
        ),
        with_headline(highway_tables, partial(glance_versus, prefix=base, metric="greedy_return")),
        f"The highway study on {env}",
        f"{task}, 10% of steps labelled",
        partial(glance_versus, prefix=base, metric="greedy_return"),
        seeds=seeds,
    )
    for base, env, task, seeds, numerics in (
        # highway-env's study is pre-registered under numerics 2 (docs/preregistration-future-work.md)
        ("highway", "highway-fast-v0", "highway-env's highway-fast-v0", 3, 2),
        ("fasthighway", "our fast highway env", "our fast highway (dospcot/FastHighway-v0)", 5, 1),
    )
}
