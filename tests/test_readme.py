"""Every fenced ``bash`` and ``python`` block of README.md runs as pasted, and the README stays short.

Each block is run as a reader would paste it: the shell blocks by bash, the Python blocks by the
interpreter, from an empty folder (the quickstart's blocks share one, in order) or, where the block
says so, from the repository's root. Blocks over 30 s on 2 cores are marked ``slow``."""

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BLOCKS = re.findall(r"^```(bash|python)\n(.*?)^```$", README.read_text(), flags=re.MULTILINE | re.DOTALL)
ENV = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
"""The environment of a reader who activated ``.venv``: its ``dospcot`` and ``tensorboard`` first."""


def _block(starts: str) -> tuple[str, str]:
    """The one block whose code starts with ``starts``."""
    found = [(lang, code) for lang, code in BLOCKS if code.startswith(starts)]
    assert len(found) == 1, f"README.md has {len(found)} blocks starting with {starts!r}"
    return found[0]


def _run(block: tuple[str, str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    lang, code = block
    command = ["bash", "-e", "-c", code] if lang == "bash" else [sys.executable, "-c", code]
    done = subprocess.run(command, cwd=cwd, env=ENV, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"README block failed:\n{code}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    return done


TRAIN = "dospcot train tiny\n"
EVALUATE = "dospcot evaluate"
TENSORBOARD = "tensorboard --logdir runs/tiny"
LOAD = "from pathlib import Path\n\nfrom stable_baselines3 import DQN"
BUILD_RUN = "import torch\n\nfrom dospcot.run.sb3_runs import build_run"
TRAIN_ENV = "from dospcot.run.python_api import train_env"
SWEEP = "dospcot sweep tiny"
STUDY = "dospcot-lab study grid16 --render-only"
MAKE = "make run"
TESTED = (TRAIN, EVALUATE, TENSORBOARD, LOAD, BUILD_RUN, TRAIN_ENV, SWEEP, STUDY, MAKE)


def test_the_readme_is_at_most_300_lines_and_every_block_has_its_test():
    assert len(README.read_text().splitlines()) <= 300
    untested = [code for _, code in BLOCKS if not any(code.startswith(starts) for starts in TESTED)]
    assert not untested, f"README blocks without a test here: {untested}"


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory):
    """An empty folder in which the quickstart's first block trained ``tiny``."""
    folder = tmp_path_factory.mktemp("quickstart")
    _run(_block(TRAIN), folder)
    return folder


def test_the_quickstart_trains_tiny(quickstart):
    runs = list((quickstart / "runs" / "tiny").iterdir())
    assert len(runs) == 1 and (runs[0] / "summary.json").is_file()
    assert (runs[0] / "agent_coords.zip").is_file() and (runs[0] / "tb").is_dir()


def test_the_quickstart_evaluates_the_newest_run(quickstart):
    _run(_block(EVALUATE), quickstart)
    assert list((quickstart / "runs" / "tiny").glob("*/evaluation.json"))


def test_the_quickstart_loads_an_agent_with_plain_stable_baselines3(quickstart):
    action = _run(_block(LOAD), quickstart).stdout.strip()
    assert action in {"0", "1", "2", "3"}


def test_the_quickstart_opens_tensorboard_on_the_runs(quickstart):
    _, code = _block(TENSORBOARD)
    server = subprocess.Popen(
        ["bash", "-c", code],
        cwd=quickstart,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    lines = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and server.poll() is None:
            lines.append(server.stdout.readline())
            if "http://" in lines[-1] or "could not bind" in lines[-1]:
                break
    finally:
        os.killpg(server.pid, 15)
        server.wait(timeout=30)
    if any("could not bind" in line for line in lines):
        pytest.skip("port 6006 is taken on this machine")
    assert any("TensorBoard" in line and "http://" in line for line in lines), "".join(lines)


def test_the_build_run_example_trains(tmp_path):
    assert "'round': 2" in _run(_block(BUILD_RUN), tmp_path).stdout


def test_the_train_env_example_trains_on_cartpole(tmp_path):
    run_dir = Path(_run(_block(TRAIN_ENV), tmp_path).stdout.strip().splitlines()[-1])
    assert (tmp_path / run_dir / "summary.json").is_file()


def test_the_study_example_rebuilds_a_table_from_the_record():
    assert "| `grid16-dospcot` |" in _run(_block(STUDY), ROOT).stdout


@pytest.mark.slow
def test_the_sweep_example_trains_and_reports(tmp_path):
    _run(_block(SWEEP), tmp_path, timeout=900)
    assert (tmp_path / "runs" / "quickstart" / "tiny" / "report.md").is_file()


@pytest.mark.slow
def test_the_two_commands_run():
    """``make run`` (the paper protocol, minutes) and ``make test`` (the suite this test is not part
    of: it runs only the tests not marked slow)."""
    _run(_block(MAKE), ROOT, timeout=3600)
