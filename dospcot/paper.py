"""``dospcot reproduce-paper``: the seed paper's CliffWalking protocol, with real reward masking.

Table 1: each agent alone; Tables 2 and 3: homogeneous pairs at gamma 0.3, 0.5, 0.8 after 1 and 5
rounds; Table 4: Expected SARSA paired with Expected SARSA, SARSA and Q at gamma 0.3. Beside every
co-training cell stand the baselines of the same agent kind at the same round (oracle, masked-zero,
labels-only, self-training with each view) and the paper's printed figure.

The 1-round and 5-round tables come from the same runs, read after their first and fifth round.
A pair's figure for a seed is the mean of its two agents.
"""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import platform
import queue
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dospcot import metrics
from dospcot.envs import CLIFF_VIEWS, TabularMDP, make_masked_cliffwalking
from dospcot.metrics import SeedSummary
from dospcot.tabular_cotraining import TabularConfig, TabularCoTraining, TabularRunSpec

KINDS: tuple[str, ...] = ("q", "sarsa", "esarsa")
KIND_NAMES = {"q": "Q", "sarsa": "SARSA", "esarsa": "ESARSA"}
GAMMAS: tuple[float, ...] = (0.3, 0.5, 0.8)
PAIR_VIEWS = ("coords", "patch")
HETERO_PAIRS = (("esarsa", "esarsa"), ("esarsa", "sarsa"), ("esarsa", "q"))
ROUNDS = 5
BASELINES: tuple[tuple[str, str, str], ...] = (
    ("oracle", "oracle", "coords"),
    ("masked-zero", "masked-zero", "coords"),
    ("labels-only", "labels-only", "coords"),
    ("self-training (coords)", "cotrain", "coords"),
    ("self-training (patch)", "cotrain", "patch"),
)
"""(row label, method, view) of the single-agent rows."""

PRESETS: dict[str, dict[str, float]] = {
    "paper-text": {"learning_rate": 0.8, "discount": 0.95},
    "published-code": {"learning_rate": 0.5, "discount": 1.0},
}
"""The hyperparameters the paper's text states, and those its published code used. Both: 500
episodes of at most 100 steps, exploration 0.1."""


