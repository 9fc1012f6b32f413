"""Highway tasks: the highway-env adapter, sensor views, binned reward classes, transition co-training."""

import csv
import json
import math
import pickle
from functools import partial

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from PIL import Image
from small_runs import PINNED
from stable_baselines3 import DQN
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from dospcot.adapters.sensor_adapter import SensorAdapter
from dospcot.cli import main
from dospcot.config.errors import ConfigError
from dospcot.core.reward_classes import QuantileRewardClasses
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.envs.masked_highway import make_masked_highway
from dospcot.raters.file_rater import QueriesPending
from dospcot.run.checks import check_config
from dospcot.run.sb3_runs import build_run
from dospcot.run.train import evaluate, train
from dospcot.tasks import load_config

pytest.importorskip("highway_env", reason="the `highway` extra (highway-env) is not installed")

TINY = [
    *PINNED,
    "training.rounds=2",
    "training.steps_per_round=120",
    "dqn.learning_starts=40",
    "dqn.net_arch=[32]",
    "highway.eval_episodes=2",
]
RUN_FILES = [
    "config.toml",
    "metrics.csv",
    "summary.json",
    "learning_curves.png",
    "run_info.json",
    "agent_kinematics.zip",
    "agent_occupancy.zip",
    "classifier_kinematics.pt",
    "classifier_occupancy.pt",
    "reward_classes.json",
    "pseudo_rewards.csv",
]


@pytest.mark.parametrize("env_id", ["highway-fast-v0", "dospcot/FastHighway-v0"])
@pytest.mark.parametrize("view", ["kinematics", "occupancy"])
def test_masked_sensor_envs_pass_gymnasium_and_sb3_env_checkers(env_id, view):
    gym_check_env(make_masked_highway(env_id, view), skip_render_check=True)
    sb3_check_env(make_masked_highway(env_id, view))


@pytest.mark.parametrize(
    ("view", "obs_type"),
    [("kinematics", "Kinematics"), ("occupancy", "OccupancyGrid"), ("ttc", "TimeToCollision")],
)
def test_each_view_is_the_observation_highway_env_returns_for_the_same_state(view, obs_type):
    ours = make_masked_highway("highway-fast-v0", view, (view, "kinematics"), label_fraction=1.0)
    theirs = gym.make("highway-fast-v0", config={"observation": {"type": obs_type}})
    obs, info = ours.reset(seed=3)
    expected, _ = theirs.reset(seed=3)
    np.testing.assert_array_equal(obs, expected)
    np.testing.assert_array_equal(info["views"][view], expected)
    for action in [1, 3, 0, 3, 2, 4, 1, 1]:
        obs, reward, terminated, truncated, info = ours.step(action)
        expected, true_reward, *_ = theirs.step(action)
        np.testing.assert_array_equal(obs, expected)
        assert reward == true_reward == info["hidden_reward"]
        if terminated or truncated:
            break


def test_transition_masking_reveals_about_the_label_fraction_and_keeps_the_truth_aside():
    env = make_masked_highway("dospcot/FastHighway-v0", label_fraction=0.25, mask_seed=1)
    env.reset(seed=0)
    observed = []
    for _ in range(400):
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        observed.append(info["reward_observed"])
        assert reward == (info["hidden_reward"] if info["reward_observed"] else 0.0)
        assert set(info["views"]) == {"kinematics", "occupancy"}
        # The reward's parts go only with a revealed reward: they would give a masked one away.
        assert ("rewards" in info) == info["reward_observed"]
        if terminated or truncated:
            env.reset()
    assert 0.18 < np.mean(observed) < 0.32


