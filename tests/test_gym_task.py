"""Any gymnasium env with discrete actions (task = "gym"): a toy corridor defined here, nothing shipped."""

from __future__ import annotations

import csv
import json
import math
import pickle
import re
import subprocess
import sys
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import stable_baselines3
import torch
from small_runs import MECHANISMS

from dospcot.adapters.sensor_adapter import SensorAdapter
from dospcot.adapters.sensor_store import KeyedStepStore, StepStore
from dospcot.config.errors import ConfigError
from dospcot.config.versions import ADOPTED, BUDGET
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.demonstrations import Demonstrations
from dospcot.envs import minigrid_views
from dospcot.envs.gym_sensors import (
    ObservationSensors,
    dotted_path,
    make_gym_env,
    make_masked_gym,
)
from dospcot.envs.masking import key_is_labelled
from dospcot.raters.file_rater import QueriesPending
from dospcot.run.checks import check_config
from dospcot.run.python_api import gym_config, train_env
from dospcot.run.run_folder import RunFolderError
from dospcot.run.sb3_runs import build_run
from dospcot.run.train import evaluate, resume, train
from dospcot.tasks import load_config

LENGTH = 10


class Corridor(gym.Env):
    """Cells 0..9 in a row, start at 0; action 1 moves right, 0 left. Reaching cell 9 pays 1 and ends
    the episode; every other step pays 0 (sparse, as MiniGrid). The observation is a Dict: the cell
    one-hot, and the cell as one number in [0, 1]."""

    def __init__(self) -> None:
        self.action_space = gym.spaces.Discrete(2)
        self.observation_space = gym.spaces.Dict(
            {
                "onehot": gym.spaces.Box(0, 1, (LENGTH,), np.float32),
                "cell": gym.spaces.Box(0, 1, (1,), np.float32),
            }
        )
        self.pos = 0

    def _obs(self) -> dict[str, np.ndarray]:
        return {
            "onehot": np.eye(LENGTH, dtype=np.float32)[self.pos],
            "cell": np.array([self.pos / (LENGTH - 1)], np.float32),
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.pos = 0
        return self._obs(), {}

    def step(self, action: int):
        self.pos = int(np.clip(self.pos + (1 if action == 1 else -1), 0, LENGTH - 1))
        done = self.pos == LENGTH - 1
        return self._obs(), float(done), done, False, {}


def make_corridor() -> gym.Env:
    return gym.wrappers.TimeLimit(Corridor(), 20)


class DrawnCorridor(Corridor):
    """The corridor, drawn as a row of 4 x 4 pixel cells: the agent's white, the rest black."""

    metadata = {"render_modes": ["rgb_array"]}  # noqa: RUF012

    def __init__(self, render_mode: str | None = None) -> None:
        super().__init__()
        self.render_mode = render_mode

    def render(self) -> np.ndarray:
        image = np.zeros((4, 4 * LENGTH, 3), np.uint8)
        image[:, 4 * self.pos : 4 * self.pos + 4] = 255
        return image


def make_drawn_corridor() -> gym.Env:
    return gym.wrappers.TimeLimit(DrawnCorridor(render_mode="rgb_array"), 20)


def drawn_cell(path: Path) -> int:
    """The agent's cell in a frame :class:`DrawnCorridor` drew, read back from its PNG."""
    from PIL import Image

    image = np.asarray(Image.open(path))
    (cells,) = np.nonzero(image[0, ::4, 0])
    assert image.shape == (4, 4 * LENGTH, 3) and len(cells) == 1
    return int(cells[0])


def signed_cell(obs: dict[str, np.ndarray]) -> np.ndarray:
    """The second view: the cell number, scaled to [-1, 1]."""
    return 2 * obs["cell"] - 1


def one_number_then_two(obs: dict[str, np.ndarray]) -> np.ndarray:
    return np.zeros(1 if obs["cell"][0] == 0 else 2)


def failing_view(obs: dict[str, np.ndarray]) -> np.ndarray:
    raise KeyError("lidar")


def corridor_cell(env: Corridor) -> int:
    """The corridor's state key: the agent's cell."""
    return env.pos


def unhashable_key(env: Corridor) -> list[int]:
    return [env.pos]


SETTINGS = {
    "defaults": MECHANISMS,
    "training.rounds": 3,
    "training.steps_per_round": 1500,
    "training.eps_start": 0.5,
    "training.update_steps": 200,
    "dqn.learning_starts": 100,
    "dqn.target_update_interval": 100,
    "dqn.net_arch": [32, 32],
    "gym.episode_steps": 20,
    "gym.eval_episodes": 2,
    "gym.max_return": 1.0,
}
VIEWS = {"onehot": "onehot", "signed": signed_cell}


def _corridor_toml(tmp_path: Path, **gym_keys: str) -> Path:
    views = {"onehot": '"onehot"', "signed": f'"{dotted_path(signed_cell, "view")}"', **gym_keys}
    path = tmp_path / "corridor.toml"
    path.write_text(
        f"""name = "corridor"
defaults = {MECHANISMS}
task = "gym"
agent = "dqn"
views = ["onehot", "signed"]
[gym]
env_id = "{dotted_path(make_corridor, "env")}"
episode_steps = 20
eval_episodes = 2
max_return = 1.0
views = {{{", ".join(f"{k} = {v}" for k, v in views.items())}}}
[training]
rounds = 3
steps_per_round = 1500
label_fraction = 0.1
eps_start = 0.5
update_steps = 200
[dqn]
learning_starts = 100
target_update_interval = 100
net_arch = [32, 32]
"""
    )
    return path


def test_a_toy_env_co_trains_from_python_and_its_run_folder_evaluates(tmp_path):
    run_dir = train_env(
        make_corridor, VIEWS, runs_dir=tmp_path, label_fraction=0.1, settings=SETTINGS, show_progress=False
    )
    with (run_dir / "metrics.csv").open() as rows:
        last = [row for row in csv.DictReader(rows) if row["round"] == "3"]
    assert [row["view"] for row in last] == ["onehot", "signed"]
    # Pseudo-rewards were admitted in the last round, and right: 0 everywhere but at the goal.
    assert all(float(row["coverage"]) > 0.5 and float(row["pseudo_accuracy"]) > 0.95 for row in last)
    result = evaluate(run_dir)
    # Both agents walk the corridor: the only reward is the goal's, 1, reached in 9 steps.
    assert result["mean"]["success"] == 1.0
    assert result["mean"]["greedy_return"] == 1.0
    assert result["mean"]["normalised_score"] > 0.5  # a random walk often fails within 20 steps
    # The agents are plain SB3 zips; the config names the functions by their dotted paths.
    agent = stable_baselines3.DQN.load(run_dir / "agent_signed.zip")
    assert agent.observation_space.shape == (1,)
    config = (run_dir / "config.toml").read_text()
    assert f'signed = "{dotted_path(signed_cell, "v")}"' in config
    with pytest.raises(RunFolderError, match="is a finished run"):  # nothing to resume
        resume(run_dir, show_progress=False)


def test_a_file_raters_queries_show_frames_of_the_step_where_the_env_draws_itself(tmp_path):
    settings = {**SETTINGS, "training.rater": "file", "training.label_strategy": "disagreement"}
    cfg = gym_config(make_drawn_corridor, VIEWS, label_fraction=0.1, name="drawn", settings=settings)
    with pytest.raises(QueriesPending) as pending:
        train(cfg, tmp_path, show_progress=False)
    rows = list(csv.DictReader(pending.value.path.open()))
    assert rows and all(row["frame"] and row["next_frame"] for row in rows)
    queries = pending.value.path.parent
    for row in rows:  # each query shows its step: the agent's cell before the action, and after it
        action = int(row["key"].rsplit(" ", 1)[1])
        before, after = drawn_cell(queries / row["frame"]), drawn_cell(queries / row["next_frame"])
        assert after == min(max(before + (1 if action == 1 else -1), 0), LENGTH - 1)
    # A simulated rater's run draws nothing, though its env could.
    plain = build_run(gym_config(make_drawn_corridor, VIEWS, label_fraction=0.1, settings=SETTINGS))
    plain.run(until_round=1)
    assert len(plain.task.store) > 0 and plain.task.store.frames == {}


def test_frames_are_asked_of_a_registered_env_only_where_it_lists_rgb_array():
    assert make_gym_env("CartPole-v1", frames=True).render_mode == "rgb_array"
    assert make_gym_env("CartPole-v1").render_mode is None
    gym.register("DospcotTestCorridor-v0", entry_point=Corridor)  # lists no render mode
    try:
        assert getattr(make_gym_env("DospcotTestCorridor-v0", frames=True), "render_mode", None) is None
    finally:
        gym.registry.pop("DospcotTestCorridor-v0")


def test_a_toml_config_with_a_dotted_path_view_is_the_python_entry_points_config(tmp_path):
    from_toml = load_config(str(_corridor_toml(tmp_path)))
    from_python = gym_config(make_corridor, VIEWS, label_fraction=0.1, name="corridor", settings=SETTINGS)
    assert from_toml == from_python  # the same run, which the test above trains
    assert isinstance(build_run(from_toml).task, SensorAdapter)


def test_success_counts_returns_above_the_threshold_and_the_score_needs_a_max_return(tmp_path):
    cfg = gym_config(
        make_corridor, VIEWS, settings={**SETTINGS, "gym.max_return": math.inf, "gym.success_return": 2.0}
    )
    run = build_run(cfg)
    policy = run.evaluate_policies()
    assert np.all(policy["success"] == 0.0)  # no episode returns more than 1
    assert np.all(np.isnan(policy["normalised_score"]))  # R_max unknown
    assert np.all(np.isnan(policy["agreement"]))
    # Every episode returns 0 or 1, so above -1 each one is a success.
    run = build_run(gym_config(make_corridor, VIEWS, settings={**SETTINGS, "gym.success_return": -1.0}))
    assert np.all(run.evaluate_policies()["success"] == 1.0)


class _ScrambledHiddenReward(gym.Wrapper):
    """Replace the hidden reward of every masked step by noise: a learner must never see it. The noise
    has its own generator: drawing from the env's would change the env (MiniGrid draws its maps)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.noise = np.random.default_rng(12345)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not info["reward_observed"]:
            info = dict(info, hidden_reward=float(self.noise.normal()))
        return obs, reward, terminated, truncated, info


def minigrid_direction(obs: dict[str, np.ndarray]) -> np.ndarray:
    """A second MiniGrid view: the agent's direction, one-hot, and the object type of each cell in sight."""
    return np.concatenate([np.eye(4)[obs["direction"]], obs["image"][..., 0].ravel() / 10])


@pytest.fixture(scope="module")
def keyed_run() -> CoTrainingRun:
    """The corridor on (cell, action) labels, 30% of them, 2 rounds of 600 steps: built and run once for
    the module; the tests only read it."""
    settings = {**SETTINGS, "training.rounds": 2, "training.steps_per_round": 600}
    run = build_run(
        gym_config(make_corridor, VIEWS, label_fraction=0.3, state_key=corridor_cell, settings=settings)
    )
    run.run()
    return run


# Single-step labels on MiniGrid, (state key, action) labels on the corridor.
@pytest.mark.parametrize("task", ["corridor-keyed", "minigrid"])
def test_leakage_scrambling_hidden_rewards_leaves_the_learners_bit_identical(request, task):
    settings = {**SETTINGS, "training.rounds": 2, "training.steps_per_round": 600}
    env, views, fraction = make_corridor, VIEWS, 0.1
    if task == "corridor-keyed":
        settings["gym.state_key"] = dotted_path(corridor_cell, "key")
        fraction = 0.3  # 18 (cell, action) pairs: a few labelled
    if task == "minigrid":
        pytest.importorskip("minigrid")
        env, views = "minigrid:MiniGrid-LavaGapS7-v0", {"image": "image", "direction": minigrid_direction}
        fraction = 0.5  # the goal, rarely reached at random, must be labelled at times
    cfg = gym_config(env, views, label_fraction=fraction, settings=settings)
    if task == "corridor-keyed":  # the module's run of this config
        plain = request.getfixturevalue("keyed_run")
        assert plain.cfg == cfg
    else:
        plain = build_run(cfg)
        plain.run()
    make = partial(make_masked_gym, cfg.gym.env_id, view_specs=cfg.gym.views, state_key=cfg.gym.state_key)
    scrambled = CoTrainingRun(
        SensorAdapter(cfg, cfg.gym, lambda *args: _ScrambledHiddenReward(make(*args))), cfg
    )
    scrambled.run()
    n = len(plain.store)
    assert (plain.table.weight[:n][~plain.store.labelled[:n]] > 0).any()
    assert not np.array_equal(plain.store.hidden_reward[:n], scrambled.store.hidden_reward[:n])
    for a, b in zip(plain.agents, scrambled.agents, strict=True):
        for p, q in zip(a.policy.parameters(), b.policy.parameters(), strict=True):
            assert np.array_equal(p.detach().numpy(), q.detach().numpy())
    assert np.array_equal(plain.table.reward, scrambled.table.reward)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            'gym.env_id="MountainCarContinuous-v0"',
            "has a Box action space: DOSPCoT's Q-learning agents need Discrete",
        ),
        ('gym.env_id="NoSuchEnv-v0"', "gym.env_id: Environment `NoSuchEnv` doesn't exist"),
        ('gym.env_id="no_such_module:make"', "gym.env_id: cannot import module 'no_such_module'"),
        ('gym.views.signed="test_gym_task:nope"', "gym.views.signed: module 'test_gym_task' has no 'nope'"),
        (
            'gym.views.signed="lidar"',
            "gym.views.signed: 'lidar' is not a key of the observation (cell, onehot)",
        ),
        ('gym.views.signed="test_gym_task:failing_view"', "view 'signed' failed on an observation: KeyError"),
        ('gym.wrappers=["NoSuchWrapper"]', "gym.wrappers: gymnasium.wrappers has no 'NoSuchWrapper'"),
        ('views=["onehot", "lidar"]', "views: the test_gym_task:make_corridor has no view 'lidar'"),
        ('agent="tabular"', "agent: 'tabular' needs a discrete task"),
        ("gym.episode_steps=0", "episode_steps, reward_classes and eval_episodes must be >= 1"),
        ("env={size=8}", 'env: a task = "gym" run does not read the [env] section'),
        ('gym.state_key="test_gym_task:unhashable_key"', "gym.state_key returned an unhashable list ([0])"),
        ('gym.state_key="cell"', "gym.state_key: 'cell' is neither one of ['minigrid'] nor a dotted path"),
        ('gym.state_key="minigrid"', "gym.state_key failed on the env: AttributeError"),
        ('gym.wrappers=["TimeLimit"]', "gym.wrappers: TimeLimit cannot wrap the env by itself"),
        (
            'gym.train_wrappers=["NoSuchWrapper"]',
            "gym.train_wrappers: gymnasium.wrappers has no 'NoSuchWrapper'",
        ),
    ],
)
def test_bad_gym_input_fails_with_one_line(tmp_path, override, message):
    with pytest.raises(ConfigError) as err:  # the config's checks, then its task's check step
        check_config(load_config(str(_corridor_toml(tmp_path)), [override]))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_view_that_changes_shape_fails_with_one_line():
    sensors = ObservationSensors(make_corridor(), {"bad": one_number_then_two})
    sensors.reset(seed=0)
    assert sensors.observe("bad").shape == (1,)
    sensors.step(1)
    with pytest.raises(ValueError, match="view 'bad' changed shape: 1 values at the first reset, 2 now"):
        sensors.observe("bad")


