"""Segment labels: the mask's segment sums by hand, the segment store and pool, the per-step reward
model's regression on sums, leakage, and a co-training run that resumes."""

import json
import pickle
import re
import runpy
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from test_gym_task import LENGTH, SETTINGS, corridor_cell, make_corridor
from test_gym_task import VIEWS as GYM_VIEWS
from test_neural_cotraining import LAYOUT, SECTIONS, assert_same_learners, config, grid

from dospcot.config.errors import ConfigError
from dospcot.config.learning_sections import ClassifierConfig
from dospcot.core.reward_classes import QuantileRewardClasses
from dospcot.core.segments import (
    SegmentLabelWrapper,
    SegmentStore,
    fit_step_rewards,
    segment_pool,
    step_rewards,
)
from dospcot.core.self_paced import RunPool
from dospcot.envs import GridWorld, RewardMaskWrapper
from dospcot.run.python_api import gym_config
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

REWARDS = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0]


class Scripted(gym.Env):
    """One state; step t pays ``REWARDS[t]``; the episode ends after the last of them."""

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.t = 0
        return 0, {}

    def step(self, action: int):
        self.t += 1
        return 0, REWARDS[self.t - 1], self.t == len(REWARDS), False, {"rewards": {"part": 1.0}}


def _episode(env: gym.Env, seed: int = 0) -> list[tuple[float, dict]]:
    env.reset(seed=seed)
    steps, done = [], False
    while not done:
        _, reward, terminated, truncated, info = env.step(0)
        steps.append((reward, info))
        done = terminated or truncated
    return steps


@pytest.mark.parametrize("mode", ["transition", "state-action"])
def test_a_segment_label_is_the_sum_of_its_hidden_rewards_and_no_single_reward_shows(mode):
    steps = _episode(RewardMaskWrapper(Scripted(), 1.0, mode=mode, segment_length=3))
    assert [reward for reward, _ in steps] == [0.0] * 7
    assert not any(info["reward_observed"] or "rewards" in info for _, info in steps)
    assert [info["hidden_reward"] for _, info in steps] == REWARDS  # metrics only
    # Segments of 3 steps from the episode's start; the episode's end cuts the last one short.
    assert [info.get("segment_end", False) for _, info in steps] == [False, False, True] * 2 + [True]
    assert [info["segment_label"] for _, info in steps if "segment_label" in info] == [7.0, 56.0, 64.0]
    # A time limit ends a segment too.
    truncated = _episode(RewardMaskWrapper(gym.wrappers.TimeLimit(Scripted(), 5), 1.0, segment_length=3))
    assert [info["segment_label"] for _, info in truncated if "segment_label" in info] == [7.0, 24.0]


def test_segments_are_labelled_at_the_label_fraction_and_a_seeded_reset_replays_them():
    env = RewardMaskWrapper(Scripted(), 0.3, mask_seed=5, segment_length=2)
    labelled = [
        ["segment_label" in info for _, info in _episode(env, seed) if "segment_end" in info]
        for seed in range(400)
    ]
    assert np.mean(labelled) == pytest.approx(0.3, abs=0.03)
    assert labelled[7] == ["segment_label" in info for _, info in _episode(env, 7) if "segment_end" in info]


def test_segment_labels_refuse_a_monitor_and_revealed_keys():
    with pytest.raises(ValueError, match="cannot be combined with a reward monitor"):
        RewardMaskWrapper(Scripted(), 0.5, monitored_states=np.array([True]), segment_length=2)
    with pytest.raises(ValueError, match="cannot be combined with a reward monitor"):
        RewardMaskWrapper(Scripted(), 0.5, mode="transition", reveal_first_steps=2, segment_length=2)
    with pytest.raises(ValueError, match="segment_length must be an integer >= 1, got 0"):
        RewardMaskWrapper(Scripted(), 0.5, segment_length=0)
    with pytest.raises(ValueError, match="a segment has at least 2 steps"):
        SegmentStore(1)


def test_the_store_keeps_each_segment_once_and_the_wrapper_drops_one_cut_off_by_a_reset():
    store = SegmentStore(3)
    assert store.add([4, 5, 6], None, -3.0) == 0
    assert store.add([7], 2.0, 2.0) == 1
    assert store.add([4, 5, 6], -3.0, -3.0) == 0  # seen again, labelled this time
    assert len(store) == 2
    assert store.ids[:2].tolist() == [[4, 5, 6], [7, -1, -1]]
    assert store.labelled[:2].tolist() == [True, True] and store.label[:2].tolist() == [-3.0, 2.0]

    class Ids(gym.Wrapper):  # the store wrapper's part: each step's store id
        def step(self, action):
            obs, reward, terminated, truncated, info = self.env.step(action)
            return obs, reward, terminated, truncated, dict(info, store_id=self.env.unwrapped.t * 10)

    segments = SegmentStore(3)
    env = SegmentLabelWrapper(Ids(RewardMaskWrapper(Scripted(), 1.0, mode="transition")), segments)
    assert env.get_wrapper_attr("segment_length") == 3  # the wrapper set the mask's
    env.reset(seed=0)
    for _ in range(5):
        env.step(0)
    env.reset(seed=1)  # steps 4 and 5 made no whole segment: dropped
    _episode(env, 1)
    assert segments.ids[: len(segments)].tolist() == [[10, 20, 30], [40, 50, 60], [70, -1, -1]]
    assert segments.label[: len(segments)].tolist() == [7.0, 56.0, 64.0] == segments.hidden[:3].tolist()


