"""Batched seeds: the seeds of one config in lock step in one process, each writing a run's folder."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch as th
from small_runs import PINNED
from stable_baselines3 import DQN
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from dospcot.cli import main
from dospcot.core.batched_runs import BatchedRuns
from dospcot.run.run_folder import BATCH_FILE
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

TINY = [*PINNED, "training.rounds=2", "training.steps_per_round=400"]


def _batch(seeds, *overrides: str) -> tuple[BatchedRuns, list[list[dict]]]:
    runs = [build_run(load_config("tiny", [*TINY, f"seed={seed}", *overrides])) for seed in seeds]
    batch = BatchedRuns(runs)
    rows: list[list[dict]] = []
    batch.run(on_round=rows.append)
    return batch, rows


def test_members_are_independent_another_members_seed_leaves_one_bit_identical():
    plain, plain_rows = _batch([0, 1, 2])
    other, other_rows = _batch([0, 1, 5])
    for member in (0, 1):
        assert json.dumps([r[member] for r in plain_rows]) == json.dumps([r[member] for r in other_rows])
        for a, b in zip(plain.runs[member].agents, other.runs[member].agents, strict=True):
            for p, q in zip(a.policy.parameters(), b.policy.parameters(), strict=True):
                assert th.equal(p, q)
    assert plain_rows[-1][2] != other_rows[-1][2]


def test_each_members_saved_agent_loads_with_plain_sb3_and_gives_its_q_values():
    batch, _ = _batch([3, 4])
    rng = np.random.default_rng(0)
    for k, run_agents in enumerate(zip(*(run.agents for run in batch.runs), strict=True)):
        shape = run_agents[0].observation_space.shape
        obs = th.as_tensor(rng.random((2, 5, *shape)), dtype=th.float32)
        stacked = batch.learners[k].q_net(obs).detach()
        for member, agent in enumerate(run_agents):
            blob = io.BytesIO()
            agent.save(blob)
            blob.seek(0)
            loaded = DQN.load(blob, device="cpu")
            np.testing.assert_allclose(loaded.q_net(obs[member]).detach(), stacked[member], atol=1e-5)


def test_a_batch_on_a_uint8_image_view_preprocesses_as_sb3_and_each_member_loads_with_its_q_values(tmp_path):
    """MiniGrid's image is an image space to SB3 (uint8 pixels, divided by 255 before the network): the
    stacked networks read it as each member's SB3 ``QNetwork`` does, in training and in acting."""
    pytest.importorskip("minigrid")
    config = tmp_path / "empty.toml"
    config.write_text(
        'task = "gym"\nmethod = "oracle"\nviews = ["image"]\n[gym]\n'
        'env_id = "minigrid:MiniGrid-Empty-5x5-v0"\nviews = { image = "image" }\n'
        "[training]\nrounds = 1\nsteps_per_round = 300\n[dqn]\nlearning_starts = 100\n"
    )
    runs = [build_run(load_config(str(config), [*PINNED, f"seed={seed}"])) for seed in (0, 1)]
    batch = BatchedRuns(runs)
    batch.run()
    space = runs[0].agents[0].observation_space
    assert space.dtype == np.uint8
    obs = th.as_tensor(np.random.default_rng(0).integers(0, 11, size=(2, 4, *space.shape), dtype=np.uint8))
    stacked = batch.learners[0].q_net(obs).detach()
    for member, run in enumerate(batch.runs):
        (agent,) = run.agents
        assert agent.num_timesteps == 300
        blob = io.BytesIO()
        agent.save(blob)
        blob.seek(0)
        loaded = DQN.load(blob, device="cpu")
        np.testing.assert_allclose(loaded.q_net(obs[member]).detach(), stacked[member], atol=1e-5)


def _scalars(run_dir, view: str) -> dict[str, list]:
    events = EventAccumulator(str(run_dir / "tb" / f"agent_{view}")).Reload()
    return {tag: events.Scalars(tag) for tag in events.Tags()["scalars"]}