@pytest.mark.slow
def test_the_worked_example_runs_as_it_stands_and_its_agents_reach_the_goal(tmp_path):
    readme = (Path(__file__).parents[1] / "docs" / "your_env.md").read_text()
    block = readme.split("<!-- your-env-example:start -->")[1].split("<!-- your-env-example:end -->")[0]
    code = block.split("```python\n")[1].split("```")[0]
    (tmp_path / "corridor.py").write_text(code)
    done = subprocess.run(
        [sys.executable, "corridor.py"], cwd=tmp_path, capture_output=True, text=True, check=True
    )
    summary = json.loads(done.stdout)
    assert summary["mean"]["success"] == 1.0
    assert summary["mean"]["pseudo_accuracy"] > 0.95


@pytest.mark.slow
def test_under_the_adopted_defaults_with_only_the_envs_facts_both_agents_learn_the_corridor(tmp_path):
    """A small sparse-reward task no setting was chosen for: the adopted version of the defaults (a gym
    task's length and agents, labels bought by outcome and where the views disagree), given only the
    env's episode limit and the return its goal pays."""
    facts = {"gym.episode_steps": 20, "gym.max_return": 1.0}
    run_dir = train_env(make_corridor, VIEWS, runs_dir=tmp_path, settings=facts, show_progress=False)
    assert load_config(str(run_dir / "config.toml")).defaults == ADOPTED
    summary = json.loads((run_dir / "summary.json").read_text())
    for view in VIEWS:
        assert summary["per_view"][view]["success"] == 1.0, view
        assert summary["per_view"][view]["labelled_steps"] <= BUDGET


