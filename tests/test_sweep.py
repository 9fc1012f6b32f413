"""`dospcot sweep` (local and Ray backends, resume after a kill) and `dospcot report` (by hand)."""

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from small_runs import MECHANISMS, PINNED

from dospcot.cli import main
from dospcot.cli.parser import parse_seeds
from dospcot.config.errors import ConfigError
from dospcot.config.presets import preset_names
from dospcot.run import run_folder
from dospcot.run.cores import usable_cores
from dospcot.sweeps.report import load_runs, write_report
from dospcot.sweeps.sweep import run_sweep
from dospcot.sweeps.sweep_spec import (
    SweepError,
    SweepSpec,
    Trial,
    open_sweep,
    parse_grid,
    seeds_option,
    stale_trials,
    trial_dir,
)
from dospcot.tasks import load_config

GRID = {"training.label_fraction": ("0.1", "0.5"), "cotraining.consensus_weight": ("0", "0.3")}


def _summaries(sweep_dir: Path) -> dict[str, str]:
    return {
        str(path.parent.relative_to(sweep_dir)): path.read_text()
        for path in sorted(sweep_dir.glob("trials/*/*/summary.json"))
    }


def test_parse_grid_keeps_lists_whole_and_rejects_bad_items():
    grid = parse_grid(["training.label_fraction=0.01, 0.1", 'views=["patch", "rays"],["patch"]'])
    assert grid == {"training.label_fraction": ("0.01", "0.1"), "views": ('["patch", "rays"]', '["patch"]')}
    trial = Trial("grid16-dospcot", "grid16-dospcot", {"views": '["patch", "rays"]'}, 3)
    assert trial.trial_id == "grid16-dospcot/views=patch+rays__seed=3"
    assert load_config(trial.config, trial.overrides()).views == ("patch", "rays")
    for bad, message in [
        ("training.label_fraction", "--grid takes key=v1,v2"),
        ("training.label_fraction=", "--grid takes key=v1,v2"),
        ("training.label_fraction=0.1,,0.2", "--grid takes key=v1,v2"),
        ("seed=1,2", "use --seeds for seeds"),
    ]:
        with pytest.raises(ConfigError, match=message):
            parse_grid([bad])
    with pytest.raises(ConfigError, match="given twice"):
        parse_grid(["cotraining.consensus_weight=0", "cotraining.consensus_weight=0.3"])
    with pytest.raises(ConfigError, match="label_fraction"):
        SweepSpec(("tiny",), {"training.label_fraction": ("0.1", "1.5")}, defaults=MECHANISMS).trials()


def test_a_trial_whose_folder_name_would_pass_255_bytes_gets_a_shortened_one_of_its_own(tmp_path):
    # The confirmatory label-budget study's Unlock arm: eight grid values, 265 bytes of folder name.
    params = {
        "gym.env_id": "minigrid:MiniGrid-Unlock-v0",
        "gym.episode_steps": "288",
        "training.label_budget": "100",
        "training.label_strategy": "outcomes+disagreement",
        "training.query_schedule": "decay",
        "cotraining.refit_new_classes": "true",
        "training.exploration": "rounds",
        "training.agent_draws": "own",
    }
    trial = Trial("minigrid-doorkey-dospcot", "minigrid-doorkey-dospcot", params, 100)
    name, folder = trial.trial_id.split("/")
    assert name == "minigrid-doorkey-dospcot" and len(folder.encode()) == 255
    assert folder.startswith("gym.env_id=minigridMiniGrid-Unlock-v0__gym.episode_steps=288__")
    assert folder.endswith("__seed=100")
    others = [
        Trial(trial.config, trial.name, params, 101),
        Trial(trial.config, trial.name, {**params, "training.agent_draws": "shared"}, 100),
    ]
    assert len({trial.trial_id, *(t.trial_id for t in others)}) == 3
    (trial_dir(tmp_path, trial) / "config.toml").parent.mkdir(parents=True)
    (trial_dir(tmp_path, trial) / "config.toml").write_text("")  # the file system takes it
    assert [p.name for p in (tmp_path / "trials" / name).iterdir()] == [folder]


