"""The batched-seeds rows of ``dospcot-lab bench`` (docs/batched_seeds.md): a cell's seeds trained as one
batch against runs of their own, in CPU time, wall time and memory."""

from __future__ import annotations

import math
import multiprocessing
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

import torch as th

from dospcot.config.run_configs import TrainConfig
from dospcot.core.batched_runs import BatchedRuns
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.stacked_esarsa import StackedExpectedSarsa, stack_samples
from dospcot.run.sb3_runs import build_run
from dospcot.sweeps.sweep import run_sweep
from dospcot.sweeps.sweep_spec import SweepSpec
from dospcot.tasks import load_config
from dospcot_lab.bench_measure import Clock, Row, alternating, onehot_cliff


def _seconds_per_seed(cfgs: list[TrainConfig], batched: bool) -> float:
    """Seconds (:class:`Clock`: CPU time, or wall time on a GPU) per seed of training ``cfgs`` (one per
    seed) as one batch, or one run after another."""
    clock = Clock(cfgs[0].dqn.device)
    clock.start()
    runs = [build_run(cfg) for cfg in cfgs] if batched else []
    if batched:
        BatchedRuns(runs).run()
    for cfg in [] if batched else cfgs:
        build_run(cfg).run()
    return clock.stop() / len(cfgs)


BATCHED_CELLS: dict[str, tuple[str, ...]] = {
    "grid16-dospcot": ("training.rounds=2", "training.steps_per_round=3000", "training.update_steps=500"),
    "grid32-dospcot": ("training.rounds=2", "training.steps_per_round=3000", "training.update_steps=500"),
    "fasthighway-dospcot": ("training.rounds=2", "training.steps_per_round=1000", "highway.eval_episodes=2"),
}
"""The shortened presets of the batched-seeds rows: two rounds, so that a cell of 10 seeds trained
both ways costs minutes, not hours (the second round is the first that trains the agents' networks
on a grid: ``learn_from_round = 2``)."""


def _batched_cell(preset: str, seeds: int, device: str = "cpu") -> list[TrainConfig]:
    """Seeds 0..``seeds``-1 of ``preset`` shortened as :data:`BATCHED_CELLS` says, on ``device``."""
    overrides = [*BATCHED_CELLS[preset], f"dqn.device={device}"]
    return [load_config(preset, [*overrides, f"seed={seed}"]) for seed in range(seeds)]


def bench_batched_seeds(
    quick: bool, repeats: int, preset: str = "grid16-dospcot", target: float = 0.25, device: str = "cpu"
) -> Row:
    """Time per seed of ``preset``'s seeds trained as one batch against runs of their own, the agents
    on ``device`` (the classifiers and envs stay on the CPU)."""
    seeds = 4 if quick else 10
    cfgs = _batched_cell(preset, seeds, device)
    ours, peer = alternating(
        repeats, lambda _: _seconds_per_seed(cfgs, True), lambda _: _seconds_per_seed(cfgs, False)
    )
    shortened = ", ".join(f"`{o}`" for o in BATCHED_CELLS[preset])
    return Row.measured(
        "`dospcot train --seeds`, one batch vs runs of their own: CPU time per seed",
        f"`{preset}`, seeds 0-{seeds - 1}, {shortened}",
        Clock(device).unit,
        ours,
        peer,
        higher_is_better=False,
        target=target,
    )


STACKED_MEMBERS, STACKED_NET, STACKED_BATCH = 10, [128, 128], 64
"""The stacked-update row: the members, and the presets' ``dqn.net_arch`` and ``dqn.batch_size``."""


def _filled_agents(device: str, fill: int) -> list[ExpectedSarsaDQN]:
    """:data:`STACKED_MEMBERS` agents of seeds 0, 1, ..., their buffers holding ``fill`` random steps."""
    agents = []
    for seed in range(STACKED_MEMBERS):
        agent = ExpectedSarsaDQN(
            "MlpPolicy",
            onehot_cliff(),
            learning_starts=fill,
            buffer_size=fill,
            batch_size=STACKED_BATCH,
            policy_kwargs={"net_arch": STACKED_NET},
            seed=seed,
            device=device,
        )
        agent.learn(fill)  # uniform actions until learning_starts: no gradient step yet
        agents.append(agent)
    return agents


