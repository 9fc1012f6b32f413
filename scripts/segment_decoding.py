"""How well a run on segment labels decodes per-step rewards: a diagnostic (docs/segments.md, "Limits").

Runs the first rounds of a config with ``training.segment_length`` > 1, then compares, for each hidden
per-step reward value, what the agents read from the reward table with what each view's per-step model
gives when fitted on the labelled segments alone (no admitted pseudo-sums). The hidden rewards are read
here for the comparison only; nothing of them reaches the run.

Usage::

    python scripts/segment_decoding.py grid16-dospcot --set training.segment_length=4 \\
        --set training.label_fraction=0.05 --set seed=1 --rounds 1
"""

from __future__ import annotations

import argparse

import numpy as np

from dospcot.config.errors import ConfigError
from dospcot.core.segments import fit_step_rewards
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config


def _cells(decoded: np.ndarray, hidden: np.ndarray, value: float) -> str:
    error = decoded[hidden == value] - value
    return f"{value + error.mean():.2f} ({np.abs(error).mean():.2f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", help="a preset name or a TOML file")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key")
    parser.add_argument("--rounds", type=int, default=1, help="rounds to run before comparing (default 1)")
    args = parser.parse_args()
    try:
        cfg = load_config(args.config, args.set)
    except ConfigError as err:
        parser.error(str(err))
    if cfg.training.segment_length < 2:
        parser.error("the config has no segment labels: set training.segment_length to 2 or more")
    run = build_run(cfg)
    run.run(until_round=args.rounds)
    segments, n = run.segments, len(run.segments)
    steps = run.task.pool()
    read = run.table.weight > 0
    hidden = run.store.hidden_reward[: len(run.table)]
    labelled = segments.labelled[:n].astype(float)
    model = run.cfg.cotraining.classifier
    alone = [  # from the run's own initial parameters
        fit_step_rewards(f, segments.ids[:n], segments.label[:n], labelled, model, seed)
        for f, seed in zip(steps.features, run.step_model_seeds(), strict=True)
    ]
    print(
        f"{cfg.name}, seed {cfg.seed}, after {args.rounds} round(s): {n} segments, "
        f"{int(labelled.sum())} labelled; {int(read.sum())} steps read by the agents.\n"
        "Each cell: the mean decoded reward (the mean absolute error) over the steps the agents read.\n"
    )
    views = [f"fit on labelled segments alone, {view}" for view in run.cfg.views]
    print("| hidden reward | steps | reward table (what the agents read) | " + " | ".join(views) + " |")
    print("|---" * (3 + len(views)) + "|")
    for value in np.unique(hidden[read]):
        count = int((hidden[read] == value).sum())
        cells = [_cells(r[: len(run.table)][read], hidden[read], value) for r in (run.table.reward, *alone)]
        print(f"| {value:g} | {count} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