def test_a_segments_input_is_the_sum_of_its_steps_inputs_and_its_class_a_bin_of_its_sum():
    step_features = np.array([[1.0, 0.0], [0.0, 1.0], [2.0, 2.0]])  # (N = 3, d = 2)
    steps = RunPool([step_features], np.zeros(3, bool), np.full(3, -1), np.ones(3, bool), np.ones(4, bool))
    store = SegmentStore(2)
    store.add([0, 2], 5.0, 5.0)
    store.add([1], None, 0.0)
    store.add([1, 0], 0.0, 0.0)
    pool = segment_pool(steps, store, QuantileRewardClasses(4))
    assert pool.features[0].tolist() == [[3.0, 2.0], [0.0, 1.0], [1.0, 1.0]]
    assert pool.labelled.tolist() == [True, False, True]
    assert pool.unlabelled.tolist() == [False, True, False]
    assert pool.label_class.tolist() == [1, -1, 0]  # two sums seen, 0 and 5: a class each
    assert pool.class_mask.tolist() == [True, True, False, False]


def test_the_per_step_model_recovers_rewards_that_the_segment_sums_determine():
    rng = np.random.default_rng(0)
    true = np.array([0.0, -1.0, 5.0, -100.0])  # a lava-like reward beside small ones
    kinds = rng.integers(4, size=400)
    ids = rng.integers(400, size=(150, 4))
    ids[:10, 3] = -1  # short segments
    sums = np.where(ids >= 0, true[kinds[ids]], 0.0).sum(axis=1)
    reward = fit_step_rewards(np.eye(4)[kinds], ids, sums, np.ones(150), ClassifierConfig(), seed=0)
    assert np.abs(reward - true[kinds]).max() < 0.05
    # A segment of weight 0 says nothing: a wrong sum there changes nothing.
    wrong = np.concatenate([sums, [1e3]])
    weights = np.concatenate([np.ones(150), [0.0]])
    again = fit_step_rewards(
        np.eye(4)[kinds], np.vstack([ids, ids[:1]]), wrong, weights, ClassifierConfig(), 0
    )
    assert np.array_equal(again, reward)


def test_a_steps_weight_is_the_largest_weight_of_a_segment_holding_it():
    steps = RunPool([np.eye(5)], np.zeros(5, bool), np.full(5, -1), np.ones(5, bool), np.ones(2, bool))
    store = SegmentStore(2)
    for ids in ([0, 1], [1, 2], [3]):
        store.add(ids, None, 0.0)
    _, weight = step_rewards(
        steps, store, np.zeros(3), np.array([0.5, 0.8, 0.0]), ClassifierConfig(epochs=1), [0]
    )
    assert weight.tolist() == [0.5, 0.8, 0.8, 0.0, 0.0]  # step 4 is in no segment


K = 4
SEGMENTS = {"segment_length": K, "label_fraction": 0.3}


class SumPreservingRewards(gym.Wrapper):
    """Different rewards step by step, the same sum over every k-step window of an episode (the windows
    of the mask's segments: the episode's 36 steps are 9 windows of 4): step t of a window pays
    r_t + c_{t-1} - c_t with c_t = r_t + 1, the window's last step r_t + c_{t-1}."""

    def reset(self, **kwargs):
        self._t, self._carry = 0, 0.0
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._t += 1
        end = self._t == K or terminated or truncated
        shifted = reward + self._carry - (0.0 if end else reward + 1.0)
        self._carry = 0.0 if end else reward + 1.0
        self._t = 0 if end else self._t
        return obs, shifted, terminated, truncated, info


def _shifted_grid() -> gym.Env:
    return SumPreservingRewards(GridWorld(LAYOUT))


def test_leakage_rewards_that_keep_every_segment_sum_leave_the_learners_bit_identical():
    assert SECTIONS["env"]["max_episode_steps"] % K == 0
    cfg = config("dospcot", ("dqn", "esarsa_dqn"), ("coords", "patch"), seed=3, training=SEGMENTS)
    # SB3 seeds the global generators when an agent is built: build and run one run at a time.
    a = grid(cfg)
    a.run()
    b = grid(cfg, _shifted_grid)
    b.run()
    # The single rewards differed; only the segment sums reached the learners, and they agree.
    assert not np.array_equal(a.store.hidden_reward, b.store.hidden_reward)
    assert a.segments.labelled.any() and np.array_equal(a.segments.label, b.segments.label)
    assert_same_learners(a, b)


