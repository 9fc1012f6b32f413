"""A command line a newcomer can find their way in (issue 62): ``dospcot config`` prints every key with its
default and meaning, misspelled names are answered with the name meant, sizes beyond the machine are
refused or warned of in one line naming the estimate, and no input hangs, raises a traceback or leaves
a folder behind."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest

from dospcot import __version__
from dospcot.cli import PIPE_CLOSED, main
from dospcot.config.errors import ConfigError
from dospcot.config.loading import parse_override
from dospcot.config.reference import REFERENCE_END, REFERENCE_START
from dospcot.run import sizes
from dospcot.run.cores import usable_cores
from dospcot.run.run_folder import LOCK_FILE, process_command, process_start, run_lock, write_toml
from dospcot.run.sizes import MAX_SEEDS, check_sizes
from dospcot.tasks import get_task, load_config

ROOT = Path(__file__).resolve().parents[1]


def _one_line(capsys, argv: list[str], status: int = 2) -> str:
    """Run ``dospcot argv`` in this process; its stderr, which must be one line."""
    assert main(argv) == status, argv
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.rstrip("\n")


def _cli(*argv: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dospcot.cli", *argv], capture_output=True, text=True, timeout=120, **kwargs
    )


# --- dospcot config and --version ---------------------------------------------------------------------


def test_version_prints_the_package_version():
    done = _cli("--version")
    assert (done.returncode, done.stdout, done.stderr) == (0, f"dospcot {__version__}\n", "")


def test_config_prints_the_resolved_config_as_toml_with_each_keys_default_and_meaning(capsys, tmp_path):
    assert main(["config", "tiny", "--set", "training.rounds=3"]) == 0
    out = capsys.readouterr().out
    table = tomllib.loads(out)  # comments and all, it is a config
    assert table["training"]["rounds"] == 3 and table["env"]["size"] == 6
    lines = out.splitlines()
    assert "rounds = 3  # default 5: " in "\n".join(lines)
    assert any(line.startswith("size = 6  # default 16: side N of the map") for line in lines)
    # Every key line carries its default and a meaning.
    keys = [line for line in lines if " = " in line and not line.startswith("#")]
    assert len(keys) > 60 and all("  # default " in line and line.split("  # default ")[1] for line in keys)
    assert "net_arch = [32]  # default [128, 128]: hidden layer widths of the Q-network" in out
    # The printed config trains what the preset and --set give.
    (tmp_path / "c.toml").write_text(out)
    assert load_config(str(tmp_path / "c.toml")) == load_config("tiny", ["training.rounds=3"])


def test_config_imports_neither_torch_nor_stable_baselines3():
    code = (
        "import sys; from dospcot.cli import main; assert main(['config', 'grid16-dospcot']) == 0; "
        "assert not {'torch', 'stable_baselines3'} & set(sys.modules), 'torch imported'"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_config_of_a_paper_preset_and_a_bad_config_is_one_line(capsys):
    assert main(["config", "paper-text"]) == 0
    assert tomllib.loads(capsys.readouterr().out)["tabular"]["episodes_per_round"] == 500
    err = _one_line(capsys, ["config", "tiny", "--set", "training.rouns=3"])
    assert err == "dospcot config: error: unknown key 'training.rouns'; did you mean 'training.rounds'?"


def test_the_guides_configuration_reference_is_current():
    """docs/guide/configuration.md holds the table dospcot config reads (python scripts/mkdocs_hooks.py
    --write rewrites it)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("mkdocs_hooks", ROOT / "scripts" / "mkdocs_hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    page = (ROOT / "docs" / "guide" / "configuration.md").read_text()
    assert REFERENCE_START in page and REFERENCE_END in page
    assert hooks.with_reference(page) == page, "stale: run python scripts/mkdocs_hooks.py --write"


# --- names that suggest themselves --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (
            ["train", "grid16-dospcott"],
            "dospcot train: error: no preset 'grid16-dospcott'; did you mean 'grid16-dospcot' or "
            "'grid32-dospcot' or 'grid16-oracle'? (or give a path to a .toml)",
        ),
        (
            ["train", "tiny", "--set", "trainig.rounds=3"],
            "dospcot train: error: unknown key 'trainig'; did you mean 'training' or 'cotraining'?",
        ),
        (
            ["train", "tiny", "--set", "training.stepz_per_round=3"],
            "dospcot train: error: unknown key 'training.stepz_per_round'; did you mean "
            "'training.steps_per_round'?",
        ),
    ],
)
def test_a_misspelled_preset_section_or_key_is_answered_with_the_name_meant(capsys, argv, line):
    assert _one_line(capsys, argv) == line


