"""The package's structure holds: one config tree with renamed keys refused by name, a task registry
that a new module extends, one loop over rounds, and a command line that answers without torch."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import tomli_w

from dospcot.config.errors import ConfigError
from dospcot.run.sb3_runs import build_run
from dospcot.sweeps.report import _read_csv
from dospcot.tasks import config_from_table, load_config, load_run_config
from dospcot.tasks.registry import get_task, tasks

ROOT = Path(__file__).parents[1]
PACKAGE = ROOT / "dospcot"
SOURCE_FOLDERS = (PACKAGE, ROOT / "envs", ROOT / "policies", ROOT / "lab")
"""Every folder that installs as part of dospcot (pyproject's package-dir)."""


def test_building_the_parser_and_listing_presets_leave_torch_and_sb3_unimported():
    script = (
        "import contextlib, io, sys\n"
        "from dospcot.cli import build_parser, main\n"
        "build_parser()\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    assert main(['train', '--list']) == 0\n"
        "assert 'grid16-dospcot' in out.getvalue().split()\n"
        "for argv in (['--help'], ['train', '--threads', '0'], ['nope']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
        "        try:\n"
        "            main(argv)\n"
        "        except SystemExit:\n"
        "            pass\n"
        "print(sorted(m for m in ('torch', 'stable_baselines3') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("cotraining.gamma=0.5", "cotraining.gamma: renamed; the key is now cotraining.consensus_weight"),
        ("cotraining={gamma=0.5}", "cotraining.gamma: renamed; the key is now cotraining.consensus_weight"),
    ],
)
def test_a_renamed_key_is_refused_with_its_new_name(override, message):
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        load_config("grid16-dospcot", [override])
    assert (
        load_config("grid16-dospcot", ["cotraining.consensus_weight=0.5"]).cotraining.consensus_weight == 0.5
    )


def test_an_older_config_file_with_the_renamed_key_names_the_new_one(tmp_path):
    path = tmp_path / "old.toml"
    path.write_text('extends = "tiny"\n\n[cotraining]\ngamma = 0.3\n')
    with pytest.raises(
        ConfigError, match=r"cotraining\.gamma: renamed; the key is now cotraining\.consensus_weight"
    ):
        load_config(str(path))


def test_a_run_folder_written_before_a_rename_still_loads_under_the_new_names(tmp_path):
    cfg = load_config("tiny", ["cotraining.consensus_weight=0.7"])
    old = cfg.to_dict()
    old["cotraining"] = {"gamma" if k == "consensus_weight" else k: v for k, v in old["cotraining"].items()}
    path = tmp_path / "config.toml"
    path.write_text(tomli_w.dumps(old))
    assert load_run_config(path) == cfg
    paper = load_config("paper-text").to_dict()
    paper["tabular"]["cotraining"]["gamma"] = paper["tabular"]["cotraining"].pop("consensus_weight")
    path.write_text(tomli_w.dumps(paper))
    assert load_run_config(path) == load_config("paper-text")


def test_the_methods_old_spelling_reads_as_dospcot_from_a_config_a_run_folder_and_a_record_csv(tmp_path):
    path = tmp_path / "old.toml"
    path.write_text('extends = "tiny"\nmethod = "cotrain"\n')
    assert load_config(str(path)) == load_config("tiny") and load_config("tiny").method == "dospcot"
    assert load_config("tiny", ['method="cotrain"']).method == "dospcot"
    old = load_config("tiny").to_dict() | {"method": "cotrain"}
    (tmp_path / "config.toml").write_text(tomli_w.dumps(old))
    assert load_run_config(tmp_path / "config.toml") == load_config("tiny")
    (tmp_path / "metrics.csv").write_text("method,round,success\ncotrain,1,0.5\noracle,1,1.0\n")
    assert [row["method"] for row in _read_csv(tmp_path / "metrics.csv")] == ["dospcot", "oracle"]


def test_an_unknown_task_names_the_registered_ones():
    with pytest.raises(ConfigError, match=r"^task: unknown task 'nope'; allowed: grid, gym, highway, paper"):
        load_config("tiny", ["task=nope"])
    assert {"grid", "gym", "highway", "paper"} <= set(tasks())


def test_a_new_task_is_one_module_that_registers_itself():
    import toy_chain_task  # registers task = "chain" on import

    assert type(get_task("chain")) is toy_chain_task.ChainTask
    data = {
        "task": "chain",
        "method": "oracle",
        "views": ["cell", "progress"],
        "agent": "tabular",
        "env": {"size": 6, "max_episode_steps": 20},
        "training": {"rounds": 2, "steps_per_round": 400, "eps_end": 0.0},
        "tabular_agent": {"learning_rate": 0.5},
    }
    cfg = config_from_table(data)
    with pytest.raises(ConfigError, match="views: the chain has no view 'coords'; allowed: cell, progress"):
        config_from_table({**data, "views": ["coords"]})
    run = build_run(cfg)
    records = run.run()
    last = [r for r in records if r["round"] == 2]
    # Both views' agents learn the corridor: the optimum is 5 steps right, and they take it.
    assert [r["success"] for r in last] == [1.0, 1.0]
    assert [r["greedy_return"] for r in last] == [-5.0, -5.0]


def test_no_module_outside_the_registry_branches_on_a_task():
    branches = re.compile(
        r"task[\"']?\)?\s*(==|!=|in)\s*[\"'(]|isinstance\([^)]*PaperConfig|get\([\"']task[\"']"
    )
    assert branches.search('if summary.get("task") == "paper":')
    assert branches.search("if cfg.task == 'grid':")
    found = [
        f"{path.relative_to(ROOT)}:{number}"
        for folder in SOURCE_FOLDERS
        for path in folder.rglob("*.py")
        if path.parent.name not in ("tasks", "adapters")
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if branches.search(line)
    ]
    assert found == []


def test_only_the_run_drives_its_rounds():
    """CoTrainingRun.run is the one loop over a run's rounds; a batch of seeds (BatchedRuns) drives its
    members through the run's own phases of a round, never through a member's run_round."""
    drivers = [
        str(path.relative_to(ROOT))
        for folder in SOURCE_FOLDERS
        for path in folder.rglob("*.py")
        if ".run_round(" in path.read_text() and path.name not in ("sb3_round.py", "batched_runs.py")
    ]
    assert drivers == []
    batch = (PACKAGE / "core" / "batched_runs.py").read_text()
    assert "run.run_round(" not in batch
    assert all(f"run.{phase}(" in batch for phase in ("seed_round_env", "label_and_cotrain", "close_round"))


def test_no_module_of_the_package_is_over_500_lines():
    long = {
        str(p.relative_to(ROOT)): n
        for folder in SOURCE_FOLDERS
        for p in folder.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 500
    }
    assert long == {}