def test_a_run_on_segment_labels_cotrains_on_segments_and_resumes_from_its_state():
    build = partial(grid, config("dospcot", ("dqn", "dqn"), ("coords", "patch"), seed=1, training=SEGMENTS))
    full = build()
    records = full.run()
    n = len(full.segments)
    # No single reward was revealed; the pool's samples were the segments.
    assert not full.store.labelled.any() and 0 < full.segments.labelled[:n].sum() < n
    assert 0 < records[-1]["coverage"] <= 1 and records[-1]["pseudo_accuracy"] > 0.5
    in_a_segment = np.isin(np.arange(len(full.table)), full.segments.ids[:n])
    assert (full.table.weight[~in_a_segment] == 0).all() and (full.table.weight[in_a_segment] > 0).any()
    # The decoding error, metrics only: the mean distance of the table's rewards from the hidden
    # ones over the steps the agents read.
    read = full.table.weight > 0
    error = np.abs(full.table.reward[read] - full.store.hidden_reward[read]).mean()
    assert records[-1]["step_reward_error"] == pytest.approx(error)
    first = build()
    first.run_round()
    state = pickle.dumps(first.state_dict())
    resumed = build()
    resumed.load_state_dict(pickle.loads(state))
    assert json.dumps(resumed.run_round()) == json.dumps(records[2:])
    assert np.array_equal(resumed.table.reward, full.table.reward)
    with pytest.raises(ConfigError, match="segment labels need co-training"):
        config("labels-only", ("dqn", "dqn"), ("coords", "patch"), seed=1, training=SEGMENTS)


@pytest.mark.parametrize(
    ("preset", "override", "message"),
    [
        ("grid16-labels-only", [], r'segment labels need co-training .*got method = "labels-only"'),
        (
            "grid16-dospcot",
            ["demonstrations.episodes=3", "demonstrations.labels=true"],
            "cannot be labels too",
        ),
        ("grid16-dospcot", ["env.monitored_columns=2"], "combined with a reward monitor"),
        ("fasthighway-dospcot", ["highway.reveal_first_steps=5"], "combined with a reward monitor"),
    ],
)
def test_bad_segment_settings_fail_with_one_line(preset, override, message):
    with pytest.raises(ConfigError, match=message):
        load_config(preset, ["training.segment_length=4", *override])
    with pytest.raises(ConfigError, match="segment_length must be >= 1, got 0"):
        load_config("grid16-dospcot", ["training.segment_length=0"])


@pytest.mark.parametrize("keyed", [False, True])
def test_on_a_gym_task_each_stored_segment_is_labelled_with_the_sum_of_its_steps_hidden_rewards(keyed):
    settings = {
        **SETTINGS,
        "training.rounds": 1,
        "training.steps_per_round": 800,
        "training.segment_length": 3,
    }
    key = {"state_key": corridor_cell} if keyed else {}
    run = build_run(gym_config(make_corridor, GYM_VIEWS, label_fraction=0.5, settings=settings, **key))
    run.run_round()
    store, segments = run.store, run.segments
    n = len(segments)
    ids = segments.ids[:n]
    # The step store's hidden rewards (metrics only), summed over each segment's steps.
    sums = np.where(ids >= 0, store.hidden_reward[np.maximum(ids, 0)], 0.0).sum(axis=1)
    assert np.array_equal(segments.hidden[:n], sums) and (sums > 0).any()  # some reached the goal
    labelled = segments.labelled[:n]
    assert np.array_equal(segments.label[:n][labelled], sums[labelled])
    assert not store.labelled[: len(store)].any()
    if keyed:  # a pool of (cell, action) pairs: segments repeat, and each is stored once
        assert len(set(map(tuple, ids))) == n and len(store) <= 2 * LENGTH
        return
    assert 0.4 < labelled.mean() < 0.6
    # Each step is in one segment, but for the at most k - 1 of each agent that the round's end cut off.
    steps = ids[ids >= 0]
    assert np.unique(steps).size == steps.size and 0 <= len(store) - steps.size <= 2 * (3 - 1)


def _segment_decoding(monkeypatch, *argv: str) -> None:
    monkeypatch.setattr("sys.argv", ["segment_decoding.py", *argv])
    script = Path(__file__).resolve().parent.parent / "scripts" / "segment_decoding.py"
    runpy.run_path(str(script), run_name="__main__")


def test_the_decoding_diagnostic_counts_every_step_the_agents_read_and_refuses_per_step_labels(
    monkeypatch, capsys
):
    small = [
        "env.size=6",
        "env.max_episode_steps=24",
        "training.rounds=1",
        "training.steps_per_round=400",
        "training.learn_from_round=1",
        "dqn.learning_starts=100",
        "training.segment_length=4",
        "training.label_fraction=0.2",
    ]
    _segment_decoding(monkeypatch, "grid16-dospcot", *(f"--set={s}" for s in small))
    out = capsys.readouterr().out
    read = int(re.search(r"(\d+) steps read by the agents", out)[1])
    rows = [line.split(" | ") for line in out.splitlines() if re.match(r"\| -?\d", line)]
    assert read > 0 and sum(int(row[1]) for row in rows) == read
    assert {float(row[0][2:]) for row in rows} <= {-1.0, -100.0, 0.0}  # the grid's step, lava and goal
    with pytest.raises(SystemExit):
        _segment_decoding(monkeypatch, "grid16-dospcot")
    assert "the config has no segment labels" in capsys.readouterr().err
