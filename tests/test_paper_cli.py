"""The reproduce-paper protocol, its tables, its sweep and report, and the command line."""

import csv
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from dospcot.cli import main
from dospcot.config.errors import ConfigError
from dospcot.config.presets import PAPER_PRESETS
from dospcot.run.paper_protocol import protocol_specs, train_protocol_at
from dospcot.statistics import SeedSummary
from dospcot.sweeps.paper_tables import cell_summary
from dospcot.sweeps.report import write_report
from dospcot.sweeps.sweep import plan_jobs, run_sweep
from dospcot.sweeps.sweep_spec import SweepError, SweepSpec, Trial
from dospcot.tasks import load_config

# Five episodes a round and short classifier fits: every file and figure of the protocol in seconds.
QUICK = ["tabular.episodes_per_round=5", "tabular.cotraining.classifier.epochs=10"]


def test_protocol_has_every_run_of_the_four_tables():
    specs = protocol_specs([0])
    pairs = {(s.agents, s.gamma) for s in specs if len(s.agents) == 2}
    assert len(specs) == 26 and sum(len(s.agents) for s in specs) == 37
    for kind in ("q", "sarsa", "esarsa"):
        assert {((kind, kind), g) for g in (0.3, 0.5, 0.8)} <= pairs
    assert {(("esarsa", "sarsa"), 0.3), (("esarsa", "q"), 0.3)} <= pairs


def test_paper_presets_hold_the_papers_hyperparameters():
    text, code = (load_config(PAPER_PRESETS[name]).tabular for name in ("paper-text", "published-code"))
    assert (text.learning_rate, text.discount, code.learning_rate, code.discount) == (0.8, 0.95, 0.5, 1.0)
    for cfg in (text, code):
        assert (cfg.rounds, cfg.episodes_per_round, cfg.eps_start, cfg.eps_end) == (5, 500, 0.1, 0.1)
        assert cfg.label_fraction == 0.1
    with pytest.raises(
        ConfigError, match="paper-protocol config, which has no 'views' \\(a key of a dospcot train"
    ):
        load_config("paper-text", ['views=["patch"]'])
    allowed = "name, seed, defaults, task, tabular"
    with pytest.raises(ConfigError, match=f"unknown key 'nokey'; allowed: {allowed}"):
        load_config("paper-text", ["nokey=1"])
    with pytest.raises(ConfigError, match=r"tabular: label_fraction must lie in \(0, 1\]"):
        load_config("paper-text", ["tabular.label_fraction=0"])


def test_summary_cell_by_hand():
    cell = cell_summary([1.0, 2.0, 3.0, float("nan")])
    assert cell.mean == 2.0 and cell.n == 3 and cell.low <= 2.0 <= cell.high
    assert str(SeedSummary(0.5, 0.25, 0.75, float("nan"), 3)) == "0.500 [0.250, 0.750]"
    assert str(SeedSummary(-13.0, -15.0, -13.0, float("nan"), 3)) == "-13.0 [-15.0, -13.0]"


def test_a_seeds_folder_is_the_same_trained_alone_or_in_a_batch(tmp_path):
    cfg = load_config("paper-text", QUICK)
    train_protocol_at(cfg, {0: tmp_path / "b0", 1: tmp_path / "b1"})
    for seed in (0, 1):
        train_protocol_at(cfg, {seed: tmp_path / f"a{seed}"})
        for name in ("config.toml", "metrics.csv", "summary.json"):
            assert (tmp_path / f"a{seed}" / name).read_bytes() == (tmp_path / f"b{seed}" / name).read_bytes()
    assert load_config(str(tmp_path / "b1" / "config.toml")).seed == 1
    info = json.loads((tmp_path / "b1" / "run_info.json").read_text())
    assert info["batch_seeds"] == [0, 1]


def test_the_local_backend_batches_a_paper_cells_seeds_over_its_workers():
    def trials(config, seeds, params=None):
        return [
            Trial(config, "x", params or {}, seed, tuple(QUICK) if "paper" in config else ())
            for seed in seeds
        ]

    paper = trials("paper-text", range(5))
    other = trials("paper-text", range(2), {"tabular.label_fraction": "0.2"})
    assert plan_jobs([*paper, *other], workers=2) == [paper[0::2], paper[1::2], other[:1], other[1:]]
    tiny = trials("tiny", range(3))
    assert plan_jobs(tiny, workers=2) == [[t] for t in tiny]
    with pytest.raises(SweepError, match=r"paper-protocol configs .* or train configs, not both"):
        SweepSpec(("paper-text", "tiny"), {}, (0,)).trials()


