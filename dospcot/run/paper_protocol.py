"""The seed paper's CliffWalking protocol with real reward masking: its runs, and how a paper config
trains in its run folders (:class:`PaperProtocolRunner`); its tables are the lab's
(:mod:`dospcot.sweeps.paper_tables`).

Table 1: each agent alone; Tables 2 and 3: homogeneous pairs at gamma 0.3, 0.5, 0.8 after 1 and 5
rounds; Table 4: Expected SARSA paired with Expected SARSA, SARSA and Q at gamma 0.3. Beside every
co-training cell stand the baselines of the same agent kind at the same round (oracle, masked-zero,
labels-only, self-training with each view) and the paper's printed figure.

A paper run is one seed of the protocol (a :class:`~dospcot.config.run_configs.PaperConfig`, presets
``paper-text`` and ``paper-published-code``): its 26 tabular runs train in one vectorised batch and
write an ordinary run folder. ``dospcot reproduce-paper`` is a ``dospcot sweep`` of such a preset
over seeds (its local backend batches each worker's seeds, :func:`train_protocol_at`) followed by
``dospcot report``, which renders these tables for a sweep of paper runs.

The 1-round and 5-round tables come from the same runs, read after their first and fifth round.
A pair's figure for a seed is the mean of its two agents.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from dospcot import metrics
from dospcot.config.run_configs import PaperConfig
from dospcot.core.tabular_runs import TabularCoTraining, TabularRunSpec
from dospcot.envs import CLIFF_VIEWS, TabularMDP, make_masked_cliffwalking
from dospcot.run.interrupts import Interrupted
from dospcot.run.run_folder import (
    CONFIG_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    RunFolderError,
    write_csv,
    write_json,
    write_run_info,
    write_toml,
)

KINDS: tuple[str, ...] = ("q", "sarsa", "esarsa")
KIND_NAMES = {"q": "Q", "sarsa": "SARSA", "esarsa": "ESARSA"}
GAMMAS: tuple[float, ...] = (0.3, 0.5, 0.8)
PAIR_VIEWS = ("coords", "patch")
HETERO_PAIRS = (("esarsa", "esarsa"), ("esarsa", "sarsa"), ("esarsa", "q"))
BASELINES: tuple[tuple[str, str, str], ...] = (
    ("oracle", "oracle", "coords"),
    ("masked-zero", "masked-zero", "coords"),
    ("labels-only", "labels-only", "coords"),
    ("self-training (coords)", "dospcot", "coords"),
    ("self-training (patch)", "dospcot", "patch"),
)
"""(row label, method, view) of the single-agent rows."""


def protocol_specs(seeds: Sequence[int]) -> list[TabularRunSpec]:
    """Every run of the protocol: per seed 26 runs (37 agents)."""
    specs = []
    for seed in seeds:
        for kind in KINDS:
            for _, method, view in BASELINES:
                specs.append(TabularRunSpec(method, (kind,), (view,), seed=seed))
            for gamma in GAMMAS:
                specs.append(TabularRunSpec("dospcot", (kind, kind), PAIR_VIEWS, gamma=gamma, seed=seed))
        for pair in HETERO_PAIRS[1:]:
            specs.append(TabularRunSpec("dospcot", pair, PAIR_VIEWS, gamma=0.3, seed=seed))
    return specs


def cliffwalking_mdp(label_fraction: float = 0.1) -> TabularMDP:
    """The tabular form of masked CliffWalking-v1 with every CliffWalking view."""
    env = make_masked_cliffwalking(label_fraction, tuple(CLIFF_VIEWS))
    return TabularMDP.from_env(env, CLIFF_VIEWS, max_episode_steps=100)


def episodes_per_seed(cfg: PaperConfig) -> int:
    """Episodes one seed of the protocol plays, summed over its agents (the unit of its progress)."""
    agents = sum(len(spec.agents) for spec in protocol_specs([0]))
    return cfg.tabular.rounds * cfg.tabular.episodes_per_round * agents


def train_protocol_at(
    cfg: PaperConfig,
    run_dirs: Mapping[int, Path],
    *,
    commands: Mapping[int, str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> None:
    """Train the protocol for every seed of ``run_dirs`` in one vectorised batch; write each seed's run
    folder: ``config.toml`` (first, so a killed batch leaves folders ``dospcot train --resume`` takes),
    then ``metrics.csv`` (one row per run, round and agent), ``run_info.json`` and, last,
    ``summary.json``.

    Runs are independent, so a seed's folder is the same whichever seeds shared its batch (bar the
    timing in ``run_info.json``, where the batch's wall time is split evenly over its seeds).

    :param commands: per seed, the command that reruns its folder alone (for ``run_info.json``).
    :param progress: called with the number of episodes just finished, summed over agents.
    """
    seeds = sorted(run_dirs)
    for seed in seeds:
        write_toml(run_dirs[seed] / CONFIG_FILE, replace(cfg, seed=seed).to_dict())
    started = time.perf_counter()
    trainer = TabularCoTraining(
        cliffwalking_mdp(cfg.tabular.label_fraction),
        protocol_specs(seeds),
        cfg.tabular,
        metrics.paper_reference_policy(),
    )
    records = trainer.run(progress=progress).records
    wall = time.perf_counter() - started
    for seed in seeds:
        run_dir = run_dirs[seed]
        mine = [record for record in records if record["seed"] == seed]
        write_csv(run_dir / METRICS_FILE, mine)
        write_run_info(
            run_dir, (commands or {}).get(seed, ""), wall / len(seeds), numerics=1, batch_seeds=seeds
        )
        # Last, so that its presence marks a finished run (``dospcot sweep`` skips those on resume).
        write_json(run_dir / SUMMARY_FILE, seed_summary(mine, cfg.tabular.rounds))


def seed_summary(records: Sequence[Mapping[str, Any]], rounds: int) -> dict[str, Any]:
    """One seed's ``summary.json``: the target's ingredients (optimal-action agreement after the last
    round, ``rounds``; every run has a record every round) for this seed alone."""
    agreement = per_seed(records, "agreement")
    target = {
        "dospcot_agreement": ("dospcot", "esarsa-esarsa", "-".join(PAIR_VIEWS), 0.3),
        "oracle_agreement": ("oracle", "esarsa", "coords", 0.3),
        "masked_zero_agreement": ("masked-zero", "esarsa", "coords", 0.3),
        "labels_only_agreement": ("labels-only", "esarsa", "coords", 0.3),
    }
    return {
        "task": "paper",
        "seed": int(records[0]["seed"]),
        "runs": len(protocol_specs([0])),
        "rounds": rounds,
        "mean": {name: agreement[(*key, rounds)][0] for name, key in target.items()},
    }


def per_seed(records: Sequence[Mapping[str, Any]], metric: str) -> dict[tuple, list[float]]:
    """Per-seed values of ``metric`` keyed by (method, agents, views, gamma, round); pairs averaged."""
    by_run: dict[tuple, list[float]] = defaultdict(list)
    for rec in records:
        key = (rec["method"], rec["agents"], rec["views"], rec["gamma"], rec["round"], rec["seed"])
        by_run[key].append(rec[metric])
    out: dict[tuple, list[float]] = defaultdict(list)
    for key in sorted(by_run):
        out[key[:-1]].append(float(np.mean(by_run[key])))
    return out


class PaperProtocolRunner:
    """How a :class:`~dospcot.config.run_configs.PaperConfig` trains (:mod:`dospcot.run.runners`): its
    runs take seconds, so a killed seed trains again from the start, and several seeds train together
    in one process."""

    @staticmethod
    def train_at(run_dir: Path, cfg: PaperConfig, *, show_progress: bool, command: str) -> Path:
        """Train one seed's 26 runs in ``run_dir`` (a progress bar in episodes)."""
        with tqdm(
            total=episodes_per_seed(cfg),
            unit="ep",
            desc=f"{cfg.name} seed {cfg.seed}",
            disable=not show_progress,
            mininterval=1.0,
            dynamic_ncols=True,
        ) as bar:
            try:
                train_protocol_at(cfg, {cfg.seed: run_dir}, commands={cfg.seed: command}, progress=bar.update)
            except KeyboardInterrupt:  # a seed keeps no checkpoint: it trains again from the start
                raise Interrupted(
                    f"nothing of seed {cfg.seed}", f"dospcot train --resume {run_dir}"
                ) from None
        return run_dir

    @classmethod
    def resume(cls, run_dir: Path, cfg: PaperConfig, *, show_progress: bool, command: str) -> Path:
        """Train the seed again from the start: it keeps no checkpoint."""
        return cls.train_at(run_dir, cfg, show_progress=show_progress, command=command)

    @staticmethod
    def evaluate(run_dir: Path, cfg: PaperConfig) -> dict[str, Any]:
        """Refused: a paper run keeps no agents."""
        raise RunFolderError(
            f"{run_dir} is a paper-protocol run: it keeps no agents (its figures are in {METRICS_FILE})"
        )

    @staticmethod
    def train_seeds_at(
        cfg: PaperConfig,
        run_dirs: dict[int, Path],
        commands: dict[int, str],
        progress: Callable[[float], None] | None,
    ) -> None:
        """Train every seed of ``run_dirs`` in one batch; ``progress`` gets the share of one seed done."""
        episodes = episodes_per_seed(cfg)
        train_protocol_at(
            cfg,
            run_dirs,
            commands=commands,
            progress=None if progress is None else lambda done: progress(done / episodes),
        )

    @staticmethod
    def result_line(run_dir: Path, summary: dict[str, Any]) -> str:
        """The seed's ESARSA pair's agreement beside the oracle's."""
        mean = summary["mean"]
        return (
            f"{run_dir}: ESARSA-ESARSA DOSPCoT agreement {mean['dospcot_agreement']:.3f}, oracle "
            f"{mean['oracle_agreement']:.3f} (seed {summary['seed']}, {summary['runs']} runs, round "
            f"{summary['rounds']}; every run in metrics.csv)"
        )