def protocol_config(preset: str, label_fraction: float, episodes: int = 500) -> TabularConfig:
    """The tabular config of a preset: 5 rounds of ``episodes`` episodes (100 steps at most), eps 0.1."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; allowed: {sorted(PRESETS)}")
    return TabularConfig(
        rounds=ROUNDS,
        episodes_per_round=episodes,
        eps_start=0.1,
        eps_end=0.1,
        label_fraction=label_fraction,
        **PRESETS[preset],
    )


def protocol_specs(seeds: Sequence[int]) -> list[TabularRunSpec]:
    """Every run of the protocol: per seed 26 runs (37 agents)."""
    specs = []
    for seed in seeds:
        for kind in KINDS:
            for _, method, view in BASELINES:
                specs.append(TabularRunSpec(method, (kind,), (view,), seed=seed))
            for gamma in GAMMAS:
                specs.append(TabularRunSpec("cotrain", (kind, kind), PAIR_VIEWS, gamma=gamma, seed=seed))
        for pair in HETERO_PAIRS[1:]:
            specs.append(TabularRunSpec("cotrain", pair, PAIR_VIEWS, gamma=0.3, seed=seed))
    return specs


def cliffwalking_mdp(label_fraction: float = 0.1) -> TabularMDP:
    """The tabular form of masked CliffWalking-v1 with every CliffWalking view."""
    env = make_masked_cliffwalking(label_fraction, tuple(CLIFF_VIEWS))
    return TabularMDP.from_env(env, CLIFF_VIEWS, max_episode_steps=100)


def _train(
    config: TabularConfig, specs: list[TabularRunSpec], progress: Callable[[int], None] | None = None
) -> list[dict]:
    trainer = TabularCoTraining(
        cliffwalking_mdp(config.label_fraction), specs, config, metrics.paper_reference_policy()
    )
    return trainer.run(progress=progress).records


def _train_chunk(args: tuple[TabularConfig, list[TabularRunSpec], object]) -> list[dict]:
    import torch

    torch.set_num_threads(1)
    config, specs, progress_queue = args
    return _train(config, specs, progress_queue.put)


def train_protocol(
    config: TabularConfig, seeds: Sequence[int], workers: int = 2, show_progress: bool = True
) -> list[dict]:
    """Train every run of the protocol, seeds split over ``workers`` processes; returns the records.

    Runs are independent, so the split does not change any result.
    """
    seeds = list(seeds)
    chunks = [seeds[i::workers] for i in range(workers) if seeds[i::workers]]
    total_agents = sum(len(s.agents) for s in protocol_specs([0])) * len(seeds)
    total = config.rounds * config.episodes_per_round * total_agents
    bar = tqdm(total=total, unit="ep", desc="reproduce-paper", disable=not show_progress, mininterval=1.0)
    if len(chunks) == 1:
        records = _train(config, protocol_specs(chunks[0]), bar.update)
        bar.close()
        return records
    ctx = multiprocessing.get_context("spawn")
    with ctx.Manager() as manager, ProcessPoolExecutor(len(chunks), mp_context=ctx) as pool:
        progress_queue = manager.Queue()
        futures = [pool.submit(_train_chunk, (config, protocol_specs(c), progress_queue)) for c in chunks]
        while not all(f.done() for f in futures):
            try:
                bar.update(progress_queue.get(timeout=0.2))
            except queue.Empty:
                pass
        records = [rec for f in futures for rec in f.result()]
        while not progress_queue.empty():  # reports sent after the last poll
            bar.update(progress_queue.get())
    bar.close()
    return records


def summarise(values: Sequence[float]) -> SeedSummary:
    """Mean, 95% bootstrap interval and (for >= 10 values) IQM of per-seed values."""
    return SeedSummary.of(values, iqm_min_n=10)


def per_seed(records: list[dict], metric: str) -> dict[tuple, list[float]]:
    """Per-seed values of ``metric`` keyed by (method, agents, views, gamma, round); pairs averaged."""
    by_run: dict[tuple, list[float]] = defaultdict(list)
    for rec in records:
        key = (rec["method"], rec["agents"], rec["views"], rec["gamma"], rec["round"], rec["seed"])
        by_run[key].append(rec[metric])
    out: dict[tuple, list[float]] = defaultdict(list)
    for key in sorted(by_run):
        out[key[:-1]].append(float(np.mean(by_run[key])))
    return out


METRICS = (
    ("paper_accuracy", "Paper accuracy (share of the 48 states matching the paper's reference policy)"),
    ("agreement", "Optimal-action agreement (reachable non-terminal states, value iteration)"),
    ("greedy_return", "Greedy return (true reward, one episode of at most 100 steps; optimum -13)"),
)


def build_tables(records: list[dict], paper: dict) -> list[dict]:
    """Long-format rows: one per table, row, gamma column and metric (the content of tables.csv)."""
    names = [m for m, _ in METRICS] + ["pseudo_accuracy", "coverage"]
    values = {m: per_seed(records, m) for m in names}
    rows: list[dict] = []

    def add(table: str, agents: str, method: str, gamma: float | None, rnd: int, metric: str, key, ref=None):
        cell = summarise(values[metric].get(key, []))
        rows.append(
            {"table": table, "agents": agents, "method": method, "gamma": gamma, "round": rnd,
             "metric": metric, **asdict(cell), "paper": ref}
        )  # fmt: skip

    def add_pair(table: str, a: str, b: str, gamma: float, rnd: int, metric: str, ref=None):
        name = f"{KIND_NAMES[a]}-{KIND_NAMES[b]}"
        add(
            table,
            name,
            "DOSPCoT",
            gamma,
            rnd,
            metric,
            ("cotrain", f"{a}-{b}", "-".join(PAIR_VIEWS), gamma, rnd),
            ref,
        )

    def add_baselines(table: str, kind: str, rnd: int, metric: str, baselines=BASELINES, ref=None):
        for label, method, view in baselines:
            add(table, KIND_NAMES[kind], label, None, rnd, metric, (method, kind, view, 0.3, rnd), ref)

    for metric in (m for m, _ in METRICS):
        on_paper = metric == "paper_accuracy"
        for kind in KINDS:
            add_baselines(
                "1",
                kind,
                ROUNDS,
                metric,
                ref=paper["table1_baseline"][KIND_NAMES[kind]] if on_paper else None,
            )
        for table, rnd, paper_key in (("2", 1, "table2_one_round"), ("3", ROUNDS, "table3_five_rounds")):
            for kind in KINDS:
                for gamma in GAMMAS:
                    pair_name = f"{KIND_NAMES[kind]}-{KIND_NAMES[kind]}"
                    ref = paper[paper_key][pair_name][str(gamma)] if on_paper else None
                    add_pair(table, kind, kind, gamma, rnd, metric, ref)
                add_baselines(table, kind, rnd, metric)
        for a, b in HETERO_PAIRS:
            ref = (
                paper["table4_heterogeneous_gamma_0.3"][f"{KIND_NAMES[a]}-{KIND_NAMES[b]}"]
                if on_paper
                else None
            )
            add_pair("4", a, b, 0.3, ROUNDS, metric, ref)
    for metric in ("pseudo_accuracy", "coverage"):
        for rnd in (1, ROUNDS):
            for kind in KINDS:
                for gamma in GAMMAS:
                    add_pair("pseudo", kind, kind, gamma, rnd, metric)
                add_baselines("pseudo", kind, rnd, metric, baselines=BASELINES[3:])
    return rows


def target_check(rows: list[dict]) -> dict:
    """Issue target: ESARSA-ESARSA DOSPCoT (gamma 0.3, 5 rounds) reaches >= 95% of the oracle's
    optimal-action agreement and beats masked-zero and labels-only with non-overlapping intervals."""

    def find(agents: str, method: str, gamma: float | None) -> dict:
        return next(
            r
            for r in rows
            if r["table"] == "3"
            and r["metric"] == "agreement"
            and r["agents"] == agents
            and r["method"] == method
            and r["gamma"] == gamma
        )

    ours = find("ESARSA-ESARSA", "DOSPCoT", 0.3)
    oracle, zero, labels = (find("ESARSA", m, None) for m in ("oracle", "masked-zero", "labels-only"))
    ratio = ours["mean"] / oracle["mean"]
    return {
        "dospcot_agreement": ours["mean"],
        "oracle_agreement": oracle["mean"],
        "ratio_to_oracle": ratio,
        "meets_95pct_of_oracle": bool(ratio >= 0.95),
        "beats_masked_zero": bool(ours["low"] > zero["high"]),
        "beats_labels_only": bool(ours["low"] > labels["high"]),
    }


def _cell(row: dict) -> str:
    """A table row's figure over seeds, as text: mean [95% interval]."""
    return str(SeedSummary(*[row[k] for k in ("mean", "low", "high", "iqm", "n")]))