def test_a_lambda_cannot_be_saved_in_a_config():
    with pytest.raises(ValueError, match="cannot be named by a dotted path: define it at the top level"):
        gym_config(make_corridor, {"onehot": lambda obs: obs["onehot"]})


def test_a_keyed_pool_holds_each_state_action_pair_once_labelled_for_every_visit_or_none():
    settings = {**SETTINGS, "training.rounds": 1}
    cfg = gym_config(
        make_corridor, VIEWS, label_fraction=0.3, seed=3, state_key=corridor_cell, settings=settings
    )
    run = build_run(cfg)
    run.run()
    store = run.store
    assert isinstance(store, KeyedStepStore)
    # 9 cells to act in (the last ends the episode) x 2 actions, each pair one sample; keys by repr.
    assert sorted(store.ids) == sorted((repr(cell), a) for cell in range(LENGTH - 1) for a in range(2))
    assert len(store) == 18 and sorted(store.ids.values()) == list(range(18))
    for (key, action), n in store.ids.items():
        cell = int(key)
        assert store.labelled[n] == key_is_labelled(key, action, 0.3, cfg.seed)
        assert store.action[n] == action
        assert store.hidden_reward[n] == float(cell == LENGTH - 2 and action == 1)
        np.testing.assert_array_equal(store.rows["onehot"][store.state_row[n]], np.eye(LENGTH)[cell])
        after = min(max(cell + (1 if action == 1 else -1), 0), LENGTH - 1)
        np.testing.assert_array_equal(store.rows["onehot"][store.next_row[n]], np.eye(LENGTH)[after])
    # Views are stored on a pair's first visit only, a row shared where one new pair follows another.
    assert 18 < store.n_rows <= 36
    assert 0 < store.labelled[:18].sum() < 18
    # Each visit: both agents' envs (other views, one mask per run) reveal a pair's reward or both hide it.
    envs = [
        make_masked_gym(
            cfg.gym.env_id, v, (v,), 0.3, cfg.seed, view_specs=cfg.gym.views, state_key=cfg.gym.state_key
        )
        for v in VIEWS
    ]
    moves = np.random.default_rng(0).integers(0, 2, 60)
    for env in envs:
        env.reset(seed=0)
        cell = 0
        for action in moves:
            _, _, done, _, info = env.step(int(action))
            assert info["reward_observed"] == key_is_labelled(repr(cell), int(action), 0.3, cfg.seed)
            cell = env.unwrapped.pos
            if done:
                env.reset()
                cell = 0
    # A store keeps a pair's views once: 18 pairs, at most two rows each, however many steps.
    assert store.n_rows <= 2 * 18