@pytest.mark.slow
def test_report_of_a_paper_sweep_gives_the_hand_computed_figures(tmp_path):
    spec = SweepSpec(("paper-text",), {}, (0, 1, 2), tuple(QUICK))
    assert not run_sweep(tmp_path / "sweep", spec, workers=2, show_progress=False).failed
    # A paper cell's seeds run together whatever --batch-seeds says: resuming with another K is no
    # reason to refuse, and the trial run again gives the same file.
    seed2 = tmp_path / "sweep" / "trials" / "paper-text" / "seed=2"
    metrics = (seed2 / "metrics.csv").read_bytes()
    shutil.rmtree(seed2)
    assert not run_sweep(tmp_path / "sweep", None, workers=2, show_progress=False, batch_seeds=4).failed
    assert (seed2 / "metrics.csv").read_bytes() == metrics
    paths = write_report(tmp_path / "sweep")
    assert [p.name for p in paths] == ["report.md", "report.csv", "paper_agreement.png"]
    # By hand from the trials' metrics.csv: per seed the mean of the ESARSA pair's two agents at
    # gamma 0.3 after round 5, then the mean over seeds.
    per_seed = []
    for seed in (0, 1, 2):
        with (tmp_path / "sweep" / "trials" / "paper-text" / f"seed={seed}" / "metrics.csv").open() as f:
            rows = [
                r
                for r in csv.DictReader(f)
                if (r["method"], r["agents"], r["gamma"], r["round"])
                == ("dospcot", "esarsa-esarsa", "0.3", "5")
            ]
        assert len(rows) == 2
        per_seed.append(np.mean([float(r["agreement"]) for r in rows]))
    with (tmp_path / "sweep" / "report.csv").open() as f:
        cell = next(
            r
            for r in csv.DictReader(f)
            if (r["table"], r["agents"], r["method"], r["gamma"], r["metric"])
            == ("3", "ESARSA-ESARSA", "DOSPCoT", "0.3", "agreement")
        )
    assert float(cell["mean"]) == pytest.approx(np.mean(per_seed)) and cell["n"] == "3"
    assert cell["paper"] == "" and cell["config"] == "paper-text"
    text = paths[0].read_text()
    assert (
        f"**Target** (ESARSA-ESARSA, γ 0.3, 5 rounds, optimal-action agreement): {np.mean(per_seed):.3f}"
        in text
    )
    assert "3 of 3 trials finished" in text and "### Table 4" in text


def test_train_runs_one_seed_of_the_protocol_and_evaluate_refuses_it(tmp_path, capsys):
    sets = [item for setting in [*QUICK, "seed=4"] for item in ("--set", setting)]
    assert main(["train", "paper-text", *sets, "--runs-dir", str(tmp_path), "--no-progress"]) == 0
    (run_dir,) = (tmp_path / "paper-text").iterdir()
    assert "ESARSA-ESARSA DOSPCoT agreement" in capsys.readouterr().out
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["task"] == "paper" and summary["seed"] == 4 and summary["runs"] == 26
    with (run_dir / "metrics.csv").open() as f:
        assert len(list(csv.DictReader(f))) == 37 * 5  # every agent, every round
    assert main(["evaluate", str(run_dir)]) == 2
    assert "is a paper-protocol run: it keeps no agents" in capsys.readouterr().err


def test_cli_reproduce_paper_is_a_sweep_and_its_report(tmp_path, capsys):
    args = ["reproduce-paper", "--seeds", "0,1", "--episodes", "5", "--set", QUICK[1]]
    assert main([*args, "--workers", "1", "--out", str(tmp_path), "--no-progress"]) == 0
    (sweep_dir,) = tmp_path.iterdir()
    out = capsys.readouterr().out
    assert "Target (ESARSA-ESARSA" in out and "wall time" in out
    spec = json.loads((sweep_dir / "sweep.json").read_text())
    assert spec["configs"] == ["paper-text"] and spec["seeds"] == [0, 1]
    assert spec["overrides"] == ["tabular.episodes_per_round=5", QUICK[1]]
    with (sweep_dir / "report.csv").open() as f:
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
    # A second report of the same folder renders the same tables.
    before = (sweep_dir / "report.md").read_bytes()
    assert main(["report", str(sweep_dir)]) == 0 and (sweep_dir / "report.md").read_bytes() == before


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
def test_cli_bad_arguments_exit_nonzero_with_a_message(capfd, args, message):
    # main is what `python -m dospcot` runs: in this process, the same status and stderr (capfd reads
    # the file descriptor as well), without the process's imports of torch.
    try:
        code = main(args)
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    assert code != 0
    err = capfd.readouterr().err
    assert message in err
    assert err.count("\n") == 1  # one line, no usage block and no traceback


def test_a_bad_argument_ends_a_process_of_its_own_with_one_line():
    out = subprocess.run(
        [sys.executable, "-m", "dospcot", "reproduce-paper", "--workers", "0"], capture_output=True, text=True
    )
    assert out.returncode == 2 and out.stdout == ""
    assert "expected a positive integer" in out.stderr and out.stderr.count("\n") == 1