def test_quantile_reward_classes_bin_by_label_quantiles_and_round_trip():
    classes = QuantileRewardClasses(4)
    labels = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    classes.fit(labels)
    # Quartile edges of the labels: 0.175, 0.35, 0.525; bin means by hand.
    np.testing.assert_allclose(classes.edges, [0.175, 0.35, 0.525])
    np.testing.assert_allclose(classes.values, [0.05, 0.25, 0.45, 0.65])
    encoded = classes.encode(np.array([0.0, 0.2, 0.35, 0.9, -1.0]))
    np.testing.assert_array_equal(encoded, [0, 1, 2, 3, 0])
    every_class = np.arange(4)
    np.testing.assert_array_equal(classes.encode(classes.decode(every_class)), every_class)
    np.testing.assert_allclose(
        classes.decode(classes.encode(labels)), [0.05] * 2 + [0.25] * 2 + [0.45] * 2 + [0.65] * 2
    )
    # A reward that fills several quantiles merges their bins; unknown classes decode to NaN.
    classes.fit(np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0]))  # quartiles 0, 1, 1
    np.testing.assert_allclose(classes.values[:2], [0.0, 1.0])
    assert not classes.mask[2:].any() and np.isnan(classes.decode(np.array([-1]))[0])


def test_a_rare_reward_keeps_its_own_quantile_class():
    classes = QuantileRewardClasses(4)
    # A sparse goal reward: 0 on 19 steps in 20. Its quartiles are all 0, yet 1 is a class of its own.
    classes.fit(np.array([0.0] * 19 + [1.0]))
    np.testing.assert_allclose(classes.edges, [1.0])
    np.testing.assert_allclose(classes.values[:2], [0.0, 1.0])
    np.testing.assert_array_equal(classes.encode(np.array([0.0, 1.0])), [0, 1])
    # MiniGrid's goal reward, 1 - 0.9 t / T, takes many values: the quartiles at 0 move up to the
    # smallest goal reward (0.4), and the goal rewards share one class, worth their mean.
    classes.fit(np.array([0.0] * 16 + [0.4, 0.6, 0.8, 1.0]))
    np.testing.assert_allclose(classes.edges, [0.4])
    np.testing.assert_allclose(classes.values[:2], [0.0, 0.7])
    # A quantile interpolated between 0 and the smallest goal reward would leave an empty bin.
    classes = QuantileRewardClasses(5)
    classes.fit(np.array([0.0] * 17 + [0.4, 0.5, 0.6, 0.8, 1.0]))  # quintiles 0, 0, 0, 0.32
    np.testing.assert_allclose(classes.edges, [0.4])
    np.testing.assert_allclose(classes.values[:2], [0.0, 0.66])
    assert classes.mask.sum() == 2