def test_a_members_tensorboard_holds_the_scalars_of_a_run_alone(tmp_path):
    sets = [a for s in TINY for a in ("--set", s)]
    assert (
        main(["train", "tiny", "--seeds", "2", "--runs-dir", str(tmp_path / "b"), "--no-progress", *sets])
        == 0
    )
    assert main(["train", "tiny", "--runs-dir", str(tmp_path / "a"), "--no-progress", *sets]) == 0
    (alone,) = (tmp_path / "a" / "tiny").iterdir()
    members = sorted((tmp_path / "b" / "tiny").iterdir())
    for view in load_config("tiny").views:
        expected = _scalars(alone, view)
        assert {
            "rollout/ep_rew_mean",
            "rollout/ep_len_mean",
            "rollout/exploration_rate",
            "train/loss",
        } <= set(expected)
        for member in members:
            logged = _scalars(member, view)
            assert set(logged) == set(expected), member  # SB3's rollout/, train/ and time/, and dospcot/
            # Dumped every 4 episodes (DQN.learn's default): the steps of the dumps are the member's own.
            lengths = [e.value for e in logged["rollout/ep_len_mean"]]
            assert len(lengths) >= 2 and all(1 <= n <= 400 for n in lengths)
            steps = [e.step for e in logged["rollout/exploration_rate"]]
            assert steps == sorted(steps) and steps[-1] <= 800


def test_runs_that_differ_in_more_than_their_seeds_are_refused():
    runs = [build_run(load_config("tiny", [*TINY, f"seed={s}"])) for s in (0, 1)]
    runs.append(build_run(load_config("tiny", [*TINY, "seed=2", "training.label_fraction=0.3"])))
    with pytest.raises(ValueError, match="differ in more than their seeds"):
        BatchedRuns(runs)


def test_a_config_that_cannot_batch_trains_its_seeds_one_after_another_saying_why(tmp_path, capsys):
    args = ["train", "tiny", "--seeds", "2", "--runs-dir", str(tmp_path), "--no-progress"]
    assert main([*args, *("--set", 'agent="tabular"'), *(a for s in TINY for a in ("--set", s))]) == 0
    out = capsys.readouterr().out
    assert "training the 2 seeds one after another, not as a batch: tabular agents" in out
    folders = sorted((tmp_path / "tiny").iterdir())
    assert [json.loads((f / "summary.json").read_text())["seed"] for f in folders] == [0, 1]


@pytest.mark.slow
def test_a_batch_killed_after_a_round_resumes_to_the_files_of_one_never_stopped(tmp_path):
    overrides = [a for s in ["training.rounds=3", "training.steps_per_round=600"] for a in ("--set", s)]
    args = ["train", "tiny", "--seeds", "2", "--no-progress", *overrides]
    assert main([*args, "--runs-dir", str(tmp_path / "full")]) == 0
    full = sorted((tmp_path / "full" / "tiny").iterdir())
    assert not any((f / BATCH_FILE).exists() or (f / "checkpoint.pkl").exists() for f in full)
    cmd = [sys.executable, "-m", "dospcot", *args, "--runs-dir", str(tmp_path / "killed")]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not list((tmp_path / "killed").glob("tiny/*/checkpoint.pkl")):
            assert proc.poll() is None and time.monotonic() < deadline, "the batch ended before a checkpoint"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)  # in round 2: round 1's checkpoint has just landed
    finally:
        proc.wait()
    killed = sorted((tmp_path / "killed" / "tiny").iterdir())
    assert all((f / BATCH_FILE).exists() and not (f / "summary.json").exists() for f in killed)
    # Any member's folder resumes the whole batch.
    assert main(["train", "--resume", str(killed[1]), "--no-progress"]) == 0
    for resumed, never_stopped in zip(killed, full, strict=True):
        for name in ("metrics.csv", "summary.json", "reward_classes.json"):
            assert (resumed / name).read_bytes() == (never_stopped / name).read_bytes(), (resumed, name)
        assert json.loads((resumed / "run_info.json").read_text())["sessions"] == 2
        assert not (resumed / BATCH_FILE).exists()


@pytest.mark.slow  # over 30 s on 2 cores: `make test-slow`; the grouping alone, untrained, is checked below
def test_a_sweep_batches_its_seeds_and_a_batchs_grouping_changes_no_members_files(tmp_path):
    from dospcot.sweeps.sweep import run_sweep
    from dospcot.sweeps.sweep_spec import SweepSpec, trial_dir

    spec = SweepSpec(("tiny",), {"training.label_fraction": ("0.2",)}, (0, 1, 2), tuple(TINY))
    folders = {}
    for k in (2, 3):
        result = run_sweep(tmp_path / f"k{k}", spec, workers=1, batch_seeds=k, show_progress=False)
        assert not result.failed
        folders[k] = [trial_dir(tmp_path / f"k{k}", trial) for trial in result.trials]
        infos = [json.loads((f / "run_info.json").read_text()) for f in folders[k]]
        assert [info.get("batch_members", 1) for info in infos] == ([2, 2, 1] if k == 2 else [3, 3, 3])
    for two, three in zip(folders[2], folders[3], strict=True):
        for name in ("metrics.csv", "summary.json"):
            assert (two / name).read_bytes() == (three / name).read_bytes()