def test_read_termination_gives_the_classifiers_whether_a_step_ended_its_episode():
    """Only the pair (cell 8, right) ends a corridor episode: its features end in 1, every other's in 0,
    and the classifiers are one input wider."""
    settings = {**SETTINGS, "training.rounds": 1, "gym.read_termination": True}
    run = build_run(
        gym_config(make_corridor, VIEWS, label_fraction=0.3, state_key=corridor_cell, settings=settings)
    )
    run.run()
    store, pool = run.store, run.task.pool()
    ended = np.array([store.ids.get((repr(LENGTH - 2), 1)) == n for n in range(len(store))])
    assert ended.sum() == 1
    np.testing.assert_array_equal(store.terminal[: len(store)], ended)
    # onehot: 10 numbers of s, 2 of the action, 10 of s', then the flag; signed: 1 + 2 + 1 + 1.
    assert [f.shape[-1] for f in pool.features] == run.task.feature_dims() == [23, 5]
    for features in pool.features:
        np.testing.assert_array_equal(features[:, -1], ended.astype(np.float32))
    without = gym_config(
        make_corridor, VIEWS, state_key=corridor_cell, settings={**SETTINGS, "training.rounds": 1}
    )
    assert build_run(without).task.feature_dims() == [22, 4]


def test_episode_end_classes_keep_the_goal_class_off_steps_that_go_on():
    """The corridor's goal class is labelled only on the pair that ends an episode: with the flag, the
    pool lets every other pair take class 0 alone, and no admitted pair that goes on gets the goal."""
    settings = {**SETTINGS, "training.rounds": 2, "gym.reward_classes": 2, "gym.episode_end_classes": True}
    cfg = gym_config(make_corridor, VIEWS, label_fraction=1.0, state_key=corridor_cell, settings=settings)
    assert build_run(cfg).task.section.episode_end_classes
    run = build_run(
        gym_config(
            make_corridor, VIEWS, label_fraction=0.5, seed=3, state_key=corridor_cell, settings=settings
        )
    )
    records = run.run()
    store, pool = run.store, run.task.pool()
    n = len(store)
    goal = int(run.classes.encode(np.array([1.0]))[0])
    assert goal == 1 and store.labelled[:n][store.terminal[:n]].all()  # seed 3 labels the goal pair
    assert pool.class_mask.shape == (n, 2)
    np.testing.assert_array_equal(pool.class_mask[:, goal], store.terminal[:n])
    assert pool.class_mask[:, 0].all()
    result = run.trainer.step(pool)
    goes_on = ~store.terminal[:n] & pool.unlabelled
    assert goes_on.any() and (result.pseudo_class[goes_on] != goal).all()
    assert (result.view_class[:, goes_on] != goal).all()
    assert {record["round"] for record in records} == {1, 2}


def test_a_store_from_a_checkpoint_older_than_its_terminal_flags_resumes():
    """Such a run never read the flags: its stored steps read as not ended, and new steps are kept."""
    store = KeyedStepStore({"cell": (1,)})
    for cell in range(3):
        store.add(store.add_row({"cell": np.zeros(1)}), 0, 0, True, 0.0, 0.0, key=cell)
    old = {name: value for name, value in store.state_dict().items() if name != "terminal"}
    resumed = KeyedStepStore({"cell": (1,)})
    resumed.load_state_dict(old)
    resumed.add(0, 1, 0, True, 1.0, 1.0, key=2, ends=(True, False))
    np.testing.assert_array_equal(resumed.terminal[: len(resumed)], [False, False, False, True])


def test_the_key_mask_labels_a_share_of_pairs_the_same_way_in_every_process():
    labelled = [key_is_labelled((x, "door"), a, 0.1, seed=7) for x in range(5000) for a in range(4)]
    assert 0.09 < np.mean(labelled) < 0.11
    assert key_is_labelled((12, "door"), 2, 0.1, seed=7) == labelled[12 * 4 + 2]
    other = [key_is_labelled((x, "door"), a, 0.1, seed=8) for x in range(5000) for a in range(4)]
    assert labelled != other
    # repr-based, not hash(): the same in a fresh process with another PYTHONHASHSEED.
    code = (
        "from dospcot.envs.masking import key_is_labelled as f; "
        "print([f(('k', x), 1, 0.5, 3) for x in range(20)])"
    )
    fresh = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONHASHSEED": "123"},
    )
    assert fresh.stdout.strip() == str([key_is_labelled(("k", x), 1, 0.5, 3) for x in range(20)])