@pytest.mark.slow  # over 30 s on 2 cores: `make test-slow`; the fast tests below resume and skip trials
def test_local_sweep_runs_every_trial_once_whatever_its_workers_and_reruns_nothing(tmp_path):
    spec = SweepSpec(("tiny",), GRID, (0, 1), defaults=MECHANISMS)
    result = run_sweep(tmp_path / "sweep", spec, workers=2, show_progress=False)
    assert len(result.trials) == 8 and len(result.ran) == 8 and not result.skipped and not result.failed
    summaries = _summaries(tmp_path / "sweep")
    assert len(summaries) == 8
    for trial in result.trials:
        cfg = load_config(str(tmp_path / "sweep" / "trials" / trial.trial_id / "config.toml"))
        assert (cfg.training.label_fraction, cfg.cotraining.consensus_weight, cfg.seed) == (
            float(trial.params["training.label_fraction"]),
            float(trial.params["cotraining.consensus_weight"]),
            trial.seed,
        )
    again = run_sweep(tmp_path / "sweep", spec, workers=2, show_progress=False)
    assert len(again.skipped) == 8 and not again.ran
    assert _summaries(tmp_path / "sweep") == summaries
    with pytest.raises(SweepError, match="holds another sweep"):
        open_sweep(tmp_path / "sweep", SweepSpec(("tiny",), GRID, (0, 1, 2), defaults=MECHANISMS))
    # --workers defaults to the cores, so no trial's numbers may depend on it: the last trial, which ran
    # after others in one of the pool's two processes, alone in a sweep of one worker gives the same files.
    last = result.trials[-1]
    alone = SweepSpec(
        (last.config,),
        {key: (value,) for key, value in last.params.items()},
        (last.seed,),
        defaults=MECHANISMS,
    )
    run_sweep(tmp_path / "alone", alone, workers=1, show_progress=False)
    for name in ("metrics.csv", "summary.json"):
        alone_file, pool_file = (trial_dir(tmp_path / s, last) / name for s in ("alone", "sweep"))
        assert alone_file.read_bytes() == pool_file.read_bytes(), name


def test_the_cores_are_the_process_affinity_where_the_platform_has_one(monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 3}, raising=False)
    assert usable_cores() == 2
    monkeypatch.delattr(os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 6)
    assert usable_cores() == 6
    monkeypatch.setattr(os, "cpu_count", lambda: None)  # undeterminable
    assert usable_cores() == 1


ROOT = Path(__file__).resolve().parent.parent
ONE_TRIAL = SweepSpec(("tiny",), {}, (0,))


@pytest.fixture(scope="module")
def one_trial_sweep(tmp_path_factory) -> Path:
    """A finished sweep of ``ONE_TRIAL`` (tiny, seed 0), run once for the module: tests copy it where they
    change it."""
    sweep_dir = tmp_path_factory.mktemp("one-trial") / "s"
    result = run_sweep(sweep_dir, ONE_TRIAL, workers=1, show_progress=False)
    assert len(result.ran) == 1 and not result.failed
    return sweep_dir


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


@pytest.mark.skipif(_git("rev-parse", "HEAD").returncode != 0, reason="needs the git checkout")
def test_the_files_git_keeps_of_a_sweep_render_it_and_resume_it_elsewhere(one_trial_sweep, tmp_path):
    """runs/README.md: the repository keeps each trial's small files under runs/sweeps, enough to
    rebuild the tables and to skip finished trials on another machine; agents and events stay out."""
    sweep = tmp_path / "runs" / "sweeps" / "s"
    spec = ONE_TRIAL
    shutil.copytree(one_trial_sweep, sweep)  # the sweep as run_sweep left it
    files = [path.relative_to(tmp_path) for path in sweep.rglob("*") if path.is_file()]
    ignored = _git("check-ignore", "--no-index", *map(str, files)).stdout.split()
    kept = [f for f in files if str(f) not in ignored]
    assert {f.name for f in kept} == {
        "sweep.json",
        "trial.json",
        "config.toml",
        "run_info.json",
        "metrics.csv",
        "summary.json",
        "reward_classes.json",
        "pseudo_rewards.csv",
        "queries.csv",  # the adopted defaults buy the labels
    }
    assert any(f.suffix == ".zip" for f in files) and any("tb" in f.parts for f in files)
    elsewhere = tmp_path / "elsewhere"
    for f in kept:
        (elsewhere / f).parent.mkdir(parents=True, exist_ok=True)
        (elsewhere / f).write_bytes((tmp_path / f).read_bytes())
    moved = elsewhere / "runs" / "sweeps" / "s"
    assert _summaries(moved) == _summaries(sweep)
    assert len(run_sweep(moved, spec, workers=1, show_progress=False).skipped) == 1
    assert [run.summary for run in load_runs(moved)[1]] == [run.summary for run in load_runs(sweep)[1]]
    # Each run names the source that trained it, so a study resumed at another commit shows it.
    (run_dir,) = (moved / "trials" / "tiny").iterdir()
    info = json.loads((run_dir / "run_info.json").read_text())
    assert info["commit"].split("+")[0] == _git("rev-parse", "HEAD").stdout.strip()
    # ... and the CPU kernels, as another instruction set may end the same seed elsewhere.
    assert info["cpu"].endswith(f", torch kernels {torch.backends.cpu.get_cpu_capability()}")


