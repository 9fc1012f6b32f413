"""Where a seed's CPU time goes, trained alone and in a batch: what limits batched seeds' speed-up
(docs/batched_seeds.md, "Speed").

Trains the same seeds of a shortened preset both ways in this process, on one torch thread, timing
each phase of a round with ``time.process_time``: collecting (acting, env steps, and the gradient
steps taken while acting), the gradient steps alone (while collecting and in the policy update),
labelling and co-training (the reward classifiers' fits inside it), the policy update, and the
round's evaluation. Then times one
first-layer gradient step of the stacked networks at the grid's patch view two ways: the batched
matrix product the engine uses, and the sum of the weight rows a one-hot input selects
(``embedding_bag``), which the issue asked to measure.

Usage::

    python scripts/batched_phases.py                      # grid16-dospcot, seeds 0-9
    python scripts/batched_phases.py grid32-dospcot --seeds 4
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import torch
import torch.nn.functional as F

from dospcot.core.batched_runs import BatchedRuns
from dospcot.core.classifier import BatchedRewardClassifier
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.policies import ExpectedSarsaDQN
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config
from dospcot_lab.bench_batched import BATCHED_CELLS

PHASES: dict[str, tuple[type, str]] = {
    "collect": (ExpectedSarsaDQN, "learn"),
    "collect, batched": (BatchedRuns, "_collect"),
    "gradient steps": (ExpectedSarsaDQN, "train"),
    "gradient steps, batched": (BatchedRuns, "_train_step"),
    "label and co-train": (CoTrainingRun, "label_and_cotrain"),
    "reward classifiers' fits": (BatchedRewardClassifier, "fit"),
    "policy update": (ExpectedSarsaDQN, "update"),
    "policy update, batched": (BatchedRuns, "_update"),
    "evaluation": (CoTrainingRun, "evaluate_policies"),
}


@contextmanager
def timed_phases(totals: dict[str, float]) -> Iterator[None]:
    """Add each phase's CPU seconds to ``totals`` while inside (phases may nest: each counts its own)."""
    originals = {name: getattr(owner, method) for name, (owner, method) in PHASES.items()}

    def timed(name: str, function: Callable) -> Callable:
        def wrapper(*args, **kwargs):
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                totals[name] += time.process_time() - start

        return wrapper

    for name, (owner, method) in PHASES.items():
        setattr(owner, method, timed(name, originals[name]))
    try:
        yield
    finally:
        for name, (owner, method) in PHASES.items():
            setattr(owner, method, originals[name])


def phase_seconds(preset: str, seeds: int, batched: bool) -> dict[str, float]:
    """CPU seconds per seed of each phase, and in all, training ``seeds`` seeds one way."""
    cfgs = [load_config(preset, [*BATCHED_CELLS[preset], f"seed={seed}"]) for seed in range(seeds)]
    totals: dict[str, float] = defaultdict(float)
    start = time.process_time()
    with timed_phases(totals):
        if batched:
            BatchedRuns([build_run(cfg) for cfg in cfgs]).run()
        else:
            for cfg in cfgs:
                build_run(cfg).run()
    totals["all, run set-up included"] = time.process_time() - start
    return {name: value / seeds for name, value in totals.items()}


def first_layer_ms(members: int, batch: int, ones: int, width: int, hidden: int, repeats: int = 200) -> tuple:
    """Milliseconds of one forward and backward of a stacked first layer on one-hot rows holding
    ``ones`` ones of ``width``: as a batched matrix product, and as sums of weight rows."""
    gen = torch.Generator().manual_seed(0)
    index = torch.stack([torch.randperm(width, generator=gen)[:ones] for _ in range(members * batch)])
    x = torch.zeros(members * batch, width).scatter_(1, index, 1.0).view(members, batch, width)
    weight = torch.randn(members, width, hidden, requires_grad=True)
    rows = (index.view(members, batch, ones) + torch.arange(members)[:, None, None] * width).view(-1, ones)

    def matmul() -> torch.Tensor:
        return torch.bmm(x, weight)

    def row_sums() -> torch.Tensor:
        return F.embedding_bag(rows, weight.view(members * width, hidden), mode="sum")

    times = []
    for forward in (matmul, row_sums):
        start = time.process_time()
        for _ in range(repeats):
            forward().relu().sum().backward()
            weight.grad = None
        times.append((time.process_time() - start) / repeats * 1000)
    return tuple(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("preset", nargs="?", default="grid16-dospcot", choices=sorted(BATCHED_CELLS))
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 (default 10)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    alone = phase_seconds(args.preset, args.seeds, batched=False)
    batch = phase_seconds(args.preset, args.seeds, batched=True)
    print(
        f"`{args.preset}`, {', '.join(BATCHED_CELLS[args.preset])}, seeds 0-{args.seeds - 1}: CPU-s per seed"
    )
    print()
    print("| phase | alone | batched |")
    print("|---|---|---|")
    for name in [*PHASES, "all, run set-up included"]:
        if name.endswith(", batched"):
            continue
        other = f"{name}, batched" if f"{name}, batched" in PHASES else name
        print(f"| {name} | {alone.get(name, 0.0):.2f} | {batch.get(other, 0.0):.2f} |")
    run = build_run(load_config(args.preset, [*BATCHED_CELLS[args.preset], "seed=0"]))
    agent = run.agents[0]
    obs = np.asarray(agent.get_env().reset())
    ones, width = int(np.count_nonzero(obs[0])), int(obs[0].size)
    one_hot = bool(np.isin(obs, (0.0, 1.0)).all())
    hidden = agent.q_net.q_net[0].out_features
    matmul, row_sums = first_layer_ms(args.seeds, agent.batch_size, max(ones, 1), width, hidden)
    print()
    print(
        f"First layer of view {run.cfg.views[0]!r} ({width} inputs, {ones} non-zero, one-hot: {one_hot}; "
        f"{hidden} units; {args.seeds} members x batch {agent.batch_size}), forward and backward: "
        f"batched matrix product {matmul:.3f} ms, sums of weight rows {row_sums:.3f} ms"
    )


if __name__ == "__main__":
    main()
