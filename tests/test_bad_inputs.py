"""Bad inputs end in one line before anything is made, run folders cannot be corrupted, and Ctrl-C stops
a sweep with the command that resumes it (docs/troubleshooting.md)."""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import os
import signal
import subprocess
import sys
import time
import tomllib
import typing
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from small_runs import PINNED

from dospcot.cli import main
from dospcot.config.errors import ConfigError
from dospcot.config.run_configs import TrainConfig
from dospcot.envs import EnvRaisedError
from dospcot.run.checks import check_config
from dospcot.run.python_api import train_env
from dospcot.run.run_folder import LOCK_FILE
from dospcot.tasks import load_config

SHORT = ["training.rounds=1", "training.steps_per_round=60", "dqn.learning_starts=20"]


def _keys(cls: type, prefix: str = "") -> list[tuple[str, typing.Any]]:
    """Every key of a config tree and its type hint."""
    keys = []
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        hint = hints[field.name]
        if dataclasses.is_dataclass(hint):
            keys += _keys(hint, f"{prefix}{field.name}.")
        else:
            keys.append((f"{prefix}{field.name}", hint))
    return keys


KEYS = [key for key, _ in _keys(TrainConfig)]
VALUES = st.sampled_from(
    [
        "nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "1",
        "3",
        "0.5",
        "2.5",
        "-0.5",
        "1e9",
        "true",
        '"x"',
        '""',
        "[1]",
        "[]",
        "{a=1}",
        "1e-12",
    ]
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=st.sampled_from(KEYS), value=VALUES)
def test_any_value_of_any_key_is_a_config_or_one_line_naming_the_key(key, value):
    """Wrong types, out-of-range and non-finite values of every key: the config and its task's check
    step accept them, or refuse them with one ConfigError line; nothing else is raised."""
    try:
        cfg = load_config("tiny", [f"{key}={value}"])
        check_config(cfg)
    except ConfigError as err:
        assert "\n" not in str(err) and str(err)
        return
    # A value that passes is one a run can use: finite wherever it is a float.
    for name, item in dataclasses.asdict(cfg).items():
        if isinstance(item, float):
            assert math.isfinite(item), name


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=st.sampled_from(KEYS), value=VALUES)
def test_dospcot_config_of_any_value_prints_a_config_that_loads_or_one_line(key, value):
    """``dospcot config tiny --set KEY=VALUE``: the resolved config as TOML that reads back as the same
    config, or one line and exit status 2."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(["config", "tiny", "--set", f"{key}={value}"])
    if status == 0:
        from dospcot.tasks.loading import config_from_table

        assert config_from_table(tomllib.loads(out.getvalue())) == load_config("tiny", [f"{key}={value}"])
    else:
        assert status == 2 and err.getvalue().count("\n") == 1 and not out.getvalue()


@settings(max_examples=200, deadline=None)
@given(
    seeds=st.integers(1, 10**9),
    rounds=st.integers(1, 2**63 - 1),
    steps=st.integers(1, 10**13),
    workers=st.integers(1, 10**4),
)
def test_any_size_starts_or_is_refused_in_one_line_naming_the_estimate(seeds, rounds, steps, workers):
    """Seeds, rounds, steps and workers of any size: refused in one line that names its estimate, or
    accepted with at most one-line warnings, and never an estimate no machine can finish."""
    from dospcot.run.sizes import REFUSE_CPU_SECONDS, REFUSE_RUN_CPU_SECONDS, check_sizes, cpu_seconds

    cfg = load_config("tiny", [f"training.rounds={rounds}", f"training.steps_per_round={steps}"])
    try:
        warnings = check_sizes([cfg], seeds, workers, batch=seeds)
    except ConfigError as err:
        assert "\n" not in str(err) and "an estimate" in str(err)
        return
    assert all("\n" not in line for line in warnings)
    each = cpu_seconds(cfg)[0]
    assert each <= REFUSE_RUN_CPU_SECONDS and each * seeds <= REFUSE_CPU_SECONDS


@settings(max_examples=15, deadline=None)
@given(
    command=st.sampled_from(["train", "sweep", "reproduce-paper"]),
    seeds=st.integers(10_001, 10**15),
)
def test_too_many_seeds_on_any_command_is_one_line_and_leaves_nothing(command, seeds, tmp_path_factory):
    where = tmp_path_factory.mktemp("seeds")
    out_option = {"train": "--runs-dir", "sweep": "--runs-dir", "reproduce-paper": "--out"}[command]
    argv = [command, *(["tiny"] if command != "reproduce-paper" else []), "--seeds", str(seeds)]
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main([*argv, out_option, str(where), "--no-progress"]) == 2
    assert err.getvalue().count("\n") == 1 and f"{seeds:,} seeds would take about" in err.getvalue()
    assert list(where.iterdir()) == []


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(key=st.sampled_from(KEYS), value=VALUES)
def test_any_value_on_the_command_line_trains_or_exits_2_in_one_line_leaving_no_folder(key, value):
    runs = Path(os.environ.get("PYTEST_TMP", "/tmp")) / f"dospcot-bad-{os.getpid()}"
    _train_or_refuse(runs, f"{key}={value}")


def _train_or_refuse(runs: Path, override: str, capfd: pytest.CaptureFixture | None = None) -> None:
    """``dospcot train tiny`` (short) with ``override``: trained, or exit status 2 and one line on stderr
    leaving no run folder. In a process of its own, or in this one where ``capfd`` is given: main is what
    the process runs, capfd reads its stderr down to the file descriptor, and a warning (which the
    process would print on stderr) fails the test."""
    import shutil

    shutil.rmtree(runs, ignore_errors=True)
    args = ["train", "tiny", "--no-progress", "--runs-dir", str(runs)]
    sets = [a for o in [*SHORT, override] for a in ("--set", o)]
    if capfd is None:
        process = subprocess.run(
            [sys.executable, "-m", "dospcot.cli", *args, *sets], capture_output=True, text=True, timeout=300
        )
        status, err = process.returncode, process.stderr
    else:
        capfd.readouterr()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                status = main([*args, *sets])
            except SystemExit as exit_:  # argparse's own errors
                status = exit_.code
        err = capfd.readouterr().err
        assert not caught, [f"{w.category.__name__}: {w.message}" for w in caught]
    if status == 0:
        assert list(runs.glob("tiny/*/summary.json"))
    else:
        assert status == 2, err
        assert err.count("\n") == 1 and "Traceback" not in err
        assert not list(runs.glob("tiny/*")), "a refused config left a run folder"


@pytest.mark.parametrize(
    "override",
    [
        "env.lava_density=2",
        "env.lava_density=0.8",
        "env.step_cost=nan",
        "cotraining.classifier.epochs=0",
        "cotraining.classifier.lr=nan",
        "dqn.buffer_size=8",
        'name="tiny2',
        "training.rounds=0",
        # A device that is no device, and a GPU where torch sees none (a machine with one trains).
        "dqn.device=gpu",
        "dqn.device=cuda:7",
    ],
)
def test_the_reported_bad_inputs_exit_2_in_one_line_before_a_folder(tmp_path, capfd, override):
    # In this process: test_a_summary_json_round_trips_finite runs the command in a process of its own.
    _train_or_refuse(tmp_path / "runs", override, capfd)
    assert not (tmp_path / "runs").exists() or not list((tmp_path / "runs").glob("tiny/*"))


def test_set_merges_a_table_key_by_key_and_refuses_what_is_not_toml():
    cfg = load_config("tiny", ["training={rounds=1}"])
    assert (cfg.training.rounds, cfg.training.steps_per_round) == (
        1,
        load_config("tiny").training.steps_per_round,
    )
    assert load_config("tiny", ["agent=tabular"]).agent == "tabular"  # a bare word is a string
    for override in ('name="tiny2', "name=two words"):
        with pytest.raises(
            ConfigError, match="is not a TOML value; a string needs its quotes past the shell"
        ):
            load_config("tiny", [override])
    with pytest.raises(ConfigError, match=r"opens and closes a different number of \{ and \}"):
        load_config("tiny", ["training={rounds=1"])


def _broken_env() -> gym.Env:
    raise RuntimeError("no such hardware")


class _StepRaises(gym.Wrapper):
    def step(self, action):
        raise OSError("the simulator died")


def _dies_on_step() -> gym.Env:
    return _StepRaises(gym.make("CartPole-v1"))


def _none_view(obs: np.ndarray) -> None:
    return None


def test_the_python_api_raises_config_errors_with_the_users_error_as_cause(tmp_path):
    with pytest.raises(
        ConfigError, match=r"gym\.env_id: test_bad_inputs:_broken_env raised RuntimeError"
    ) as err:
        train_env(_broken_env, {"state": "observation"}, runs_dir=tmp_path, show_progress=False)
    assert isinstance(err.value.__cause__, RuntimeError)
    with pytest.raises(ConfigError, match="view 'none' returned None; a view returns an array of numbers"):
        train_env("CartPole-v1", {"none": _none_view}, runs_dir=tmp_path, show_progress=False)
    with pytest.raises(EnvRaisedError, match=r"raised OSError at env step 1 .*the simulator died") as err:
        train_env(_dies_on_step, {"state": "observation"}, runs_dir=tmp_path, show_progress=False)
    assert isinstance(err.value.__cause__, OSError)
    assert not list(tmp_path.glob("gym/*")), "a run that failed before its first round left its folder"


def _stopped_for_answers(tmp_path: Path, capsys) -> Path:
    """A two-round tiny run whose file rater stopped it in round 2, round 1 finished."""
    sets = [
        *PINNED,
        "training.label_fraction=0.2",
        'training.label_strategy="random"',
        'training.rater="file"',
    ]
    assert (
        main(
            [
                "train",
                "tiny",
                "--no-progress",
                "--runs-dir",
                str(tmp_path),
                *(a for s in sets for a in ("--set", s)),
            ]
        )
        == 0
    )
    (run_dir,) = (tmp_path / "tiny").iterdir()
    path = run_dir / "queries" / "round_1.csv"
    rows = list(csv.DictReader(path.open()))
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({**row, "reward": "-1", "confirm_new": "yes"} for row in rows)  # -1: new in round 1
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 0  # round 1, then round 2 asks
    assert (run_dir / "queries" / "round_2.csv").is_file() and (run_dir / "checkpoint.pkl").is_file()
    capsys.readouterr()
    return run_dir


def test_run_folders_refuse_a_second_process_an_edited_config_and_a_lost_checkpoint(tmp_path, capsys):
    run_dir = _stopped_for_answers(tmp_path, capsys)
    # A live Python process holds the lock: a second resume stops in one line naming it (a process that
    # is no Python, its id reused, is named as such: tests/test_cli_newcomer.py).
    (run_dir / LOCK_FILE).write_text(str(os.getpid()))
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
    assert f"is being trained by process {os.getpid()}" in capsys.readouterr().err
    (run_dir / LOCK_FILE).write_text("999999999")  # a process that is gone: its lock is taken over
    config = (run_dir / "config.toml").read_text()
    (run_dir / "config.toml").write_text(config.replace("rounds = 2", "rounds = 3"))
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "config.toml changed since its checkpoint was written" in err and err.count("\n") == 1
    (run_dir / "config.toml").write_text(config)
    # Evaluating an unfinished run says which round it scores and writes nothing.
    assert main(["evaluate", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "the agents of round 1 of 2 (unfinished)" in out and "nothing written" in out
    assert not (run_dir / "evaluation.json").exists()
    (run_dir / "checkpoint.pkl").unlink()
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
    assert "finished rounds (metrics.csv) but has no checkpoint.pkl" in capsys.readouterr().err


def _sweep(runs: Path, *more: str) -> subprocess.Popen:
    command = [
        sys.executable,
        "-m",
        "dospcot.cli",
        "sweep",
        "tiny",
        "--seeds",
        "3",
        "--workers",
        "2",
        "--set",
        "training.steps_per_round=500",
        "--runs-dir",
        str(runs),
        "--name",
        "s",
        "--no-progress",
        *more,
    ]
    # Its own process group, as a terminal gives a command; and Ctrl-C's default, whatever launched the tests.
    return subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


@pytest.mark.slow
def test_ctrl_c_stops_a_sweep_within_seconds_a_second_sweep_is_refused_and_it_resumes_byte_identical(
    tmp_path,
):
    sweep = _sweep(tmp_path / "a")
    trials = tmp_path / "a" / "s" / "trials"
    deadline = time.monotonic() + 120
    while not list(trials.glob("*/*/checkpoint.pkl")) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert list(trials.glob("*/*/checkpoint.pkl")), "no trial finished a round"
    os.killpg(sweep.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
    stopped = time.monotonic()
    _, err = sweep.communicate(timeout=30)
    assert time.monotonic() - stopped < 2 and sweep.returncode == 130
    assert "interrupted" in err and f"resume with: dospcot sweep --resume {tmp_path / 'a' / 's'}" in err
    assert "Traceback" not in err and err.count("\n") == 1
    left = b"?"
    for _ in range(50):  # no child left (the resource tracker closes a moment after the sweep)
        left = subprocess.run(["pgrep", "-g", str(sweep.pid)], capture_output=True).stdout
        if not left:
            break
        time.sleep(0.1)
    assert left == b""
    resume = ["sweep", "--resume", str(tmp_path / "a" / "s"), "--no-progress"]
    # The stopped sweep let go of its folder; a live second one on it is refused in one line.
    lock = tmp_path / "a" / "s" / LOCK_FILE
    assert not lock.exists()
    lock.write_text(str(os.getpid()))
    refused = subprocess.run([sys.executable, "-m", "dospcot.cli", *resume], capture_output=True, text=True)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert f"{tmp_path / 'a' / 's'} is being run by process {os.getpid()}" in refused.stderr
    lock.write_text("999999999")  # a sweep that is gone: its lock is taken over
    resumed = subprocess.run([sys.executable, "-m", "dospcot.cli", *resume], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    whole = _sweep(tmp_path / "b")
    assert whole.wait(timeout=300) == 0
    for summary in sorted(trials.glob("*/*/summary.json")):
        other = tmp_path / "b" / summary.relative_to(tmp_path / "a")
        assert summary.read_bytes() == other.read_bytes()
        assert (summary.parent / "metrics.csv").read_bytes() == (other.parent / "metrics.csv").read_bytes()
    assert len(list(trials.glob("*/*/summary.json"))) == 3


def test_the_commands_refuse_what_they_would_ignore_or_misread(capsys, tmp_path):
    cases = [
        (
            ["reproduce-paper", "--label-fraction", "0.2", "--set", "tabular.label_fraction=0.5"],
            "give it once",
        ),
        (["reproduce-paper", "--seeds", "1"], "one seed cannot give"),
        (["sweep", "tiny", "--grid", "training.rounds=1,1"], "1 is given twice"),
        (["sweep", "tiny", "--ray-address", "10.0.0.1:6379"], "it needs --backend ray"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err


def test_a_summary_json_round_trips_finite(tmp_path):
    # A refused draw leaves nothing; an accepted one trains and its figures are finite numbers or NaN.
    _train_or_refuse(tmp_path / "runs", "training.eps_end=0.2")
    (summary,) = (tmp_path / "runs").glob("tiny/*/summary.json")
    assert json.loads(summary.read_text())["rounds"] == 1


def test_an_empty_config_and_a_report_folder_that_cannot_be_made_are_one_line(tmp_path, capsys):
    (tmp_path / "empty.toml").write_text("# nothing set\n")
    assert main(["train", str(tmp_path / "empty.toml"), "--runs-dir", str(tmp_path / "runs")]) == 2
    assert "holds no key; start it from a preset" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()
    assert main(["report", "runs/sweeps/grid16", "--out", "/proc/nope/report"]) == 2
    err = capsys.readouterr().err
    assert "--out /proc/nope/report: cannot make the folder" in err and err.count("\n") == 1


def test_a_stop_as_a_sweep_closes_counts_what_finished(tmp_path, monkeypatch):
    """SIGTERM after the last trial ended, while the sweep shuts its workers down: the line still says
    what was kept, not a bare "interrupted"."""
    from dospcot.run.interrupts import Interrupted
    from dospcot.sweeps import sweep as sweep_module
    from dospcot.sweeps.sweep_spec import SweepSpec

    class StoppedAsItCloses(sweep_module.tqdm):
        stops = 1  # once: tqdm closes again when collected

        def close(self):
            super().close()
            if StoppedAsItCloses.stops:
                StoppedAsItCloses.stops -= 1
                raise KeyboardInterrupt  # what SIGTERM raises (stop_on_signals)

    monkeypatch.setattr(sweep_module, "tqdm", StoppedAsItCloses)
    spec = SweepSpec(("tiny",), {}, (0,), tuple(SHORT))
    with pytest.raises(Interrupted) as stop:
        sweep_module.run_sweep(tmp_path / "s", spec, workers=1, show_progress=False)
    assert str(stop.value) == (
        "1 finished trial(s) of the 1 to run; none stopped mid-run; "
        f"resume with: dospcot sweep --resume {tmp_path / 's'}"
    )


def _wait_for(predicate: typing.Callable[[], bool], seconds: float = 120) -> None:
    deadline = time.monotonic() + seconds
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert predicate()


@pytest.mark.slow
def test_sigint_to_a_sweeps_main_process_alone_stops_its_trials_and_it_resumes_byte_identical(tmp_path):
    """``kill -INT <sweep>`` (the main process, not its group): the running trials stop with it, in
    under 2 s, with the resume line and no traceback; the resumed sweep's files are those of one never
    stopped."""
    sweep = _sweep(tmp_path / "a")
    trials = tmp_path / "a" / "s" / "trials"
    _wait_for(lambda: bool(list(trials.glob("*/*/checkpoint.pkl"))))
    os.kill(sweep.pid, signal.SIGINT)
    stopped = time.monotonic()
    _, err = sweep.communicate(timeout=30)
    assert time.monotonic() - stopped < 2 and sweep.returncode == 130
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"resume with: dospcot sweep --resume {tmp_path / 'a' / 's'}" in err
    _wait_for(lambda: not subprocess.run(["pgrep", "-g", str(sweep.pid)], capture_output=True).stdout, 10)
    finished = {p: p.stat().st_mtime_ns for p in trials.glob("*/*/metrics.csv")}
    time.sleep(1)  # a trial still training would write on
    assert {p: p.stat().st_mtime_ns for p in trials.glob("*/*/metrics.csv")} == finished
    resume = ["sweep", "--resume", str(tmp_path / "a" / "s"), "--no-progress"]
    resumed = subprocess.run([sys.executable, "-m", "dospcot.cli", *resume], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert _sweep(tmp_path / "b").wait(timeout=300) == 0
    summaries = sorted(trials.glob("*/*/summary.json"))
    assert len(summaries) == 3
    for summary in summaries:
        other = tmp_path / "b" / summary.relative_to(tmp_path / "a")
        assert summary.read_bytes() == other.read_bytes()
        assert (summary.parent / "metrics.csv").read_bytes() == (other.parent / "metrics.csv").read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("after", [0.5, 3.0])
def test_ctrl_c_as_a_sweep_starts_says_how_to_go_on_and_prints_no_traceback(tmp_path, after):
    """Ctrl-C while the sweep imports, or while its workers start: one line with the command that goes
    on, in under 2 s, from the sweep and from every worker."""
    sweep = _sweep(tmp_path)
    time.sleep(after)
    os.killpg(sweep.pid, signal.SIGINT)
    stopped = time.monotonic()
    _, err = sweep.communicate(timeout=30)
    assert time.monotonic() - stopped < 2 and sweep.returncode == 130
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "resume with: dospcot sweep" in err
