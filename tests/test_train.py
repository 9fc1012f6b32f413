"""`dospcot train` / `evaluate`: configs, run folders, TensorBoard tags, checkpoints and resume."""

import csv
import dataclasses
import inspect
import json
import os
import pickle
import random
import shutil
import signal
import subprocess
import sys
import time
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import torch as th
from stable_baselines3 import DQN
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
from tensorboard.compat.proto.event_pb2 import SessionLog

from dospcot.cli import main
from dospcot.config.agent_sections import DQN_DEFAULTS, DQN_SET_ELSEWHERE, DQNConfig
from dospcot.config.errors import ConfigError
from dospcot.config.presets import preset_names
from dospcot.core.classifier import load_classifier
from dospcot.core.round_records import DEPENDENCE_STATS
from dospcot.envs import GridWorld, TabularMDP
from dospcot.run.run_folder import RunFolderError, read_checkpoint, write_csv
from dospcot.run.run_session import ROUND_SCALARS
from dospcot.run.train import evaluate
from dospcot.tasks import get_task, load_config
from dospcot.tasks.grid import grid_world

ISSUE_PRESETS = [
    "grid16-dospcot",
    "grid16-oracle",
    "grid16-masked-zero",
    "grid16-labels-only",
    "grid16-self-training",
    "grid32-dospcot",
]
RUN_FILES = [
    "config.toml",
    "metrics.csv",
    "summary.json",
    "learning_curves.png",
    "run_info.json",
]


def _train(tmp_path: Path, *overrides: str) -> Path:
    args = ["train", "tiny", "--runs-dir", str(tmp_path), "--no-progress"]
    assert main([*args, *(a for o in overrides for a in ("--set", o))]) == 0
    (run_dir,) = (tmp_path / "tiny").iterdir()
    return run_dir


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """``trained(*overrides)``: the folder :func:`_train` gives for ``overrides``, trained once per config
    in the module (overrides that resolve to the same config share it: a config trains the same run).
    Tests only read it; a test that changes a run's files works on a copy (:func:`_copy`)."""
    runs: dict[str, Path] = {}

    def get(*overrides: str) -> Path:
        key = repr(load_config("tiny", list(overrides)))
        if key not in runs:
            runs[key] = _train(tmp_path_factory.mktemp("tiny"), *overrides)
        return runs[key]

    return get


def _copy(run_dir: Path, tmp_path: Path) -> Path:
    """A copy of the run folder ``run_dir`` under ``tmp_path``, for a test to change."""
    return Path(shutil.copytree(run_dir, tmp_path / "tiny" / run_dir.name))


def test_every_issue_preset_ships_and_validates():
    assert set(ISSUE_PRESETS) <= set(preset_names())
    methods = {name: load_config(name).method for name in ISSUE_PRESETS}
    assert methods["grid16-oracle"] == "oracle" and methods["grid16-dospcot"] == "dospcot"
    assert load_config("grid16-self-training").views == ("patch",)
    assert load_config("grid32-dospcot").env.size == 32
    assert load_config("grid16-dospcot").training.label_fraction == 0.05


@pytest.mark.parametrize("method", ["oracle", "masked-zero", "labels-only", "self-training", "dospcot", "m3"])
def test_grid32_presets_are_the_grid16_ones_on_a_32_map(method):
    small, large = load_config(f"grid16-{method}"), load_config(f"grid32-{method}")
    assert (large.env.size, large.env.train_episode_steps, large.env.max_episode_steps) == (32, 32, 128)
    assert large.training.steps_per_round == 2 * small.training.steps_per_round
    assert (small.env.ray_encoding, large.env.ray_encoding) == ("inverse", "inverse")
    assert (large.method, large.views, large.dqn, large.cotraining) == (
        small.method,
        small.views,
        small.dqn,
        small.cotraining,
    )


def test_set_overrides_are_typed_and_extends_merges(tmp_path):
    cfg = load_config(
        "grid16-dospcot", ["training.rounds=3", "method=oracle", 'views=["rays"]', "dqn.gamma=0.9"]
    )
    assert (cfg.training.rounds, cfg.method, cfg.views, cfg.dqn.gamma) == (3, "oracle", ("rays",), 0.9)
    assert cfg.env.size == 16  # inherited from the base preset
    child = tmp_path / "child.toml"
    child.write_text('extends = "grid16-dospcot"\nname = "mine"\n[env]\nsize = 8\n')
    mine = load_config(str(child))
    assert (mine.name, mine.env.size, mine.env.layout_seed, mine.views) == ("mine", 8, 0, ("patch", "rays"))