def test_reproduce_paper_takes_the_presets_own_name(capsys):
    # Past the parser (which refused paper-published-code), the handler's own check answers.
    err = _one_line(capsys, ["reproduce-paper", "--preset", "paper-published-code", "--seeds", "1"])
    assert "one seed cannot give" in err


# --- misleading lines, tracebacks --------------------------------------------------------------------


def test_a_folder_given_as_a_config_says_what_it_is(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs" / "tiny" / "s").mkdir(parents=True)
    (tmp_path / "runs" / "tiny" / "s" / "config.toml").write_text('extends = "tiny"\n')
    assert _one_line(capsys, ["train", "runs"]) == (
        "dospcot train: error: runs is a folder, not a config: give a preset (see dospcot train --list) "
        "or a .toml file"
    )
    run = Path("runs/tiny/s")
    assert _one_line(capsys, ["train", str(run)]) == (
        f"dospcot train: error: {run} is a run folder, not a config; to train its config again: "
        f"dospcot train {run / 'config.toml'}; to continue it: dospcot train --resume {run}"
    )
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["config.toml", "runs", "s", "tiny"]


def test_resume_of_a_run_folders_config_toml_names_the_folder(capsys, tmp_path):
    run = _run_folder(tmp_path)
    err = _one_line(capsys, ["train", "--resume", str(run / "config.toml")])
    assert err == f"dospcot train: error: {run / 'config.toml'} is a file: give its run folder, {run}"


def _run_folder(tmp_path: Path) -> Path:
    """A run folder that finished no round: its config.toml alone."""
    run = tmp_path / "tiny" / "stamp"
    run.mkdir(parents=True)
    cfg = load_config("tiny")
    write_toml(run / "config.toml", get_task(cfg.task).config_table(cfg))
    return run


def test_a_lock_naming_a_live_process_that_is_no_dospcot_run_says_how_to_clear_it(capsys, tmp_path):
    run = _run_folder(tmp_path)
    other = subprocess.Popen(["sleep", "60"])
    try:
        # Popen returns while the child may still be part-way into the new program, its command line empty.
        _wait_until(lambda: process_command(other.pid) == "sleep 60", f"process {other.pid} shows 'sleep 60'")
        (run / LOCK_FILE).write_text(str(other.pid))  # a lock as an old dospcot wrote it: the id alone
        err = _one_line(capsys, ["train", "--resume", str(run), "--no-progress"])
        assert err == (
            f"dospcot train: error: {run / LOCK_FILE} names process {other.pid}, which is no dospcot run "
            f"(sleep 60): a run that died left it; remove {run / LOCK_FILE} and resume"
        )
        # A lock that holds the start time too names one process: the id reused is no holder.
        if process_start(other.pid) is not None:
            (run / LOCK_FILE).write_text(f"{other.pid} {process_start(other.pid) + 1}")
            with run_lock(run):
                assert (run / LOCK_FILE).read_text().split()[0] == str(os.getpid())
            assert not (run / LOCK_FILE).exists()
    finally:
        other.kill()
        other.wait()


def _wait_until(holds: Callable[[], bool], what: str) -> None:
    """Wait (at most 30 s) until ``holds()``: a child process's state, as ``/proc`` shows it, lags
    the parent's call that changed it."""
    for _ in range(3000):
        if holds():
            return
        time.sleep(0.01)
    raise AssertionError(f"never: {what}")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads a process's state from /proc")
def test_a_lock_naming_a_process_with_no_command_line_says_both_ways_to_clear_it(capsys, tmp_path):
    run = _run_folder(tmp_path)
    gone = subprocess.Popen(["true"])  # exits at once; unreaped, it keeps its id and an empty command line
    try:
        state = Path(f"/proc/{gone.pid}/stat")
        _wait_until(
            lambda: state.read_text().rpartition(")")[2].split()[0] == "Z", f"process {gone.pid} exits"
        )
        assert process_command(gone.pid) is None
        (run / LOCK_FILE).write_text(str(gone.pid))
        err = _one_line(capsys, ["train", "--resume", str(run), "--no-progress"])
        assert err == (
            f"dospcot train: error: {run} is being trained by process {gone.pid} (its {LOCK_FILE}); wait for "
            f"it or stop it, then resume; if process {gone.pid} is no dospcot run, remove {run / LOCK_FILE}"
        )
    finally:
        gone.wait()


def test_a_leading_dot_number_in_set_is_a_number():
    assert load_config("tiny", ["env.step_cost=.5"]).env.step_cost == 0.5
    assert parse_override("env.step_cost=-.25") == (["env", "step_cost"], -0.25)
    assert parse_override("a=.5e1") == (["a"], 5.0)


def test_an_empty_seed_between_commas_is_refused(capsys):
    with pytest.raises(SystemExit, match="2"):
        main(["train", "tiny", "--seeds", "1,,2"])
    err = capsys.readouterr().err.rstrip("\n")
    assert err == (
        "dospcot train: error: argument --seeds: --seeds 1,,2: an empty item between commas; write the "
        "seeds as 0,3,7 (see dospcot train --help)"
    )


def test_a_sweep_whose_ray_does_not_start_leaves_nothing_and_the_next_answers_the_same(capsys, tmp_path):
    pytest.importorskip("ray")
    argv = ["sweep", "tiny", "--backend", "ray", "--ray-address", "x", "--runs-dir", str(tmp_path / "s")]
    line = (
        "dospcot sweep: error: --ray-address x: expected HOST:PORT (e.g. 10.0.0.1:6379), ray://HOST:PORT "
        "or auto"
    )
    for _ in range(2):
        assert _one_line(capsys, [*argv, "--no-progress"]) == line
        assert not (tmp_path / "s" / "tiny").exists()


def test_a_list_piped_into_head_ends_quietly():
    """The reader closes the pipe before the list is written: no BrokenPipeError, no word on stderr."""
    process = subprocess.Popen(
        [sys.executable, "-m", "dospcot.cli", "train", "--list"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    process.stdout.close()  # as head does once it has its lines; here before the first
    err = process.stderr.read().decode()
    assert process.wait(timeout=60) == PIPE_CLOSED and err == ""


# --- sizes checked before anything starts ------------------------------------------------------------


def test_a_hundred_million_seeds_are_refused_with_the_estimate_and_no_folder(capsys, tmp_path):
    err = _one_line(capsys, ["train", "tiny", "--seeds", "100000000", "--runs-dir", str(tmp_path)])
    assert err.startswith("dospcot train: error: 100,000,000 seeds would take about ")
    assert err.endswith(f"CPU-years (an estimate) and make a run folder each; give at most {MAX_SEEDS:,}")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("override", "line"),
    [
        (
            "training.steps_per_round=1000000000000",
            "dospcot train: error: tiny: one seed would take about 57.1 CPU-years (an estimate: "
            "4,000,000,000,000 agent steps at about 2,500/CPU-s), more than the 3.0 CPU-days a run may; "
            "lower training.rounds or training.steps_per_round, or allow more: "
            "DOSPCOT_MAX_RUN_CPU_DAYS=<CPU-days> in the environment",
        ),
        (
            "training.rounds=100000000000",
            "dospcot train: error: tiny: one seed would take about 979 CPU-years (an estimate: "
            "60,000,000,000,000 agent steps at about 2,500/CPU-s), more than the 3.0 CPU-days a run may; "
            "lower training.rounds or training.steps_per_round, or allow more: "
            "DOSPCOT_MAX_RUN_CPU_DAYS=<CPU-days> in the environment",
        ),
    ],
)
def test_rounds_and_steps_no_machine_can_finish_are_refused_before_a_folder(capsys, tmp_path, override, line):
    assert _one_line(capsys, ["train", "tiny", "--set", override, "--runs-dir", str(tmp_path)]) == line
    assert list(tmp_path.iterdir()) == []


def test_workers_above_the_cores_are_a_warning(capsys, tmp_path):
    assert main(["sweep", "--resume", str(tmp_path / "none"), "--workers", "1000"]) == 2
    warning, error = capsys.readouterr().err.splitlines()
    assert warning == (
        f"dospcot sweep: warning: --workers 1000 is above the {usable_cores()} cores this process may use: "
        "the workers share them"
    )
    assert error.startswith("dospcot sweep: error: ") and "is not a sweep folder" in error


def test_replay_buffers_beyond_the_memory_are_refused(monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(sizes, "memory_bytes", lambda: 8 * 2**30)
    cfg = load_config("grid16", ["training.steps_per_round=2000000000", "dqn.buffer_size=100000000000"])
    with pytest.raises(ConfigError) as refused:
        check_sizes([cfg], 1)
    assert str(refused.value) == (
        "grid16: the replay buffers would need at least 447 GiB (an estimate: 20,000,000,000 transitions x 1 "
        "seeds x 24 bytes), and this machine has 8 GiB; lower dqn.buffer_size"
    )
    # Past the estimate's lower bound, a buffer numpy cannot allocate is one line too, and no folder.
    from dospcot.run import train

    def out_of_memory(*args, **kwargs):
        raise MemoryError("Unable to allocate 48.4 GiB for an array with shape (50000000, 1, 260)")

    monkeypatch.setattr(train, "train", out_of_memory)
    assert _one_line(capsys, ["train", "tiny", "--runs-dir", str(tmp_path)]) == (
        "dospcot train: error: out of memory (Unable to allocate 48.4 GiB for an array with shape "
        "(50000000, 1, 260)); lower dqn.buffer_size or train fewer seeds at once"
    )