@pytest.fixture
def doorkey() -> gym.Env:
    """MiniGrid-DoorKey-5x5, reset with seed 0 (skipped without the ``minigrid`` extra)."""
    pytest.importorskip("minigrid")
    env = make_gym_env("minigrid:MiniGrid-DoorKey-5x5-v0")
    env.reset(seed=0)
    return env


def test_the_minigrid_state_key_names_the_agents_pose_load_and_map(doorkey):
    env = doorkey
    cell, direction, held, grid = minigrid_views.state_key(env.unwrapped)
    assert cell == tuple(int(v) for v in env.unwrapped.agent_pos) and direction == env.unwrapped.agent_dir
    assert held is None and grid == env.unwrapped.grid.encode().tobytes()
    env.step(0)  # turn left: only the direction changes
    assert minigrid_views.state_key(env.unwrapped)[1:] == ((direction - 1) % 4, None, grid)
    # Another episode draws another map: the same pose is another state.
    maps = set()
    for seed in range(5):
        env.reset(seed=seed)
        maps.add(minigrid_views.state_key(env.unwrapped)[3])
    assert len(maps) > 1


def test_the_minigrid_views_read_the_map_and_the_agents_pose():
    minigrid = pytest.importorskip("minigrid")
    views = {"full": "minigrid.full", "pose": "minigrid.position", "ahead": "image"}
    env = make_masked_gym("minigrid:MiniGrid-DoorKey-5x5-v0", "full", tuple(views), 1.0, view_specs=views)
    _, info = env.reset(seed=0)
    unwrapped = env.unwrapped
    # The full view is what MiniGrid's own FullyObsWrapper observes.
    fully = minigrid.wrappers.FullyObsWrapper(gym.make("MiniGrid-DoorKey-5x5-v0"))
    np.testing.assert_array_equal(info["views"]["full"], fully.reset(seed=0)[0]["image"].ravel())
    x, y = unwrapped.agent_pos
    expected = np.concatenate([np.eye(5)[x], np.eye(5)[y], np.eye(4)[unwrapped.agent_dir]])
    np.testing.assert_array_equal(info["views"]["pose"], expected)
    assert info["views"]["ahead"].shape == (7 * 7 * 3,)
    # As indicators: one object type and one state per cell, the agent's direction on its own cell.
    indicators = minigrid_views.full_one_hot(unwrapped)
    assert indicators.shape == (5, 5, 15) and (indicators.sum(axis=-1) == 2).all()
    full = info["views"]["full"].reshape(5, 5, 3)
    np.testing.assert_array_equal(indicators[..., :11].argmax(-1), full[..., 0])
    assert indicators[x, y, 10] == 1 and indicators[x, y, 11 + unwrapped.agent_dir] == 1
    _, _, _, _, info = env.step(1)  # turn right: the pose follows
    assert info["views"]["pose"][10 + (unwrapped.agent_dir)] == 1.0


def test_the_egocentric_map_puts_the_agent_at_its_centre_facing_up(doorkey):
    env = doorkey
    unwrapped = env.unwrapped
    indicators = minigrid_views.full_one_hot(unwrapped)
    centre = 4  # a 5 x 5 map: 9 x 9 cells, the agent at (4, 4)
    # Direction -> (the cell ahead, the cell on the agent's right), as MiniGrid moves: 0 +x, 1 +y, ...
    ahead = {0: (1, 0), 1: (0, 1), 2: (-1, 0), 3: (0, -1)}
    for direction in range(4):
        unwrapped.agent_dir = direction
        view = minigrid_views.egocentric_map(unwrapped)
        assert view.shape == (9, 9, 15) and view.flags.c_contiguous and view.dtype == bool  # stored as bits
        x, y = unwrapped.agent_pos
        assert view[centre, centre, 10] == 1  # the agent
        dx, dy = ahead[direction]
        right_x, right_y = -dy, dx  # a quarter turn clockwise on screen (y grows downwards)
        np.testing.assert_array_equal(view[centre, centre - 1], indicators[x + dx, y + dy])
        np.testing.assert_array_equal(view[centre + 1, centre], indicators[x + right_x, y + right_y])
        # Every map cell appears once, the rest of the canvas is empty.
        assert view.sum() == indicators.sum() and (view.sum(axis=-1) > 0).sum() == 25


def test_a_keyed_run_resumed_from_its_checkpoint_ends_as_the_uninterrupted_run(keyed_run):
    settings = {**SETTINGS, "training.rounds": 2, "training.steps_per_round": 600}
    cfg = gym_config(make_corridor, VIEWS, label_fraction=0.3, state_key=corridor_cell, settings=settings)
    whole = keyed_run
    assert whole.cfg == cfg
    first = build_run(cfg)
    first.run_round()
    saved = pickle.dumps(first.state_dict())
    resumed = build_run(cfg)
    resumed.load_state_dict(pickle.loads(saved))
    resumed.run_round()
    assert resumed.store.ids == whole.store.ids
    np.testing.assert_array_equal(resumed.table.reward, whole.table.reward)
    for a, b in zip(whole.agents, resumed.agents, strict=True):
        for p, q in zip(a.policy.parameters(), b.policy.parameters(), strict=True):
            assert np.array_equal(p.detach().numpy(), q.detach().numpy())


def test_a_none_env_kwarg_is_refused_as_a_config_cannot_hold_it():
    with pytest.raises(ConfigError, match=r"env_kwargs\.render_mode: None cannot be saved in a config"):
        gym_config(make_corridor, VIEWS, settings={"gym.env_kwargs": {"render_mode": None}})


