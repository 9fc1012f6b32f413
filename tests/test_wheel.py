"""The wheel is the library: built from the repository it holds the training stack, sweeps and
reports, and no study, benchmark or record module of the lab; installed in a fresh virtualenv outside
the repository, ``dospcot train tiny`` runs from it."""

from __future__ import annotations

import json
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def is_lab_module(name: str) -> bool:
    """Whether a path inside a wheel is of the lab: its package, a study, a benchmark or the record's
    writer."""
    parts = Path(name).parts
    return (
        "dospcot_lab" in parts
        or "studies" in parts
        or parts[-1].startswith("bench")
        or parts[-1] == "record.py"
    )


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    command = [
        sys.executable,
        "-m",
        "pip",
        "wheel",
        "-q",
        "--no-deps",
        "--no-build-isolation",
        "-w",
        str(out),
    ]
    subprocess.run([*command, str(ROOT)], check=True, capture_output=True)
    (path,) = out.glob("dospcot-*.whl")
    return path


def test_the_wheel_holds_the_library_and_no_module_of_the_lab(wheel: Path) -> None:
    names = zipfile.ZipFile(wheel).namelist()
    assert [name for name in names if is_lab_module(name)] == []
    assert is_lab_module("dospcot_lab/studies/budget.py") and not is_lab_module(
        "dospcot/core/round_records.py"
    )
    for module in ("dospcot/cli/__init__.py", "dospcot/sweeps/report.py", "dospcot/statistics.py"):
        assert module in names
    assert "dospcot/envs/gridworld.py" in names and "dospcot/policies/esarsa_dqn/esarsa_dqn.py" in names
    assert "dospcot/presets/tiny.toml" in names


@pytest.mark.slow  # a virtualenv and a run: over 30 s on 2 cores
def test_train_tiny_runs_from_the_wheel_in_a_fresh_virtualenv_outside_the_repository(
    wheel: Path, tmp_path: Path
) -> None:
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    # The dependencies come from this environment's site-packages, read as a plain folder: its .pth
    # files (the editable install of this checkout among them) are not run, so dospcot comes from the
    # wheel alone.
    site = Path(sysconfig.get_paths()["purelib"])
    env_site = Path(
        subprocess.run(
            [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    (env_site / "dependencies.pth").write_text(f"{site}\n")
    subprocess.run([python, "-m", "pip", "install", "-q", "--no-deps", str(wheel)], check=True)
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    train = [env_dir / "bin" / "dospcot", "train", "tiny", "--set", "training.rounds=1", "--no-progress"]
    subprocess.run(train, check=True, cwd=outside, capture_output=True)
    (summary,) = outside.glob("runs/tiny/*/summary.json")
    assert json.loads(summary.read_text())["rounds"] == 1
    where = subprocess.run(
        [
            python,
            "-c",
            "import dospcot, importlib.util as u; print(dospcot.__file__, u.find_spec('dospcot_lab'))",
        ],
        check=True,
        capture_output=True,
        text=True,
        cwd=outside,
    ).stdout.split()
    assert Path(where[0]).is_relative_to(env_dir) and where[1] == "None"
