"""The reproduce-paper protocol, its tables, and the command line."""

import csv
import json
import subprocess
import sys

import pytest

from dospcot.cli import main
from dospcot.metrics import SeedSummary
from dospcot.paper import build_tables, protocol_config, protocol_specs, summarise, train_protocol


def test_protocol_has_every_run_of_the_four_tables():
    specs = protocol_specs([0])
    pairs = {(s.agents, s.gamma) for s in specs if len(s.agents) == 2}
    assert len(specs) == 26 and sum(len(s.agents) for s in specs) == 37
    for kind in ("q", "sarsa", "esarsa"):
        assert {((kind, kind), g) for g in (0.3, 0.5, 0.8)} <= pairs
    assert {(("esarsa", "sarsa"), 0.3), (("esarsa", "q"), 0.3)} <= pairs
    assert protocol_config("published-code", 0.1).learning_rate == 0.5
    with pytest.raises(ValueError, match="unknown preset 'paper'"):
        protocol_config("paper", 0.1)


def test_summary_cell_by_hand():
    cell = summarise([1.0, 2.0, 3.0, float("nan")])
    assert cell.mean == 2.0 and cell.n == 3 and cell.low <= 2.0 <= cell.high
    assert str(SeedSummary(0.5, 0.25, 0.75, float("nan"), 3)) == "0.500 [0.250, 0.750]"
    assert str(SeedSummary(-13.0, -15.0, -13.0, float("nan"), 3)) == "-13.0 [-15.0, -13.0]"


def test_worker_split_does_not_change_results():
    config = protocol_config("paper-text", 0.1, episodes=5)
    one = train_protocol(config, [0, 1], workers=1, show_progress=False)
    two = train_protocol(config, [0, 1], workers=2, show_progress=False)
    key = lambda r: (r["seed"], r["method"], r["agents"], r["views"], r["gamma"], r["round"], r["agent"])  # noqa: E731
    assert json.dumps(sorted(one, key=key)) == json.dumps(sorted(two, key=key))
    rows = build_tables(one, json.loads(_paper_tables()))
    assert {r["table"] for r in rows} == {"1", "2", "3", "4", "pseudo"}


def _paper_tables():
    from importlib import resources

    return resources.files("dospcot").joinpath("data/paper_tables.json").read_text()


def test_cli_reproduce_paper_writes_tables(tmp_path, capsys):
    code = main(
        [
            "reproduce-paper",
            "--seeds",
            "0,1",
            "--episodes",
            "5",
            "--workers",
            "1",
            "--out",
            str(tmp_path),
            "--no-progress",
        ]
    )
    assert code == 0
    (run_dir,) = tmp_path.iterdir()
    for name in ("tables.md", "tables.csv", "metrics.csv", "config.json", "summary.json"):
        assert (run_dir / name).stat().st_size > 0
    with (run_dir / "tables.csv").open() as f:
        rows = list(csv.DictReader(f))
    cell = next(
        r
        for r in rows
        if r["table"] == "3"
        and r["agents"] == "ESARSA-ESARSA"
        and r["gamma"] == "0.3"
        and r["metric"] == "paper_accuracy"
    )
    assert cell["paper"] == "0.9792" and cell["n"] == "2"
    assert "wall time" in capsys.readouterr().out
    assert "**Target**" in (run_dir / "tables.md").read_text()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["reproduce-paper", "--label-fraction", "1.5"], "--label-fraction must lie in (0, 1]"),
        (["reproduce-paper", "--seeds", "abc"], "--seeds takes a count"),
        (["reproduce-paper", "--preset", "paper"], "invalid choice: 'paper'"),
        (["reproduce-paper", "--workers", "0"], "expected a positive integer"),
        (["sweep"], "give at least one CONFIG"),
        (["train"], "give a CONFIG: a preset"),
        (["evaluate"], "the following arguments are required: run_dir"),
    ],
)
def test_cli_bad_arguments_exit_nonzero_with_a_message(args, message):
    out = subprocess.run([sys.executable, "-m", "dospcot", *args], capture_output=True, text=True)
    assert out.returncode != 0
    assert message in out.stderr
    assert out.stderr.count("\n") == 1  # one line, no usage block and no traceback


def test_bench_quick_writes_every_row(tmp_path):
    out = tmp_path / "BENCHMARKS.md"
    assert main(["bench", "--quick", "--repeats", "3", "--out", str(out)]) == 0
    text = out.read_text()
    assert text.count("ExpectedSarsaDQN (target=") == 3 and "median of 3 repetitions" in text
    assert "DOSPCoT run vs its two ExpectedSarsaDQN agents alone: wall time" in text
    assert "`dospcot sweep` local backend, 2 workers vs 1: throughput" in text
    assert "Shared transition store vs the raw arrays: memory per million steps" in text
    assert "One co-training step, 100,000 vs 10,000 stored steps: growth against n log n" in text
    assert "FastHighwayVec vs highway-env's highway-fast-v0: env steps per second" in text
    assert "Tabular agents, vectorised vs a per-step Python loop: agent steps per second" in text
    assert "| ratio | target | met |" in text