def _table_md(rows: list[dict], table: str, metric: str, with_gamma: bool) -> list[str]:
    sel = [r for r in rows if r["table"] == table and r["metric"] == metric]
    lines = []
    if with_gamma:
        lines += [
            "| agents | method | γ = 0.3 | γ = 0.5 | γ = 0.8 | paper (0.3 / 0.5 / 0.8) |",
            "|---|---|---|---|---|---|",
        ]
        seen = []
        for r in sel:
            if (r["agents"], r["method"]) not in seen:
                seen.append((r["agents"], r["method"]))
        for agents, method in seen:
            group = [r for r in sel if r["agents"] == agents and r["method"] == method]
            if group[0]["gamma"] is None:
                cells = [_cell(group[0]), "(no γ)", ""]
                paper = ""
            else:
                cells = [_cell(r) for r in group]
                refs = [r["paper"] for r in group]
                paper = " / ".join(f"{x:.4f}" for x in refs) if refs[0] is not None else ""
            lines.append(f"| {agents} | {method} | " + " | ".join(cells) + f" | {paper} |")
    else:
        lines += ["| agents | method | ours | paper |", "|---|---|---|---|"]
        for r in sel:
            paper = f"{r['paper']:.4f}" if r["paper"] is not None else ""
            lines.append(f"| {r['agents']} | {r['method']} | {_cell(r)} | {paper} |")
    return lines


