"""How often the ``"outcomes"`` queries label FrozenLake's goal: the spread over end states against a
draw at random among the episode ends.

    python scripts/end_queries_frozenlake.py --seeds 0 1 2 3 4 5 6 7 --runs-dir /tmp/fl

Each run co-trains two agents on ``FrozenLake-v1`` (4 x 4, not slippery: the goal pays 1, the four
holes end the episode with 0) through the gym path (docs/your_env.md), one agent reading the cell
one-hot and one its row and column, with 60 labels spread evenly over 5 rounds, under
``training.query_end_states = RULE`` (``--rule``: ``"spread"`` or ``"random"``). Prints, per seed,
the round whose labels first showed the goal (0: none did).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from dospcot.run.python_api import train_env

SETTINGS = {
    "gym.env_kwargs": {"is_slippery": False},
    "gym.episode_steps": 100,
    "gym.max_return": 1.0,
    "training.rounds": 5,
    "training.steps_per_round": 2000,
    "training.label_budget": 60,
    "training.query_schedule": "even",
    "training.label_strategy": "outcomes",
    "dqn.learning_starts": 100,
}
"""The runs' config keys beside the env and its views."""


def cell(obs: int) -> np.ndarray:
    """View 1: the agent's cell, one-hot."""
    return np.eye(16, dtype=np.float32)[int(obs)]


def row_column(obs: int) -> np.ndarray:
    """View 2: the agent's row and column, each in [0, 1]."""
    row, column = divmod(int(obs), 4)
    return np.array([row / 3, column / 3], dtype=np.float32)


def first_goal_round(run_dir: Path) -> int:
    """The round whose answers first showed the goal's reward (1), 0 if none did."""
    with (run_dir / "queries.csv").open() as handle:
        rounds = [int(row["round"]) for row in csv.DictReader(handle) if float(row["answer"]) > 0]
    return min(rounds, default=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(8)))
    parser.add_argument("--rule", choices=("spread", "random"), default="spread")
    parser.add_argument("--runs-dir", type=Path, default=Path("/tmp/frozenlake-ends"))
    args = parser.parse_args()
    found = []
    for seed in args.seeds:
        run_dir = train_env(
            "FrozenLake-v1",
            {"cell": cell, "row_column": row_column},
            seed=seed,
            name=f"frozenlake-{args.rule}",
            settings={**SETTINGS, "training.query_end_states": args.rule},
            runs_dir=args.runs_dir,
            show_progress=False,
        )
        found.append(first_goal_round(run_dir))
        print(f"rule={args.rule} seed={seed} first goal label in round {found[-1]} ({run_dir})", flush=True)
    print(f"rule={args.rule}: {sum(r > 0 for r in found)} of {len(found)} runs labelled the goal; {found}")


if __name__ == "__main__":
    main()