def test_a_hidden_reward_between_two_classes_labels_takes_the_nearest_labels_class():
    classes = QuantileRewardClasses(2)
    # Goal labels 0.4-1.0 among zeros: encode's edge is the smallest goal label, 0.4, so a goal reached
    # later than any labelled one (0.3) would read as class 0; the metrics' edge is midway, 0.2.
    labels = np.array([0.0] * 16 + [0.4, 0.6, 0.8, 1.0])
    classes.fit(labels)
    np.testing.assert_allclose(classes.hidden_edges, [0.2])
    hidden = np.array([0.0, 0.15, 0.25, 0.3, 0.4, 0.9])
    np.testing.assert_array_equal(classes.encode(hidden), [0, 0, 0, 0, 1, 1])
    np.testing.assert_array_equal(classes.encode_hidden(hidden), [0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(classes.encode_hidden(labels), classes.encode(labels))
    # Quartiles of 0.0-0.7 in steps of 0.1 (edges 0.175, 0.35, 0.525): midway 0.15, 0.35, 0.55.
    classes = QuantileRewardClasses(4)
    labels = np.arange(8) / 10
    classes.fit(labels)
    np.testing.assert_allclose(classes.hidden_edges, [0.15, 0.35, 0.55])
    np.testing.assert_array_equal(classes.encode_hidden(labels), classes.encode(labels))
    # One labelled value: as encode, any other reward is a value no label has shown.
    classes.fit(np.zeros(5))
    np.testing.assert_array_equal(classes.encode_hidden(np.array([0.0, 0.3])), [0, -1])


def _train(tmp_path, preset: str, *overrides: str):
    args = ["train", preset, "--runs-dir", str(tmp_path), "--no-progress"]
    assert main([*args, *(a for o in (*TINY, *overrides) for a in ("--set", o))]) == 0
    (run_dir,) = (tmp_path / load_config(preset).name).iterdir()
    return run_dir


def _no_new_agents(*args, **kwargs):
    raise AssertionError("an agent was built")


def test_short_cotraining_on_the_fast_env_writes_every_run_file_and_evaluates(tmp_path, monkeypatch):
    run_dir = _train(tmp_path, "fasthighway-dospcot")
    assert sorted(RUN_FILES) == sorted(p.name for p in run_dir.iterdir() if p.is_file())
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["env_steps_per_agent"] == 240 and summary["max_return"] == 30.0
    assert 0 <= summary["mean"]["coverage"] <= 1 and 0 <= summary["mean"]["pseudo_accuracy"] <= 1
    classes = json.loads((run_dir / "reward_classes.json").read_text())["rewards"]
    assert 1 <= len(classes) <= 5 and classes == sorted(classes)
    # Evaluating the saved agents builds the task's evaluator, not a training run with fresh agents.
    monkeypatch.setattr("dospcot.core.sb3_round.make_agent", _no_new_agents)
    evaluation = evaluate(run_dir)
    for view in ("kinematics", "occupancy"):
        assert evaluation["per_view"][view]["greedy_return"] == summary["per_view"][view]["greedy_return"]


def test_an_agent_trained_on_the_fast_env_drives_on_highway_env_through_the_same_view(tmp_path):
    run_dir = _train(tmp_path, "fasthighway-oracle")
    agent = DQN.load(run_dir / "agent_kinematics.zip", device="cpu")
    env = make_masked_highway("highway-fast-v0", "kinematics", label_fraction=1.0)
    assert agent.observation_space == env.observation_space and agent.action_space == env.action_space
    obs, _ = env.reset(seed=0)
    total, steps = 0.0, 0
    for steps in range(1, 31):  # noqa: B007
        action, _ = agent.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total += reward
        if terminated or truncated:
            break
    assert steps >= 1 and 0.0 <= total <= steps


@pytest.fixture(scope="module")
def fast_run():
    """``fasthighway-dospcot`` on ``TINY``, built and run once for the module; the tests only read it (its
    agents are evaluated again, which changes nothing: an evaluation starts its episodes from the seeds)."""
    run = build_run(load_config("fasthighway-dospcot", TINY))
    run.run()
    return run


def test_a_resumed_highway_run_continues_exactly(fast_run):
    cfg = load_config("fasthighway-dospcot", TINY)
    straight = fast_run
    first = build_run(cfg)
    first.run_round()
    state = pickle.loads(pickle.dumps(first.state_dict()))
    resumed = build_run(cfg)
    resumed.load_state_dict(state)
    rows = resumed.run_round()
    expected = straight._records({})  # the same agents, evaluated afresh
    assert [r["greedy_return"] for r in rows] == [r["greedy_return"] for r in expected]
    for a, b in zip(resumed.agents, straight.agents, strict=True):
        for p, q in zip(a.policy.parameters(), b.policy.parameters(), strict=True):
            assert np.array_equal(p.detach().numpy(), q.detach().numpy())


class _ScrambledHiddenReward(gym.Wrapper):
    """Replaces the hidden reward of every masked step (the truth only metrics may read) with 1 - r."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not info["reward_observed"]:
            info = dict(info, hidden_reward=1.0 - info["hidden_reward"])
        return obs, reward, terminated, truncated, info


@pytest.mark.parametrize("monitor", [[], ["highway.reveal_first_steps=5"]])
def test_leakage_scrambling_hidden_rewards_leaves_the_transition_learners_bit_identical(request, monitor):
    cfg = load_config("fasthighway-dospcot", TINY + monitor)
    # SB3 seeds the global generators when an agent is built: build and run one run at a time.
    if monitor:
        plain = build_run(cfg)
        plain.run()
    else:  # the module's run of the same config
        plain = request.getfixturevalue("fast_run")
    make = partial(
        make_masked_highway,
        cfg.highway.env_id,
        config=cfg.highway.config,
        reveal_first_steps=cfg.highway.reveal_first_steps,
    )
    scrambled = CoTrainingRun(
        SensorAdapter(cfg, cfg.highway, lambda *args: _ScrambledHiddenReward(make(*args))), cfg
    )
    scrambled.run()
    n = len(plain.store)
    assert (plain.table.weight[:n][~plain.store.labelled[:n]] > 0).any()  # pseudo-rewards were used
    if monitor:  # the first 5 steps of every episode were revealed besides the share
        assert plain.store.labelled[:n].mean() > cfg.training.label_fraction + 0.05
    assert not np.array_equal(plain.store.hidden_reward[:n], scrambled.store.hidden_reward[:n])
    for a, b in zip(plain.agents, scrambled.agents, strict=True):
        for p, q in zip(a.policy.parameters(), b.policy.parameters(), strict=True):
            assert np.array_equal(p.detach().numpy(), q.detach().numpy())
    assert np.array_equal(plain.table.reward, scrambled.table.reward)
    assert np.array_equal(plain.table.weight, scrambled.table.weight)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("highway.env_id=nope-v0", "highway.env_id: unknown task 'nope-v0'; allowed: highway-fast-v0"),
        (
            "highway.config={vehicle_count=3}",
            "highway.config: highway-fast-v0 has no config key 'vehicle_count'",
        ),
        ('highway.config={observation={type="Kinematics"}}', "'observation' is set by dospcot"),
        (
            'views=["lidar"]',
            "views: the highway-fast-v0 has no view 'lidar'; allowed: kinematics, occupancy, ttc",
        ),
        ("highway.reward_classes=0", "reward_classes and eval_episodes must be >= 1"),
        ("highway.reveal_first_steps=-1", "highway: reveal_first_steps must be >= 0, got -1"),
        (
            'highway.config={vehicles_count="many"}',
            "highway.config: vehicles_count must be a number (highway-env's default is 20), got 'many'",
        ),
        (
            "highway.config={lanes_count=0}",
            "highway.config: highway-fast-v0 cannot run with {'lanes_count': 0}: ValueError: ",
        ),
        ("env.size=8", 'env: a task = "highway" run does not read the [env] section'),
    ],
)
def test_bad_highway_configs_fail_with_one_line(tmp_path, capsys, override, message):
    code = main(["train", "highway-dospcot", "--runs-dir", str(tmp_path), "--set", override])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "highway-dospcot").exists()


def test_fast_env_config_keys_and_views_are_checked():
    with pytest.raises(ConfigError, match=r"highway.config: .*speed_limit"):  # the task's check step
        check_config(load_config("fasthighway-dospcot", ["highway.config={speed_limit=3}"]))
    with pytest.raises(ConfigError, match="no view 'ttc'; allowed: kinematics, occupancy"):
        load_config("fasthighway-dospcot", ['views=["ttc"]'])


@pytest.mark.slow
def test_a_file_raters_queries_on_highway_env_show_the_frames_of_each_step(tmp_path):
    overrides = [
        *TINY,
        'highway.env_id="highway-fast-v0"',
        'training.label_strategy="outcomes"',
        'training.rater="file"',
        "training.label_fraction=0.05",
    ]
    with pytest.raises(QueriesPending) as pending:
        train(load_config("fasthighway-dospcot", overrides), tmp_path, show_progress=False)
    rows = list(csv.DictReader(pending.value.path.open()))
    assert len(rows) == math.ceil(0.05 * 2 * 120)  # the budget: 5% of the two agents' steps met
    for row in rows:
        folder = pending.value.path.parent
        before, after = (np.asarray(Image.open(folder / row[c])) for c in ("frame", "next_frame"))
        assert before.shape == after.shape == (150, 600, 3) and not np.array_equal(before, after)