def test_a_trial_run_under_another_config_stops_the_sweep_with_one_line(one_trial_sweep, tmp_path):
    """A sweep folder may outlive its presets (the studies keep theirs): a trial whose stored config
    differs from what its preset gives now is neither counted nor resumed, and the sweep names it."""
    spec = ONE_TRIAL
    shutil.copytree(one_trial_sweep, tmp_path / "s")  # the sweep as run_sweep left it
    (stored,) = (tmp_path / "s").glob("trials/tiny/*/config.toml")
    stored.write_text(stored.read_text().replace("steps_per_round = 300", "steps_per_round = 200"))
    message = r"1 trial\(s\) .* tiny/seed=0: training.steps_per_round was 200, is 300"
    with pytest.raises(SweepError, match=message):
        run_sweep(tmp_path / "s", spec, workers=1, show_progress=False)


def test_the_stale_check_resolves_a_combination_once_and_still_reads_each_trials_seed(tmp_path):
    """The check resolves a combination's config once and gives each trial its seed: sound because a
    seed moves no other key, under any preset and version."""
    for preset in preset_names():
        for defaults in (1, 11):
            assert load_config(preset, ["seed=7"], defaults) == replace(
                load_config(preset, [], defaults), seed=7
            )
    trials = [Trial("tiny", "tiny", {}, seed, ()) for seed in (0, 1, 2)]
    for trial in trials:
        stored = trial_dir(tmp_path, trial) / "config.toml"
        stored.parent.mkdir(parents=True)
        # seed 2's folder holds seed 1's config
        run_folder.write_toml(stored, load_config("tiny", [f"seed={min(trial.seed, 1)}"]).to_dict())
    assert stale_trials(tmp_path, trials) == [("tiny/seed=2", "seed was 1, is 2")]


@pytest.mark.slow  # over 30 s on 2 cores: `make test-slow`
def test_ray_backend_runs_the_same_trials_to_the_same_summaries(tmp_path):
    ray = pytest.importorskip("ray", reason="the `ray` extra is not installed (pip install 'dospcot[ray]')")
    spec = SweepSpec(("tiny",), GRID, (0, 1), defaults=MECHANISMS)
    local = run_sweep(tmp_path / "local", spec, workers=2, show_progress=False)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        remote = run_sweep(tmp_path / "ray", spec, backend="ray", workers=2)
    finally:
        ray.shutdown()
    assert not local.failed and not remote.failed and len(remote.ran) == 8
    # Same trials, same folders, same results: the backend only decides where a trial runs.
    assert _summaries(tmp_path / "ray") == _summaries(tmp_path / "local")


@pytest.mark.slow
def test_a_killed_sweep_resumes_by_running_only_the_missing_trials(tmp_path):
    sweep_dir = tmp_path / "killed"
    cmd = [sys.executable, "-m", "dospcot", "sweep", "tiny", "--seeds", "4", "--workers", "1"]
    cmd += ["--runs-dir", str(tmp_path), "--name", "killed", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while len(list(sweep_dir.glob("trials/*/*/summary.json"))) < 2:
            assert proc.poll() is None and time.monotonic() < deadline, "the sweep ended before the kill"
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)  # the parent and its pool's worker, mid-trial
    finally:
        proc.wait()
    finished = {p.parent.name: p.stat().st_mtime_ns for p in sweep_dir.glob("trials/*/*/summary.json")}
    assert 2 <= len(finished) < 4
    assert main(["sweep", "--resume", str(sweep_dir), "--workers", "1", "--no-progress"]) == 0
    after = {p.parent.name: p.stat().st_mtime_ns for p in sweep_dir.glob("trials/*/*/summary.json")}
    assert len(after) == 4
    assert {name: after[name] for name in finished} == finished  # finished trials were not run again
    result = run_sweep(sweep_dir, workers=1, show_progress=False)
    assert not result.ran and len(result.skipped) == 4