def test_minigrid_action_sets_keep_the_actions_a_task_needs():
    pytest.importorskip("minigrid")
    env = make_gym_env(
        "minigrid:MiniGrid-DoorKey-5x5-v0", wrappers=["dospcot.envs.minigrid_views:DoorActions"]
    )
    assert env.action_space == gym.spaces.Discrete(5)
    assert [env.action(a) for a in range(5)] == [0, 1, 2, 3, 5]  # 4 is toggle, MiniGrid's 5
    env.reset(seed=0)
    direction = env.unwrapped.agent_dir
    env.step(1)  # turn right
    assert env.unwrapped.agent_dir == (direction + 1) % 4
    moves = make_gym_env(
        "minigrid:MiniGrid-LavaGapS7-v0", wrappers=["dospcot.envs.minigrid_views:MoveActions"]
    )
    assert moves.action_space == gym.spaces.Discrete(3)


def test_a_random_policy_reaches_lavagaps_goal_more_often_with_three_actions_than_with_seven():
    pytest.importorskip("minigrid")
    goals = {}
    for wrappers in ((), ("dospcot.envs.minigrid_views:MoveActions",)):
        env = make_gym_env("minigrid:MiniGrid-LavaGapS7-v0", wrappers=wrappers)
        env.reset(seed=0)
        env.action_space.seed(0)
        goals[len(wrappers)] = 0
        for _ in range(10_000):
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            goals[len(wrappers)] += reward > 0
            if terminated or truncated:
                env.reset()
    assert goals[1] > 2 * goals[0] > 0


def test_exploring_starts_move_training_episodes_only_and_follow_the_envs_seed():
    pytest.importorskip("minigrid")
    env_id, start = "minigrid:MiniGrid-LavaGapS7-v0", "dospcot.envs.minigrid_views:RandomStart"
    starts = []
    for seed in range(20):
        env = make_gym_env(env_id, train_wrappers=[start])
        env.reset(seed=seed)
        u = env.unwrapped
        assert u.grid.get(*u.agent_pos) is None  # an empty cell: not lava, wall or the goal
        starts.append((tuple(int(v) for v in u.agent_pos), u.agent_dir))
        again = make_gym_env(env_id, train_wrappers=[start])
        again.reset(seed=seed)
        assert (tuple(int(v) for v in again.unwrapped.agent_pos), again.unwrapped.agent_dir) == starts[-1]
    assert len(set(starts)) > 10
    # The image observation is drawn from the new pose.
    env = make_gym_env(env_id, train_wrappers=[start])
    obs, _ = env.reset(seed=3)
    np.testing.assert_array_equal(obs["image"], env.unwrapped.gen_obs()["image"])
    # A run's training envs start anywhere, its evaluation envs at the task's start (1, 1).
    views = {"image": "image", "pose": "minigrid.position"}
    cfg = gym_config(
        env_id,
        views,
        settings={"gym.wrappers": ["dospcot.envs.minigrid_views:MoveActions"], "gym.train_wrappers": [start]},
    )
    task = build_run(cfg).task
    train_starts = set()
    for seed in range(10):
        _, info = task.agent_env(0, "image").reset(seed=seed)
        train_starts.add(tuple(info["views"]["pose"]))
    assert len(train_starts) > 1
    for env in task.eval_envs:
        env.reset()
        assert tuple(int(v) for v in env.envs[0].unwrapped.agent_pos) == (1, 1)


def test_reachable_starts_skip_the_empty_space_a_start_cannot_reach():
    pytest.importorskip("minigrid")
    random_start, reachable = (
        f"dospcot.envs.minigrid_views:{name}" for name in ("RandomStart", "ReachableStart")
    )
    # Where every empty cell connects (through DoorKey's locked door), both draw the same starts.
    for seed in range(10):
        poses = []
        for start in (random_start, reachable):
            env = make_gym_env("minigrid:MiniGrid-DoorKey-5x5-v0", train_wrappers=[start])
            env.reset(seed=seed)
            poses.append((tuple(int(v) for v in env.unwrapped.agent_pos), env.unwrapped.agent_dir))
        assert poses[0] == poses[1]
    # MultiRoom's two rooms sit in a 25 x 25 map of empty space: a reachable start lies inside them,
    # where the task's own start and its goal are.
    for seed in range(10):
        task = make_gym_env("minigrid:MiniGrid-MultiRoom-N2-S4-v0")
        task.reset(seed=seed)
        inside = {(x, y) for room in task.unwrapped.rooms for x, y in _room_cells(room)}
        env = make_gym_env("minigrid:MiniGrid-MultiRoom-N2-S4-v0", train_wrappers=[reachable])
        env.reset(seed=seed)
        assert tuple(int(v) for v in env.unwrapped.agent_pos) in inside
        assert env.unwrapped.grid.get(*env.unwrapped.agent_pos) is None


def _room_cells(room) -> list[tuple[int, int]]:
    """The cells inside a MultiRoom room's walls."""
    (x0, y0), (w, h) = room.top, room.size
    return [(x, y) for x in range(x0 + 1, x0 + w - 1) for y in range(y0 + 1, y0 + h - 1)]


def test_the_map_encoding_is_read_once_per_step_and_follows_every_change(doorkey):
    env = doorkey
    u = env.unwrapped
    first = minigrid_views.map_encoding(u)
    assert minigrid_views.map_encoding(u) is first  # the same step: encoded once
    np.testing.assert_array_equal(first, u.grid.encode())
    # Stand beside the key, facing it, and pick it up: the map changes with the step.
    kx, ky = next((x, y) for x in range(5) for y in range(5) if (c := u.grid.get(x, y)) and c.type == "key")
    u.agent_pos, u.agent_dir = (kx, ky - 1), 1  # above the key, facing down (direction 1)
    assert u.grid.get(kx, ky - 1) is None
    env.step(3)  # pick up
    assert u.carrying is not None and u.carrying.type == "key"
    after = minigrid_views.map_encoding(u)
    np.testing.assert_array_equal(after, u.grid.encode())
    assert after[kx, ky, 0] == 1 and first[kx, ky, 0] == 5  # empty now, a key before
    # A reset draws a new map, encoded afresh even at the same step count.
    env.reset(seed=1)
    np.testing.assert_array_equal(minigrid_views.map_encoding(u), u.grid.encode())
    assert minigrid_views.state_key(u)[3] == u.grid.encode().tobytes()