def render_markdown(rows: list[dict], header: dict, target: dict) -> str:
    """tables.md: the four tables for each metric, the pseudo-reward table and the target line."""
    out = [
        "# Seed paper reproduction: masked CliffWalking-v1",
        "",
        f"Command: `{header['command']}`  ",
        f"Preset: `{header['preset']}` (learning rate {header['learning_rate']}, discount "
        f"{header['discount']}, exploration {header['eps']}, {header['rounds']} rounds of "
        f"{header['episodes_per_round']} episodes of at most 100 steps), label fraction "
        f"{header['label_fraction']}, seeds {header['seeds']}.  ",
        f"Machine: {header['machine']}; wall time {header['wall_time_s']:.1f} s.",
        "",
        "Each cell: mean over seeds [95% bootstrap interval]. A pair's figure is the mean of its two "
        "agents. Baseline rows are single agents of the pair's kind, read at the same round; they do "
        "not depend on γ. The paper's figures come from runs whose rewards were never masked.",
        "",
        f"**Target** (ESARSA-ESARSA, γ 0.3, 5 rounds, optimal-action agreement): "
        f"{target['dospcot_agreement']:.3f} = {100 * target['ratio_to_oracle']:.1f}% of the oracle's "
        f"{target['oracle_agreement']:.3f} (needs ≥ 95%: "
        f"{'met' if target['meets_95pct_of_oracle'] else 'NOT met'}); interval above masked-zero: "
        f"{'yes' if target['beats_masked_zero'] else 'NO'}; above labels-only: "
        f"{'yes' if target['beats_labels_only'] else 'NO'}.",
        "",
    ]
    titles = {
        "1": "Table 1: each agent alone, after 5 rounds",
        "2": "Table 2: homogeneous pairs after 1 round",
        "3": "Table 3: homogeneous pairs after 5 rounds",
        "4": "Table 4: Expected SARSA with other agents, γ = 0.3, after 5 rounds",
    }
    for metric, description in METRICS:
        out += [f"## {description}", ""]
        for table, title in titles.items():
            out += [f"### {title}", ""]
            out += _table_md(rows, table, metric, with_gamma=table in ("2", "3"))
            out.append("")
    for metric, description in (
        ("pseudo_accuracy", "Pseudo-reward accuracy (admitted unlabelled keys)"),
        ("coverage", "Coverage (admitted share of the unlabelled pool)"),
    ):
        for rnd in (1, ROUNDS):
            out += [f"## {description}, round {rnd}", ""]
            sub = [
                dict(r, table=f"p{rnd}")
                for r in rows
                if r["table"] == "pseudo" and r["metric"] == metric and r["round"] == rnd
            ]
            out += _table_md(sub, f"p{rnd}", metric, with_gamma=True)
            out.append("")
    return "\n".join(out)


def machine_description() -> str:
    """CPU, core count and Python version, for the tables' header."""
    cpu = platform.processor() or platform.machine()
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def reproduce_paper(
    preset: str = "paper-text",
    label_fraction: float = 0.1,
    seeds: Sequence[int] = tuple(range(10)),
    episodes: int = 500,
    workers: int = 2,
    out_dir: Path = Path("runs/paper"),
    command: str = "dospcot reproduce-paper",
    show_progress: bool = True,
) -> Path:
    """Run the protocol, write ``tables.md``, ``tables.csv``, ``metrics.csv``, ``config.json`` and
    ``summary.json`` under ``out_dir/<stamp>/``; return that folder."""
    config = protocol_config(preset, label_fraction, episodes)
    start = time.perf_counter()
    records = train_protocol(config, seeds, workers=workers, show_progress=show_progress)
    wall = time.perf_counter() - start
    run_dir = out_dir / time.strftime("%Y%m%d-%H%M%S")
    run_dir.mkdir(parents=True, exist_ok=True)
    rows = build_tables(records, metrics.paper_tables())
    target = target_check(rows)
    header = {
        "command": command,
        "preset": preset,
        "label_fraction": label_fraction,
        "seeds": list(seeds),
        "learning_rate": config.learning_rate,
        "discount": config.discount,
        "eps": config.eps_start,
        "rounds": config.rounds,
        "episodes_per_round": config.episodes_per_round,
        "machine": machine_description(),
        "wall_time_s": wall,
        "workers": workers,
    }
    (run_dir / "tables.md").write_text(render_markdown(rows, header, target))
    _write_csv(run_dir / "tables.csv", rows)
    _write_csv(run_dir / "metrics.csv", records)
    (run_dir / "config.json").write_text(
        json.dumps({**header, "config": asdict(config)}, indent=1, default=str)
    )
    (run_dir / "summary.json").write_text(json.dumps({"target": target, "wall_time_s": wall}, indent=1))
    return run_dir


def _write_csv(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