def _descendants(pid: int) -> set[int]:
    """The process ids below ``pid`` (Linux: /proc)."""
    found: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        for child in map(int, task.read_text().split()):
            found |= {child, *_descendants(child)}
    return found


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="reads the process tree from /proc")
def test_the_workers_of_a_sweep_killed_alone_exit_with_it(tmp_path):
    cmd = [sys.executable, "-m", "dospcot", "sweep", "tiny", "--seeds", "8", "--workers", "1"]
    cmd += ["--runs-dir", str(tmp_path), "--name", "orphans", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:  # the pool's worker, the manager that carries progress reports, multiprocessing's tracker
        deadline = time.monotonic() + 180
        while not list(tmp_path.glob("orphans/trials/*/*/tb")):  # a worker is training its first trial
            assert proc.poll() is None and time.monotonic() < deadline, "the sweep ended before the kill"
            time.sleep(0.05)
        children = _descendants(proc.pid)
        assert children, "the sweep has no worker to watch"
        proc.kill()  # the parent only, as `kill -9 PID` does: its workers see it gone
        proc.wait()
        deadline = time.monotonic() + 60
        while alive := {c for c in children if Path(f"/proc/{c}").exists() and _state(c) != "Z"}:
            assert time.monotonic() < deadline, f"processes {sorted(alive)} outlived their sweep"
            time.sleep(0.2)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _state(pid: int) -> str:
    """A process's state letter ("Z": a zombie, gone but not yet reaped); "" once it is gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return ""


def _synthetic_sweep(root: Path, scores: dict[str, list[float]]) -> Path:
    """A sweep folder written by hand: config `a`, grid over the label fraction, seeds 0-3."""
    sweep_dir = root / "synthetic"
    spec = SweepSpec(("a",), {"training.label_fraction": tuple(scores)}, (0, 1, 2, 3), defaults=MECHANISMS)
    open_sweep(sweep_dir, spec)
    for fraction, values in scores.items():
        for seed, score in enumerate(values):
            trial = Trial("a", "a", {"training.label_fraction": fraction}, seed)
            folder = sweep_dir / "trials" / trial.trial_id
            folder.mkdir(parents=True)
            data = {"config": "a", "name": "a", "params": trial.params, "seed": seed, "base_overrides": []}
            (folder / "trial.json").write_text(json.dumps(data))
            # A run folder holds its config, written first.
            cfg = load_config("tiny", [*PINNED, f"training.label_fraction={fraction}", f"seed={seed}"])
            run_folder.write_toml(folder / "config.toml", cfg.to_dict())
            if math.isinf(score):  # an unfinished trial: no summary.json
                continue
            mean = {"normalised_score": score, "success": 1.0, "agreement": 0.5, "pseudo_accuracy": math.nan}
            (folder / "summary.json").write_text(json.dumps({"mean": {**mean, "coverage": 0.25}}))
            rows = "round,view,env_steps,normalised_score,pseudo_accuracy\n"
            rows += "".join(f"{r},v,{100 * r},{score / r},nan\n" for r in (1, 2))
            (folder / "metrics.csv").write_text(rows)
    return sweep_dir


def test_report_on_synthetic_summaries_gives_hand_checked_figures(tmp_path):
    sweep_dir = _synthetic_sweep(
        tmp_path,
        {"0.1": [0.0, 1.0, 0.0, 1.0], "0.5": [1.0, 2.0, 3.0, 10.0], "1.0": [2.0, 2.0, 2.0, math.inf]},
    )
    paths = write_report(sweep_dir)
    with (sweep_dir / "report.csv").open() as handle:
        rows = {(r["training.label_fraction"], r["metric"]): r for r in csv.DictReader(handle)}
    score = {fraction: rows[(fraction, "normalised_score")] for fraction in ("0.1", "0.5", "1.0")}
    # {0, 1, 0, 1}: mean 0.5; IQM drops one value at each end -> mean(0, 1) = 0.5. A bootstrap mean of
    # four draws is 0 or 1 with probability 1/16 each (> 2.5%), so the 95% interval is [0, 1].
    assert [float(score["0.1"][k]) for k in ("mean", "iqm", "ci_low", "ci_high")] == [0.5, 0.5, 0.0, 1.0]
    # {1, 2, 3, 10}: mean 4, IQM mean(2, 3) = 2.5; the interval lies within [1, 10] and holds the mean.
    assert float(score["0.5"]["mean"]) == 4.0 and float(score["0.5"]["iqm"]) == 2.5
    assert 1.0 <= float(score["0.5"]["ci_low"]) < 4.0 < float(score["0.5"]["ci_high"]) <= 10.0
    # Three finished seeds of 2.0 (the fourth has no summary): every figure is 2.
    assert score["1.0"]["n"] == "3" and score["1.0"]["seeds"] == "0 1 2"
    assert {float(score["1.0"][k]) for k in ("mean", "iqm", "ci_low", "ci_high")} == {2.0}
    # No finite pseudo-reward accuracy (no co-training): counted as no seeds, shown as n/a.
    assert rows[("0.1", "pseudo_accuracy")]["n"] == "0"
    text = (sweep_dir / "report.md").read_text()
    assert "| a | 0.1 | 4 | 0.500 [0.000, 1.000] | 0.500 |" in text
    assert "(11 of 12 trials finished)" in text and "| a | 0.1 | 0 | n/a | n/a |" in text
    names = {p.name for p in paths}
    assert {"learning_curves.png", "score_vs_label_fraction.png"} <= names
    assert "pseudo_accuracy.png" not in names  # nothing finite to draw
    for path in paths:
        if path.suffix == ".png":
            assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    _, runs = load_runs(sweep_dir)
    assert [(r.trial.params["training.label_fraction"], r.trial.seed) for r in runs][:5] == [
        ("0.1", 0),
        ("0.1", 1),
        ("0.1", 2),
        ("0.1", 3),
        ("0.5", 0),
    ]


def test_the_per_view_table_shows_which_views_agent_failed_where_the_mean_hides_it(tmp_path):
    sweep_dir = _synthetic_sweep(tmp_path, {"0.1": [1.0] * 4, "0.5": [1.0] * 4})
    # Fraction 0.1: the patch agent reaches the goal on every seed, the rays agent on seeds 1 and 3,
    # so the mean over agents (0.75) names no culprit. Fraction 0.5 trains one view: no per-view rows.
    for seed in range(4):
        for fraction, views in (("0.1", ("patch", "rays")), ("0.5", ("patch",))):
            path = (
                sweep_dir / "trials" / Trial("a", "a", {"training.label_fraction": fraction}, seed).trial_id
            )
            summary = json.loads((path / "summary.json").read_text())
            agent = {"patch": (1.0, -17.0, 0.9), "rays": (float(seed % 2), -17.0 - 47 * (1 - seed % 2), 0.8)}
            summary["per_view"] = {
                v: dict(zip(("success", "greedy_return", "agreement"), agent[v], strict=True)) for v in views
            }
            (path / "summary.json").write_text(json.dumps(summary))
    paths = write_report(sweep_dir)
    assert sweep_dir / "report_per_view.csv" in paths
    with (sweep_dir / "report_per_view.csv").open() as handle:
        rows = {(r["training.label_fraction"], r["view"], r["metric"]): r for r in csv.DictReader(handle)}
    assert {fraction for fraction, _, _ in rows} == {"0.1"}
    assert float(rows[("0.1", "patch", "success")]["mean"]) == 1.0
    assert (
        float(rows[("0.1", "rays", "success")]["mean"]) == 0.5
        and rows[("0.1", "rays", "success")]["n"] == "4"
    )
    # Greedy returns -64, -17, -64, -17: mean -40.5.
    assert float(rows[("0.1", "rays", "greedy_return")]["mean"]) == -40.5
    text = (sweep_dir / "report.md").read_text()
    assert (
        "| config | label_fraction | view | seeds | success | greedy return | optimal-action agreement |"
        in text
    )
    assert (
        "| a | 0.1 | patch | 4 | 1.000 [1.000, 1.000] | -17.0 [-17.0, -17.0] | 0.900 [0.900, 0.900] |" in text
    )
    assert "| a | 0.1 | rays | 4 | 0.500 [" in text and "| a | 0.5 | patch |" not in text


@pytest.mark.slow
def test_resume_with_more_seeds_runs_only_the_new_seeds_and_refuses_to_drop_one(tmp_path, capsys):
    sweep_dir, quiet = tmp_path / "tiny", ["--workers", "1", "--no-progress"]
    one_round = ["--set", "training.rounds=1", "--runs-dir", str(tmp_path)]
    assert main(["sweep", "tiny", *one_round, *quiet]) == 0
    first = _summaries(sweep_dir)
    assert len(first) == 1
    capsys.readouterr()
    assert main(["sweep", "--resume", str(sweep_dir), "--seeds", "2", *quiet]) == 0
    assert "2 trials; 1 already finished, 1 run now, 0 failed" in capsys.readouterr().out
    assert json.loads((sweep_dir / "sweep.json").read_text())["seeds"] == [0, 1]
    summaries = _summaries(sweep_dir)
    assert len(summaries) == 2 and {k: summaries[k] for k in first} == first
    added = json.loads(next(v for k, v in summaries.items() if k not in first))
    assert added["seed"] == 1
    before = (sweep_dir / "sweep.json").read_text()
    assert main(["sweep", "--resume", str(sweep_dir), "--seeds", "1,2"]) == 2
    err = capsys.readouterr().err
    assert "--seeds would drop seed(s) 0 of the sweep in" in err and err.count("\n") == 1
    assert (sweep_dir / "sweep.json").read_text() == before
    # The same sweep with more seeds, named as a new one, says how to add them.
    assert main(["sweep", "tiny", *one_round, "--seeds", "3"]) == 2
    assert f"to add seeds to it: dospcot sweep --resume {sweep_dir} --seeds 0-2" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["sweep"], "give at least one CONFIG"),
        (["sweep", "tiny", "--grid", "training.rounds"], "--grid takes key=v1,v2"),
        (["sweep", "tiny", "--grid", "training.nokey=1,2"], "unknown key 'training.nokey'"),
        (["sweep", "tiny", "--backend", "dask"], "invalid choice: 'dask'"),
        (["sweep", "tiny", "--seeds", "0"], "--seeds 0 gives no seed: give a count >= 1 (10)"),
        (["sweep", "tiny", "--seeds", "1,1"], "--seeds takes distinct seeds >= 0, got '1,1'"),
        (["sweep", "--resume", "/nonexistent"], "is not a sweep folder"),
        (["report", "/nonexistent"], "is not a sweep folder"),
    ],
)
def test_sweep_and_report_bad_arguments_fail_with_one_line(args, message, tmp_path, capsys):
    extra = ["--runs-dir", str(tmp_path)] if args[:1] == ["sweep"] else []
    try:
        code = main([*args, *extra])
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not list(tmp_path.iterdir())  # nothing was written


def test_a_run_outside_a_git_checkout_records_no_commit(monkeypatch):
    """An installed wheel has no checkout to name: the commit is None, and nothing fails."""

    def no_git(*args, **kwargs):
        raise OSError("git: not found")

    monkeypatch.setattr(run_folder.subprocess, "run", no_git)
    run_folder.source_commit.cache_clear()  # asked once per process: ask again
    try:
        assert run_folder.source_commit() is None
    finally:
        run_folder.source_commit.cache_clear()


def test_changed_run_records_do_not_mark_the_source_dirty(tmp_path):
    """A study rerun into its record rewrites tracked files under runs/: the code is still clean."""
    (tmp_path / "runs").mkdir()
    (tmp_path / "code.py").write_text("x = 1\n")
    (tmp_path / "runs" / "summary.json").write_text("{}\n")
    here = ("-C", str(tmp_path))  # a later -C wins over _git's checkout
    commit = ("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "record")
    for args in (("init", "-q"), ("add", "."), commit):
        assert _git(*here, *args).returncode == 0
    head = _git(*here, "rev-parse", "HEAD").stdout.strip()
    (tmp_path / "runs" / "summary.json").write_text('{"success": 1.0}\n')
    try:
        assert run_folder.source_commit(tmp_path) == head
        (tmp_path / "code.py").write_text("x = 2\n")
        run_folder.source_commit.cache_clear()  # asked once per process: ask again
        assert run_folder.source_commit(tmp_path) == head + "+dirty"
    finally:
        run_folder.source_commit.cache_clear()


@pytest.mark.parametrize(
    ("seeds", "text"), [((0, 1, 2), "0-2"), ((100, 101), "100-101"), ((5,), "5-5"), ((0, 4, 9), "0,4,9")]
)
def test_the_seeds_a_message_suggests_read_back_as_those_seeds(seeds, text):
    assert seeds_option(seeds) == text
    assert list(parse_seeds(text)) == list(seeds)