def _corridor_demonstrations(path: Path, episodes: int = 2) -> Path:
    """An expert's episodes on the corridor, always right: cells 0..8, the last step pays 1."""
    cells = np.tile(np.arange(LENGTH - 1), episodes)
    onehot = np.eye(LENGTH, dtype=np.float32)
    signed = (2 * cells / (LENGTH - 1) - 1).astype(np.float32)[:, None]
    next_signed = (2 * (cells + 1) / (LENGTH - 1) - 1).astype(np.float32)[:, None]
    Demonstrations(
        {"onehot": onehot[cells], "signed": signed},
        {"onehot": onehot[cells + 1], "signed": next_signed},
        np.ones(len(cells), np.int64),
        np.repeat(np.arange(episodes), LENGTH - 1),
        (cells == LENGTH - 2).astype(np.float64),
    ).save(path)
    return path


def test_a_gym_run_reads_demonstrations_from_a_file_as_labels_and_for_the_margin_loss(tmp_path):
    path = _corridor_demonstrations(tmp_path / "demos.npz", episodes=3)
    settings = {**SETTINGS, "demonstrations.file": str(path), "demonstrations.episodes": 2}
    run = build_run(gym_config(make_corridor, VIEWS, label_fraction=0.1, settings=settings))
    store = run.store
    # The first two episodes' 18 steps are the pool's first samples, labelled, with their rewards.
    assert len(store) == 18 and store.labelled[:18].all()
    np.testing.assert_array_equal(store.label_value[:18], np.tile((np.arange(9) == 8).astype(float), 2))
    np.testing.assert_array_equal(store.features("onehot", 2)[:9, :LENGTH], np.eye(LENGTH)[:9])
    assert all(agent.n_demonstrations == 18 for agent in run.agents)
    # Without labels the rewards go unread: the store stays empty, the loss keeps the steps.
    settings["demonstrations.labels"] = False
    run = build_run(gym_config(make_corridor, VIEWS, settings=settings))
    assert len(run.store) == 0 and all(agent.n_demonstrations == 18 for agent in run.agents)


def test_bad_demonstrations_files_for_a_gym_run_fail_with_one_line(tmp_path):
    path = _corridor_demonstrations(tmp_path / "demos.npz")
    settings = {**SETTINGS, "demonstrations.file": str(path)}
    with pytest.raises(ValueError, match="holds no view 'cell' \\(it has onehot, signed\\)"):
        build_run(gym_config(make_corridor, {"onehot": "onehot", "cell": "cell"}, settings=settings))
    with pytest.raises(
        ValueError, match="a file's steps name no state key, so they cannot join a keyed pool"
    ):
        build_run(gym_config(make_corridor, VIEWS, state_key=corridor_cell, settings=settings))
    with pytest.raises(ConfigError, match=r"gym\.read_termination: demonstrations do not record which"):
        gym_config(make_corridor, VIEWS, settings={**settings, "gym.read_termination": True})
    with pytest.raises(ConfigError, match=r"gym\.episode_end_classes: demonstrations do not record which"):
        gym_config(make_corridor, VIEWS, settings={**settings, "gym.episode_end_classes": True})
    with pytest.raises(ConfigError, match=r"demonstrations\.file: demonstrations: cannot read"):
        check_config(
            gym_config(make_corridor, VIEWS, settings={"demonstrations.file": str(tmp_path / "none.npz")})
        )
    with pytest.raises(ConfigError, match='a task = "gym" run\'s demonstrations come from a file or a saved'):
        gym_config(make_corridor, VIEWS, settings={"demonstrations.episodes": 3})
    with pytest.raises(ConfigError, match="a grid run's demonstrations come from value iteration"):
        load_config("grid16-dospcot", [f"demonstrations.file={str(path)!r}"])


def _saved_corridor_agent(path: Path) -> Path:
    """A DQN on the corridor's one-hot view whose greedy action is always 1 (right): the expert."""
    corridor = make_corridor()
    space = corridor.observation_space["onehot"]
    env = gym.wrappers.TransformObservation(corridor, lambda obs: obs["onehot"], space)
    agent = stable_baselines3.DQN("MlpPolicy", env, seed=0)
    with torch.no_grad():
        for net in (agent.q_net, agent.q_net_target):
            last = net.q_net[-1]
            last.weight.zero_()
            last.bias.copy_(torch.tensor([0.0, 1.0]))
    agent.save(path)
    return path


def test_a_saved_agent_demonstrates_its_greedy_episodes_in_every_view(tmp_path):
    path = _saved_corridor_agent(tmp_path / "expert.zip")
    settings = {**SETTINGS, "demonstrations.agent": str(path), "demonstrations.episodes": 2}
    run = build_run(gym_config(make_corridor, VIEWS, label_fraction=0.1, settings=settings))
    demos = run.task.demos
    # Two walks right from cell 0: 9 steps each, the last one paying the goal's 1.
    assert demos.n_episodes == 2 and len(demos) == 18 and (demos.actions == 1).all()
    np.testing.assert_array_equal(demos.rewards, np.tile((np.arange(9) == 8).astype(float), 2))
    np.testing.assert_array_equal(demos.observations["onehot"][:9], np.eye(LENGTH, dtype=np.float32)[:9])
    np.testing.assert_allclose(
        demos.next_observations["signed"][:9, 0], 2 * np.arange(1, 10) / 9 - 1, atol=1e-6
    )
    # As labels, its steps are the pool's first samples; every agent's margin loss reads them.
    assert run.store.labelled[:18].all() and all(agent.n_demonstrations == 18 for agent in run.agents)
    demos.save(tmp_path / "recorded.npz")  # a recording round-trips through the file format
    again = Demonstrations.load(tmp_path / "recorded.npz")
    np.testing.assert_array_equal(again.observations["signed"], demos.observations["signed"])
    np.testing.assert_array_equal(again.rewards, demos.rewards)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            {"demonstrations.agent_algorithm": "NoSuchAlgo"},
            "'NoSuchAlgo' is not an SB3 or sb3-contrib algorithm",
        ),
        ({"demonstrations.agent_view": "lidar"}, "agent_view: the .* has no view 'lidar'"),
        ({"demonstrations.agent_view": "signed"}, r"observes shape \(10,\), but view 'signed' gives \(1,\)"),
        ({"demonstrations.episodes": 0}, "agent: set episodes"),
        ({"demonstrations.file": "demos.npz"}, "give file or agent, not both"),
        ({"demonstrations.agent": "missing.zip"}, "agent: no file 'missing.zip'"),
        ({"demonstrations.agent": "corrupt.zip"}, "cannot load 'corrupt.zip' as DQN"),
    ],
)
def test_bad_demonstrating_agents_fail_with_one_line(tmp_path, monkeypatch, override, message):
    monkeypatch.chdir(tmp_path)
    path = _saved_corridor_agent(tmp_path / "expert.zip")
    (tmp_path / "corrupt.zip").write_text("not a zip")
    settings = {**SETTINGS, "demonstrations.agent": str(path), "demonstrations.episodes": 2, **override}
    with pytest.raises(ValueError, match=message):
        build_run(gym_config(make_corridor, VIEWS, settings=settings))