def test_dqn_section_is_sb3_dqns_signature_with_dospcots_defaults_where_named():
    sb3 = inspect.signature(DQN.__init__).parameters
    config = DQNConfig()
    own = {"net_arch", "cut_windows"}
    for f in dataclasses.fields(DQNConfig):
        if f.name in own:
            continue
        expected = DQN_DEFAULTS.get(f.name, sb3[f.name].default)
        assert getattr(config, f.name) == expected, f.name
    names = {f.name for f in dataclasses.fields(DQNConfig)} - own
    # Every plain-valued SB3 argument is a key, except those the run sets itself.
    assert {"max_grad_norm", "tau", "stats_window_size", "optimize_memory_usage"} <= names
    assert not names & set(DQN_SET_ELSEWHERE)
    cfg = load_config("tiny", ["dqn.max_grad_norm=0.5", "dqn.tau=0.01"])
    assert cfg.dqn.sb3_kwargs()["max_grad_norm"] == 0.5 and cfg.dqn.sb3_kwargs()["tau"] == 0.01


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("training.stepz=3", "unknown key 'training.stepz'; allowed: rounds, steps_per_round"),
        ("training.rounds=two", "training.rounds: expected an integer, got 'two'"),
        ("training.label_fraction=1.5", "training: label_fraction must lie in (0, 1], got 1.5"),
        ("training.label_fraction=0", "training: label_fraction must lie in (0, 1], got 0.0"),
        (
            'views=["coords", "lidar"]',
            "views: the grid world has no view 'lidar'; allowed: coords, patch, rays",
        ),
        ("views=[]", "views: need at least one view; allowed: coords, patch, rays"),
        ("method=ppo", "method: 'ppo' is not allowed; allowed: oracle, masked-zero, labels-only, dospcot"),
        ('agents=["a2c", "dqn"]', "agents: unknown agent kind 'a2c'; allowed: esarsa_dqn, dqn, tabular"),
        ("agent=sarsa", "agent: unknown agent kind 'sarsa'; allowed: esarsa_dqn, dqn, tabular"),
        (
            "tabular_agent.learning_rate=1.5",
            "tabular_agent: learning_rate and gamma must lie in (0, 1], got 1.5, 0.97",
        ),
        ("training.update_steps=-1", "training: update_steps must be >= 0, got -1"),
        ("training.learn_from_round=9", "training: learn_from_round must lie in [1, rounds = 2], got 9"),
        ("dqn.n_steps=0", "dqn: n_steps must be >= 1, got 0"),
        ("tabular_agent.n_steps=0", "tabular_agent: n_steps must be >= 1, got 0"),
        ("env.compass=true", "env.compass: True is not allowed; allowed: none, axes, cell"),
        ("env.size=100", 'env: compass = "cell" needs size <= 64, got 100; use "axes"'),
        ('env.ray_encoding="log"', "env.ray_encoding: 'log' is not allowed; allowed: distance, inverse"),
        ("env.blind_spot_rate=1.5", "env: blind_spot_rate must lie in [0, 1], got 1.5"),
        (
            'env.blind_spots="both"',
            "env.blind_spots: 'both' is not allowed; allowed: independent, identical",
        ),
        ("env.monitored_columns=7", "env: monitored_columns must lie in [0, size = 6], got 7"),
        (
            'cotraining.quota="share"',
            "cotraining.quota: 'share' is not allowed; allowed: label-share, candidates",
        ),
        ("dqn.net_arch=[0]", "dqn: net_arch needs one or more hidden layer widths, each >= 1, got [0]"),
        ("dqn.net_arch=[]", "dqn: net_arch needs one or more hidden layer widths, each >= 1, got []"),
        ("dqn.learning_rate=0", "dqn: learning_rate must be > 0, got 0.0"),
        ("dqn.learning_starts=-1", "dqn: learning_starts must be >= 0, got -1"),
        ("extends=grid16", "--set extends=grid16: extends is read with the file, before any --set"),
        (
            "dqn.exploration_initial_eps=0.3",
            "dqn.exploration_initial_eps: not a config key here; it is set by training.eps_start",
        ),
        ("dqn.max_grad_norm=big", "dqn.max_grad_norm: expected a number, got 'big'"),
    ],
)
def test_bad_config_stops_before_training_with_one_line(tmp_path, capsys, override, message):
    assert main(["train", "tiny", "--set", override, "--runs-dir", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "tiny").exists()  # nothing was trained or written


@pytest.mark.parametrize(
    "command",
    [["train", "tiny", "--runs-dir"], ["sweep", "tiny", "--runs-dir"], ["reproduce-paper", "--out"]],
)
def test_a_runs_folder_that_cannot_be_made_fails_with_one_line(tmp_path, capsys, command):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    for where, reason in ((blocker, "Not a directory"), (Path("/proc/dospcot-runs"), "No such file")):
        assert main([*command, str(where), "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(where) in err and reason in err
    assert blocker.read_text() == ""


def test_a_section_of_the_other_task_is_refused_unless_it_says_nothing(tmp_path):
    cfg = load_config("tiny")
    table = get_task(cfg.task).config_table(cfg)
    assert "highway" not in table  # a run folder's config.toml holds its own task's section
    both = tmp_path / "both.toml"  # as config.toml files held both sections before
    both.write_text(tomli_w.dumps({**table, "highway": {"episode_steps": 30}}))
    assert load_config(str(both)) == cfg
    with pytest.raises(ConfigError, match=r'highway: a task = "grid" run does not read the \[highway\]'):
        load_config("tiny", ["highway.episode_steps=3"])


def test_on_the_grid16_map_every_view_tells_every_cell_apart():
    make_env, views, _ = grid_world(load_config("grid16"))
    mdp = TabularMDP.from_env(make_env(), views, 64)
    assert {v: len(np.unique(mdp.views[v], axis=0)) for v in views} == {v: 256 for v in views}


def test_tabular_agents_on_a_highway_stop_with_one_line(capsys):
    assert main(["train", "highway-dospcot", "--set", "agent=tabular"]) == 2
    message = "agent: 'tabular' needs a discrete task (task = \"grid\"); allowed on highway-fast-v0: "
    assert capsys.readouterr().err.endswith(f"{message}esarsa_dqn, dqn\n")


def test_unknown_preset_and_bad_resume_folder_fail_with_one_line(tmp_path, capsys):
    assert main(["train", "grid-99"]) == 2
    err = capsys.readouterr().err
    assert "no preset 'grid-99'; did you mean 'grid32-m3' or 'grid16-m3' or 'grid32'?" in err
    assert err.count("\n") == 1
    assert main(["train", "zzz"]) == 2  # nothing close: the first presets, and where the rest are
    err = capsys.readouterr().err
    assert "no preset 'zzz'; presets (dospcot train --list): fasthighway, " in err and ", ... (or" in err
    assert main(["train", "--resume", str(tmp_path)]) == 2
    assert "has no config.toml" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("views", "names"),
    [
        (["coords"], ["coords"]),
        (["coords", "patch"], ["coords", "patch"]),
        (["coords", "patch", "rays"], ["coords", "patch", "rays"]),
        (["coords", "coords"], ["coords", "coords-2"]),  # a same-sensor twin
    ],
)
def test_tiny_run_writes_every_file_for_one_two_and_three_views_and_a_twin(trained, views, names):
    run_dir = trained(f"views={json.dumps(views)}")
    for name in RUN_FILES:
        assert (run_dir / name).is_file(), name
    assert not (run_dir / "checkpoint.pkl").exists()  # a finished run keeps no checkpoint
    assert (run_dir / "learning_curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (run_dir / "metrics.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * len(views)  # one row per round and view
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["rounds"] == 2 and summary["m"] == len(views) and list(summary["per_view"]) == names
    assert summary["env_steps_per_agent"] == 600
    assert load_config(str(run_dir / "config.toml")).views == tuple(views)
    assert json.loads((run_dir / "reward_classes.json").read_text())["rewards"]
    agents, classifiers = [], []
    for name in names:
        agents.append(DQN.load(run_dir / f"agent_{name}.zip", device="cpu"))  # plain SB3, no dospcot class
        classifiers.append(load_classifier(run_dir / f"classifier_{name}.pt"))
        features = 2 * agents[-1].observation_space.shape[0] + 4  # (s, a, s') features
        assert classifiers[-1].weights[0].shape[1] == features
        tags = EventAccumulator(str(run_dir / "tb" / f"agent_{name}")).Reload().Tags()["scalars"]
        assert {f"dospcot/{key}" for key in ROUND_SCALARS} <= set(tags)
        # The views' error dependence, where there are two classifiers to compare; their error
        # correlation is undefined (NaN, not logged) in a round where a classifier made no error.
        rates = {f"dospcot/{key}" for key in DEPENDENCE_STATS if key != "error_correlation"}
        assert (rates <= set(tags)) == (len(views) > 1)
        assert {"rollout/exploration_rate", "train/loss"} <= set(tags)  # SB3's own scalars
    if len(set(views)) < len(views):  # the twin's agents and classifiers: a second model of one view
        first, second = (a.policy.state_dict() for a in agents)
        assert any(not th.equal(first[key], second[key]) for key in first)
        assert not th.equal(classifiers[0].weights[0], classifiers[1].weights[0])
        assert [(r["agent"], r["view"]) for r in csv.DictReader(rows)][:2] == [
            ("0", "coords"),
            ("1", "coords"),
        ]


def test_a_run_on_segment_labels_logs_and_summarises_its_decoding_error(tmp_path):
    run_dir = _train(tmp_path, "training.segment_length=4", 'views=["coords"]')
    rows = list(csv.DictReader((run_dir / "metrics.csv").open()))
    summary = json.loads((run_dir / "summary.json").read_text())
    error = float(rows[-1]["step_reward_error"])
    assert error >= 0 and summary["mean"]["step_reward_error"] == pytest.approx(error)
    tags = EventAccumulator(str(run_dir / "tb" / "agent_coords")).Reload().Tags()["scalars"]
    assert {f"dospcot/{key}" for key in ROUND_SCALARS} <= set(tags)


@pytest.mark.parametrize("agent", ["esarsa_dqn", "tabular"])
def test_evaluate_reproduces_the_summary_with_plain_sb3_agents(trained, tmp_path, capsys, agent):
    run_dir = _copy(trained(f"agent={agent}"), tmp_path)
    capsys.readouterr()
    assert main(["evaluate", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert "wrote" in out
    summary = json.loads((run_dir / "summary.json").read_text())
    evaluation = json.loads((run_dir / "evaluation.json").read_text())
    for view, row in evaluation["per_view"].items():
        for key in ("greedy_return", "success", "normalised_score", "agreement"):
            assert row[key] == pytest.approx(summary["per_view"][view][key])
        # One line per agent, its name first; success is a share of episodes, printed as one.
        (line,) = [line for line in out.splitlines() if line.startswith(f"{view}:")]
        assert f"success {row['success']:.3f}" in line
    assert evaluation == evaluate(run_dir)


def test_corrupt_checkpoint_and_agent_give_clear_errors(trained, tmp_path, capsys):
    run_dir = _copy(trained(), tmp_path)
    (run_dir / "summary.json").unlink()  # a killed run's folder: a finished one is not resumed
    whole = pickle.dumps({"records": [], "elapsed_s": 1.0, "sessions": 1})
    (run_dir / "checkpoint.pkl").write_bytes(whole[: len(whole) // 2])  # as a kill mid-write would leave it
    with pytest.raises(RunFolderError, match="corrupt or truncated"):
        read_checkpoint(run_dir)
    assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
    assert "checkpoint.pkl is corrupt or truncated" in capsys.readouterr().err
    (run_dir / "agent_patch.zip").write_bytes(b"not a zip")
    assert main(["evaluate", str(run_dir)]) == 2
    assert "agent_patch.zip is not a readable SB3 agent" in capsys.readouterr().err
    (run_dir / "agent_patch.zip").unlink()
    assert main(["evaluate", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert "agent_patch.zip is missing, though the run finished 2 round(s)" in err
    assert err.count("\n") == 1
    clf_path = next(run_dir.glob("classifier_*.pt"))
    for damaged in (clf_path.read_bytes()[:100], b"", b"\x80\x04not a torch file"):
        clf_path.write_bytes(damaged)
        with pytest.raises(ValueError, match=r"is not a readable dospcot classifier \("):
            load_classifier(clf_path)


@pytest.mark.slow
def test_resume_after_a_kill_in_round_two_ends_with_the_uninterrupted_summary(trained, tmp_path, capsys):
    overrides = ["--set", "training.rounds=3", "--set", "training.steps_per_round=800", "--no-progress"]
    full = trained("training.rounds=3", "training.steps_per_round=800")
    cmd = [
        sys.executable,
        "-m",
        "dospcot",
        "train",
        "tiny",
        "--runs-dir",
        str(tmp_path / "killed"),
        *overrides,
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not list((tmp_path / "killed").glob("tiny/*/checkpoint.pkl")):
            assert proc.poll() is None and time.monotonic() < deadline, (
                "the run ended before its first checkpoint"
            )
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)  # in round 2: round 1's checkpoint has just landed
    finally:
        proc.wait()
    (killed,) = (tmp_path / "killed" / "tiny").iterdir()
    assert read_checkpoint(killed)["run"]["round"] == 1 and not (killed / "summary.json").exists()
    first_session_cpu = read_checkpoint(killed)["cpu_s"]
    assert main(["train", "--resume", str(killed), "--no-progress"]) == 0
    for name in ("summary.json", "metrics.csv", "pseudo_rewards.csv"):
        assert (killed / name).read_text() == (full / name).read_text(), name
    info = json.loads((killed / "run_info.json").read_text())
    assert info["sessions"] == 2 and info["session_commits"] == [info["commit"]] * 2
    assert 0 < first_session_cpu < info["cpu_time_s"]  # both sessions' CPU time, summed
    assert "session_commits" not in json.loads((full / "run_info.json").read_text())
    # TensorBoard shows the killed round's scalars once: the resumed session marks its first step
    # (TensorBoard's purge_step), and readers drop the killed session's events from there.
    for folder in (killed / "tb").iterdir():
        marks = [
            event.step
            for path in sorted(folder.iterdir())
            for event in EventFileLoader(str(path)).Load()
            if event.session_log.status == SessionLog.START
        ]
        assert marks == [800], folder.name
        events = EventAccumulator(str(folder))
        events.Reload()
        for tag in events.Tags()["scalars"]:
            steps = [e.step for e in events.Scalars(tag)]
            assert steps == sorted(set(steps)), (folder.name, tag)
    # Resuming a finished run changes nothing and says so.
    before = {p.relative_to(killed): p.read_bytes() for p in killed.rglob("*") if p.is_file()}
    assert main(["train", "--resume", str(killed), "--no-progress"]) == 2
    assert "is a finished run (it has summary.json): nothing to resume" in capsys.readouterr().err
    assert {p.relative_to(killed): p.read_bytes() for p in killed.rglob("*") if p.is_file()} == before


def _assert_every_run_file_whole(run_dir: Path) -> None:
    """Every file a kill left in a run folder parses in full: none is half-written."""
    for path in run_dir.iterdir():
        if path.name.startswith(".") and path.name.endswith(".tmp"):
            continue  # an interrupted write's temporary: never read, removed on resume
        if path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".toml":
            tomllib.loads(path.read_text())
        elif path.suffix == ".csv":
            with path.open() as handle:
                rows = list(csv.reader(handle))
            assert len(rows) > 1 and {len(r) for r in rows} == {len(rows[0])}
        elif path.suffix == ".zip":
            with zipfile.ZipFile(path) as archive:
                assert archive.testzip() is None
        elif path.suffix == ".pkl":
            read_checkpoint(run_dir)
        elif path.suffix == ".pt":
            load_classifier(path)
        elif path.suffix == ".png":
            data = path.read_bytes()
            assert data.startswith(b"\x89PNG") and data.endswith(b"IEND\xaeB`\x82")


@pytest.mark.slow
def test_a_run_killed_at_random_moments_resumes_to_the_uninterrupted_result(trained, tmp_path):
    overrides = ["training.rounds=3", "training.steps_per_round=800"]
    full = trained(*overrides)
    rng = random.Random(11)
    base = [sys.executable, "-m", "dospcot", "train", "--no-progress"]
    kills = []
    for _ in range(3):
        folders = list((tmp_path / "killed").glob("tiny/*"))
        if folders:
            cmd = [*base, "--resume", str(folders[0])]
        else:
            cmd = [*base, "tiny", "--runs-dir", str(tmp_path / "killed")]
            cmd += [a for o in overrides for a in ("--set", o)]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 120
        while not list((tmp_path / "killed").glob("tiny/*/config.toml")) and proc.poll() is None:
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.02)
        delay = rng.uniform(0.0, 5.0)  # from the run's start, past the imports
        time.sleep(delay)
        proc.kill()  # SIGKILL, wherever the run is: learning, writing a file, renaming it
        kills.append((delay, proc.wait()))
        for run_dir in (tmp_path / "killed").glob("tiny/*"):
            _assert_every_run_file_whole(run_dir)
    assert any(code == -signal.SIGKILL for _, code in kills)
    (killed,) = (tmp_path / "killed" / "tiny").iterdir()
    # A run that finished between the kills is refused by --resume (nothing left to train).
    if not (killed / "summary.json").exists():
        assert main(["train", "--resume", str(killed), "--no-progress"]) == 0
    assert (killed / "summary.json").read_text() == (full / "summary.json").read_text()
    assert (killed / "metrics.csv").read_text() == (full / "metrics.csv").read_text()
    assert not list(killed.glob(".*.tmp"))


def test_exploring_starts_draw_free_cells_from_the_seed_and_lava_returns_to_the_map_start():
    env = GridWorld(size=8, layout_seed=1, exploring_starts=True)
    starts = [env.reset(seed=5)[0]] + [env.reset()[0] for _ in range(200)]
    again = [env.reset(seed=5)[0]] + [env.reset()[0] for _ in range(200)]
    assert starts == again and len(set(starts)) > 10
    free = env.layout.terrain.reshape(-1) == 0
    assert free[starts].all()
    lava_moves = np.argwhere(env.reward == -100.0)
    assert (env.next_state[tuple(lava_moves.T)] == env.start_state).all()


def test_metrics_csv_holds_every_rows_columns_when_a_resumed_run_adds_one(tmp_path):
    # Rows from a checkpoint written before a column existed, then rows that have it.
    write_csv(
        tmp_path / "metrics.csv",
        [{"round": 1, "success": 0.5}, {"round": 2, "success": 1.0, "labelled_steps": 40}],
    )
    with (tmp_path / "metrics.csv").open() as rows:
        assert list(csv.DictReader(rows)) == [
            {"round": "1", "success": "0.5", "labelled_steps": ""},
            {"round": "2", "success": "1.0", "labelled_steps": "40"},
        ]


def test_a_run_stops_where_its_greedy_evaluation_stops_improving_and_says_why(trained, tmp_path):
    capped = json.loads((trained() / "summary.json").read_text())
    assert (capped["stopped_early"], capped["stopped_because"]) == (
        False,
        "its last round (training.rounds = 2)",
    )
    run_dir = _train(tmp_path, "training.rounds=8", "training.stop_patience=2")
    summary = json.loads((run_dir / "summary.json").read_text())
    rows = list(csv.DictReader((run_dir / "metrics.csv").open()))
    # Each round's greedy evaluation, mean over the agents: the run ends two rounds after its best.
    greedy = [
        tuple(
            float(np.mean([float(r[key]) for r in rows if int(r["round"]) == n]))
            for key in ("success", "normalised_score")
        )
        for n in range(1, summary["rounds"] + 1)
    ]
    best = max(range(len(greedy)), key=lambda i: (greedy[i], -i))
    assert summary["rounds"] == best + 3 < 8 and summary["stopped_early"]
    assert summary["stopped_because"] == "no new best greedy evaluation in 2 rounds (training.stop_patience)"
    with pytest.raises(ConfigError, match="stop_patience must be >= 0"):
        load_config("tiny", ["training.stop_patience=-1"])


def test_a_run_on_step_labels_reads_its_classes_values_against_the_hidden_rewards(trained):
    """``step_reward_error`` on step labels: 0 in every round where the admitted samples read their
    hidden rewards (the true-rewards control); in the classifiers' run, its last round's value is the one
    summary.json keeps."""
    control = trained('cotraining.pseudo_rewards="hidden"')
    rows = list(csv.DictReader((control / "metrics.csv").open()))
    assert [float(r["step_reward_error"]) for r in rows] == [0.0] * len(rows)
    run_dir = trained()
    rows = list(csv.DictReader((run_dir / "metrics.csv").open()))
    error = float(rows[-1]["step_reward_error"])
    summary = json.loads((run_dir / "summary.json").read_text())
    assert error >= 0 and summary["mean"]["step_reward_error"] == pytest.approx(error)