@pytest.mark.parametrize("seeds", [[], ["--seeds", "2"]])
def test_a_run_or_batch_stopped_in_its_first_round_keeps_its_folders_and_resumes(tmp_path, seeds):
    # Long enough that the signal lands inside the round on any CPU, short enough that the resume is cheap.
    steps = ("--set", "training.steps_per_round=1500", "--set", "training.rounds=1")
    cmd = [sys.executable, "-m", "dospcot", "train", "tiny", *seeds, *steps, "--no-progress"]
    proc = subprocess.Popen(
        [*cmd, "--runs-dir", str(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    try:
        deadline = time.monotonic() + 120
        while len(list(tmp_path.glob("tiny/*/tb/*"))) < 2:  # the agents' loggers: the run has begun
            assert proc.poll() is None and time.monotonic() < deadline, "the run ended before it began"
            time.sleep(0.02)
        time.sleep(0.5)  # into round 1
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "no finished round in" in out
    folders = sorted((tmp_path / "tiny").iterdir())
    assert len(folders) == (2 if seeds else 1) and f"dospcot train --resume {folders[0]}" in out
    assert main(["train", "--resume", str(folders[-1]), "--no-progress"]) == 0
    assert all((folder / "summary.json").is_file() for folder in folders)


def test_a_batch_reports_its_progress_to_a_sweep_in_trials(tmp_path):
    from dospcot.run.train_batch import train_batch_at

    cfgs = [load_config("tiny", [*TINY, f"seed={seed}"]) for seed in (0, 1)]
    shares: list[float] = []
    train_batch_at([tmp_path / "a", tmp_path / "b"], cfgs, commands=["", ""], progress=shares.append)
    assert sum(shares) == pytest.approx(2.0, abs=0.02)  # two trials, but what is left under the last report


@pytest.mark.slow  # each over 30 s on 2 cores: `make test-slow`; the refusal alone is checked below
@pytest.mark.parametrize(("started", "other"), [(3, 1), (1, 3)])
def test_a_killed_sweep_resumes_with_its_own_batch_seeds_to_the_files_of_one_never_stopped(
    tmp_path, capsys, started, other
):
    from dospcot.sweeps.sweep import run_sweep
    from dospcot.sweeps.sweep_spec import SweepSpec, trial_dir

    steps = ["training.rounds=3", "training.steps_per_round=600"]
    spec = SweepSpec(("tiny",), {}, (0, 1, 2), tuple(steps))
    never = run_sweep(tmp_path / "never", spec, workers=1, batch_seeds=started, show_progress=False)
    cmd = [sys.executable, "-m", "dospcot", "sweep", "tiny", "--seeds", "3", "--workers", "1"]
    cmd += [*(a for s in steps for a in ("--set", s)), "--batch-seeds", str(started)]
    cmd += ["--runs-dir", str(tmp_path), "--name", "killed", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while not list((tmp_path / "killed").glob("trials/*/*/checkpoint.pkl")):
            assert proc.poll() is None and time.monotonic() < deadline, "the sweep ended before a checkpoint"
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGKILL)  # the parent and its worker, in round 2
    finally:
        proc.wait()
    args = ["sweep", "--resume", str(tmp_path / "killed"), "--workers", "1", "--no-progress"]
    # Another grouping for the rest would mix two ways of training in one sweep: refused, in one line.
    assert main([*args, "--batch-seeds", str(other)]) == 2
    begun = 3 if started > 1 else 1  # a batch starts all its members; one trial at a time starts one
    error = capsys.readouterr().err
    assert f"trains its trials with --batch-seeds {started} and {begun} of its 3 have started" in error
    assert main(args) == 0  # the sweep's own, from its sweep.json
    folders = [trial_dir(tmp_path / "killed", trial) for trial in never.trials]
    for trial, folder in zip(never.trials, folders, strict=True):
        for name in ("metrics.csv", "summary.json"):
            whole = trial_dir(tmp_path / "never", trial) / name
            assert (folder / name).read_bytes() == whole.read_bytes(), (trial.trial_id, name)
    infos = [json.loads((folder / "run_info.json").read_text()) for folder in folders]
    assert [info.get("batch_members", 1) for info in infos] == [started] * 3
    # The killed trials went on from their checkpoint (a second session), none from scratch.
    assert [info["sessions"] for info in infos] == ([2, 2, 2] if started > 1 else [2, 1, 1])


def test_a_sweep_groups_its_seeds_by_batch_seeds_and_refuses_another_once_its_trials_began(tmp_path, capsys):
    """The two slow tests above without their training: --batch-seeds K puts a cell's seeds in jobs of
    at most K, and a sweep whose trials began under K refuses another K in one line."""
    from dospcot.run.run_folder import write_toml
    from dospcot.sweeps.sweep import plan_jobs
    from dospcot.sweeps.sweep_spec import SweepSpec, open_sweep, store_batch_seeds, trial_dir
    from dospcot.tasks import get_task

    spec = SweepSpec(("tiny",), {"training.label_fraction": ("0.2",)}, (0, 1, 2), tuple(TINY))
    trials = spec.trials()

    def seeds(jobs):
        return [[trial.seed for trial in job] for job in jobs]

    assert seeds(plan_jobs(trials, workers=1, batch_seeds=2)) == [[0, 1], [2]]
    assert seeds(plan_jobs(trials, workers=1, batch_seeds=3)) == [[0, 1, 2]]
    assert seeds(plan_jobs(trials, workers=1)) == [[0], [1], [2]]
    sweep_dir = tmp_path / "s"
    open_sweep(sweep_dir, spec)
    store_batch_seeds(sweep_dir, 3)
    for trial in trials:  # each trial's run folder begun: its config.toml, which a run writes first
        cfg = load_config(trial.config, trial.overrides())
        write_toml(trial_dir(sweep_dir, trial) / "config.toml", get_task(cfg.task).config_table(cfg))
    args = ["sweep", "--resume", str(sweep_dir), "--workers", "1", "--no-progress"]
    assert main([*args, "--batch-seeds", "1"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "Traceback" not in error
    assert "trains its trials with --batch-seeds 3 and 3 of its 3 have started" in error
    assert not list(sweep_dir.glob("trials/*/*/summary.json"))  # nothing trained


@pytest.mark.parametrize("seeds", [[], ["--seeds", "2"]])
def test_a_run_or_batch_stopped_while_it_is_built_says_what_it_kept_and_resumes(
    tmp_path, capsys, monkeypatch, seeds
):
    from dospcot.run.run_session import RunSession

    built = RunSession.__init__

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt  # Ctrl-C while the task, its envs and its agents are made

    monkeypatch.setattr(RunSession, "__init__", stopped)
    sets = [a for s in TINY for a in ("--set", s)]
    assert main(["train", "tiny", *seeds, *sets, "--runs-dir", str(tmp_path), "--no-progress"]) == 130
    error = capsys.readouterr().err
    first = sorted((tmp_path / "tiny").iterdir())[0]
    assert "interrupted; kept no finished round in" in error
    assert f"resume with: dospcot train --resume {first}" in error
    monkeypatch.setattr(RunSession, "__init__", built)
    assert main(["train", "--resume", str(first), "--no-progress"]) == 0
    assert all((folder / "summary.json").is_file() for folder in (tmp_path / "tiny").iterdir())


def test_seed_trains_one_run_of_that_seed_and_a_seeds_range_a_batch_of_its_seeds(tmp_path):
    sets = [a for s in TINY for a in ("--set", s)]
    assert (
        main(["train", "tiny", "--seed", "3", "--runs-dir", str(tmp_path / "one"), "--no-progress", *sets])
        == 0
    )
    (alone,) = (tmp_path / "one" / "tiny").iterdir()
    assert json.loads((alone / "summary.json").read_text())["seed"] == 3
    args = ["train", "tiny", "--seeds", "3-4", "--runs-dir", str(tmp_path / "batch"), "--no-progress", *sets]
    assert main([*args]) == 0
    folders = sorted((tmp_path / "batch" / "tiny").iterdir())
    assert [json.loads((f / "summary.json").read_text())["seed"] for f in folders] == [3, 4]