def _member_updates_per_second(agents: list[ExpectedSarsaDQN], steps: int, stacked: bool) -> float:
    """Gradient updates per second, counted over all members, of ``steps`` updates of every agent: one
    stacked step of all members at a time (as :class:`BatchedRuns` takes them), or each agent's own
    ``train`` one agent after another. Both sample each member's batch from its own buffer."""
    clock = Clock(str(agents[0].device))
    clock.start()
    if stacked:
        learner = StackedExpectedSarsa.from_agents(agents)
        eps = th.tensor([a.exploration_rate for a in agents], dtype=th.float32, device=agents[0].device)
        for _ in range(steps):
            batches = [agent.replay_buffer.sample(STACKED_BATCH) for agent in agents]
            learner.train_step(stack_samples(batches), eps, agents[0].gamma)
    else:
        for agent in agents:
            agent.train(steps, STACKED_BATCH)
    return steps * len(agents) / clock.stop()


def bench_stacked_update(quick: bool, repeats: int, device: str = "cpu") -> Row:
    """Member updates per second of the stacked gradient step against each member's ``train``."""
    steps, fill = (100, 1_000) if quick else (500, 5_000)
    agents = _filled_agents(device, fill)
    ours, peer = alternating(
        repeats,
        lambda _: _member_updates_per_second(agents, steps, True),
        lambda _: _member_updates_per_second(agents, steps, False),
    )
    return Row.measured(
        f"One stacked gradient step of {STACKED_MEMBERS} members vs each member's "
        "`ExpectedSarsaDQN.train()`: member updates per second",
        f"CliffWalking-v1 one-hot, MlpPolicy {STACKED_NET}, batch {STACKED_BATCH}, {STACKED_MEMBERS} "
        f"members, {steps} updates each, every batch sampled from the member's buffer",
        f"updates/{Clock(device).unit}",
        ours,
        peer,
        higher_is_better=True,
        target=2.0,
    )


def _sweep_wall_seconds(spec: SweepSpec, batch_seeds: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        result = run_sweep(Path(tmp) / "sweep", spec, workers=2, show_progress=False, batch_seeds=batch_seeds)
        seconds = time.perf_counter() - start
    if result.failed:
        raise RuntimeError(f"benchmark sweep trials failed: {result.failed}")
    return seconds


def bench_batched_wall(quick: bool, repeats: int) -> Row:
    """Wall time of a cell's seeds as two batch processes against ``dospcot sweep --workers 2`` of the
    same runs, each alone."""
    seeds = 4 if quick else 10
    preset = "grid16-dospcot"
    spec = SweepSpec((preset,), {}, tuple(range(seeds)), BATCHED_CELLS[preset])
    ours, peer = alternating(
        repeats,
        lambda _: _sweep_wall_seconds(spec, math.ceil(seeds / 2)),
        lambda _: _sweep_wall_seconds(spec, 1),
    )
    return Row.measured(
        "`dospcot sweep --workers 2 --batch-seeds K`, two batches vs the runs alone: wall time of a cell",
        f"`{preset}` as in the CPU-time row, seeds 0-{seeds - 1}, K = {math.ceil(seeds / 2)}, "
        "process start-up included",
        "s",
        ours,
        peer,
        higher_is_better=False,
        target=round(1 / 3, 3),
    )


def _status_kib(field: str) -> int:
    """A memory figure of this process from ``/proc/self/status`` (Linux), in KiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1])
    raise RuntimeError(f"/proc/self/status has no {field}")


def _added_memory_mib(cfgs: list[TrainConfig], batched: bool) -> float:
    """Peak resident memory (MiB) that training ``cfgs`` adds to a fresh process that has imported
    everything, per seed; run in a child process of its own (Linux: it resets and reads the peak)."""
    import torch

    torch.set_num_threads(1)
    # Importing torch peaks above what the process then holds: start the peak from here.
    Path("/proc/self/clear_refs").write_text("5")
    before = _status_kib("VmRSS")
    if batched:
        BatchedRuns([build_run(cfg) for cfg in cfgs]).run()
    else:
        build_run(cfgs[0]).run()
    return (_status_kib("VmHWM") - before) / 1024 / (len(cfgs) if batched else 1)


def _in_fresh_process(function: Callable[[], float]) -> float:
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=context) as pool:
        return pool.submit(function).result()


def bench_batched_memory(quick: bool, repeats: int) -> Row:
    """Memory a member of a batch adds against the memory a run of its own adds."""
    seeds, preset = 4 if quick else 10, "grid16-dospcot"
    cfgs = _batched_cell(preset, seeds)
    batch, alone = partial(_added_memory_mib, cfgs, True), partial(_added_memory_mib, cfgs[:1], False)
    ours, peer = alternating(repeats, lambda _: _in_fresh_process(batch), lambda _: _in_fresh_process(alone))
    return Row.measured(
        "`dospcot train --seeds`, a batch's member vs a run of its own: peak memory added to the process",
        f"`{preset}` as in the CPU-time row; ours: a batch of seeds 0-{seeds - 1}, per seed; "
        "the peer: seed 0",
        "MiB",
        ours,
        peer,
        higher_is_better=False,
        target=1.2,
    )