def test_a_minigrid_query_names_its_state_by_a_short_digest_the_same_in_every_query():
    pytest.importorskip("minigrid")
    settings = ["training.rounds=1", "training.steps_per_round=300", "training.label_strategy=outcomes"]
    run = build_run(load_config("minigrid-doorkey-dospcot", settings))
    run.run()
    store = run.task.store
    texts = {n: run.task.describe(n)["key"] for n in range(len(store))}
    for (_, action), n in store.ids.items():  # a state's pairs share its name; no raw map bytes shown
        assert re.fullmatch(r"state #[0-9a-f]{12}, action \d", texts[n]) and "\\x" not in texts[n]
        assert texts[n].endswith(f", action {action}")
    by_state: dict[str, set[str]] = {}
    for (key, _), n in store.ids.items():
        by_state.setdefault(key, set()).add(texts[n].rsplit(",", 1)[0])
    assert all(len(names) == 1 for names in by_state.values())
    assert len({next(iter(names)) for names in by_state.values()}) == len(by_state)  # states apart


def test_minigrid_indicator_views_are_stored_as_uint8_and_read_as_the_same_floats():
    pytest.importorskip("minigrid")

    views = {"ego": "minigrid.egocentric_map", "image": "image"}
    env = make_masked_gym("minigrid:MiniGrid-DoorKey-5x5-v0", "ego", tuple(views), 1.0, view_specs=views)
    assert env.observation_space.dtype == np.uint8 and env.observation_space.shape == (9 * 9 * 15,)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.uint8 and env.observation_space.contains(obs)
    spaces = {v: env.get_wrapper_attr("view_space")(v) for v in views}
    assert all(space.dtype == np.uint8 for space in spaces.values())
    shapes = {v: space.shape for v, space in spaces.items()}
    compact = StepStore(shapes, {v: space.dtype for v, space in spaces.items()})
    wide = StepStore(shapes)  # float32 rows, as before
    for store in (compact, wide):
        assert store.rows["ego"].dtype == (np.uint8 if store is compact else np.float32)
    rng = np.random.default_rng(0)
    state = {v: np.array(info["views"][v]) for v in views}
    for _ in range(40):
        _, _, terminated, truncated, info = env.step(int(rng.integers(3)))
        following = {v: np.array(info["views"][v]) for v in views}
        for store in (compact, wide):
            rows = store.add_row(state), store.add_row(following)
            store.add(rows[0], 0, rows[1], True, 0.0, 0.0, ends=(terminated, truncated))
        state = following
        if terminated or truncated:
            _, info = env.reset(seed=1)
            state = {v: np.array(info["views"][v]) for v in views}
    for view in views:
        for termination in (False, True):
            new, old = compact.features(view, 3, termination), wide.features(view, 3, termination)
            assert new.dtype == old.dtype == np.float32
            np.testing.assert_array_equal(new, old)


def test_store_features_in_float64_hold_the_float32_values():
    """The classifiers' float64 inputs are built directly, with the values the float32 inputs hold:
    a float64 view is rounded to float32 first (1/3 has no float32 form), a uint8 view is exact."""
    store = StepStore({"fine": (2,), "onehot": (3,)}, {"fine": np.float64, "onehot": np.uint8})
    rows = [
        store.add_row({"fine": np.array([1 / 3, 2.0]), "onehot": np.eye(3, dtype=np.uint8)[i]})
        for i in range(2)
    ]
    store.add(rows[0], 1, rows[1], True, 0.0, 0.0, ends=(True, False))
    for view in ("fine", "onehot"):
        wide = store.features(view, 2, termination=True, dtype=np.float64)
        narrow = store.features(view, 2, termination=True)
        assert wide.dtype == np.float64 and narrow.dtype == np.float32
        np.testing.assert_array_equal(wide, narrow.astype(np.float64))
    wide = store.features("fine", 2, termination=True, dtype=np.float64)
    assert wide[0, 0] == float(np.float32(1 / 3)) != 1 / 3
    np.testing.assert_array_equal(wide[0, 2:4], [0.0, 1.0])  # the one-hot action
    assert wide[0, -1] == 1.0  # it ended its episode


def test_the_python_api_refuses_a_share_the_versions_budget_leaves_unread_and_a_key_never_read():
    assert gym_config(make_corridor, VIEWS).training.label_budget == BUDGET  # the adopted version's
    with pytest.raises(ConfigError, match=r"training\.label_fraction: unread"):
        gym_config(make_corridor, VIEWS, label_fraction=0.1)
    uniform = {"training.label_strategy": "uniform"}
    assert gym_config(make_corridor, VIEWS, label_fraction=0.1, settings=uniform).mask_fraction == 0.1
    with pytest.raises(ConfigError, match='method = "oracle" never reads it'):
        gym_config(make_corridor, VIEWS, method="oracle", settings={"cotraining.consensus_weight": 0.3})
