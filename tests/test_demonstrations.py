"""Expert demonstrations: the large-margin loss by hand, the file format, value iteration's episodes,
and the two roles on a grid run (labels that reach only through the file's rewards, and the loss)."""

import json
import pickle
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN
from test_neural_cotraining import (  # the small grid of the co-training tests
    LABEL_FRACTION,
    LAYOUT,
    VIEWS,
    config,
    grid,
)

from dospcot.config.errors import ConfigError
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.demonstrations import Demonstrations, expert_demonstrations
from dospcot.envs import GridWorld, StateActionMask, View, ViewObservationWrapper
from dospcot.envs.masked_highway import FAST_HIGHWAY_ID, make_masked_highway
from dospcot.envs.masking import RewardMaskWrapper
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.esarsa_dqn import large_margin_loss
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config


def test_the_large_margin_loss_by_hand():
    q = th.tensor([[1.0, 2.0, 0.5], [3.0, 1.0, 2.0]])
    # Row 1, expert action 0: max(1 + 0, 2 + 0.8, 0.5 + 0.8) - 1 = 1.8. Row 2, expert action 0:
    # max(3, 1.8, 2.8) - 3 = 0: the expert's action already leads by the margin.
    assert large_margin_loss(q, th.tensor([0, 0]), 0.8).item() == pytest.approx(0.9)
    # Expert action 1 in row 1: max(1.8, 2, 1.3) - 2 = 0.
    assert large_margin_loss(q[:1], th.tensor([1]), 0.8).item() == pytest.approx(0.0)
    # A margin of 0 is the plain gap to the best action.
    assert large_margin_loss(q[:1], th.tensor([2]), 0.0).item() == pytest.approx(1.5)


def _demos(rewards: bool = True) -> Demonstrations:
    rng = np.random.default_rng(0)
    obs = {"a": rng.normal(size=(5, 3)).astype(np.float32), "b": rng.normal(size=(5, 2)).astype(np.float32)}
    nxt = {name: value + 1 for name, value in obs.items()}
    return Demonstrations(
        obs,
        nxt,
        np.array([0, 1, 2, 1, 0]),
        np.array([0, 0, 0, 1, 1]),
        np.array([0.0, 0.0, 1.0, 0.0, 1.0]) if rewards else None,
        np.array([4, 5, 6, 4, 5]),
    )


@pytest.mark.parametrize("rewards", [True, False])
def test_a_demonstrations_file_round_trips(tmp_path, rewards):
    demos = _demos(rewards)
    demos.save(tmp_path / "demos.npz")
    loaded = Demonstrations.load(tmp_path / "demos.npz")
    assert loaded.views == ("a", "b") and loaded.n_episodes == 2 and len(loaded) == 5
    for name in demos.views:
        np.testing.assert_array_equal(loaded.observations[name], demos.observations[name])
        np.testing.assert_array_equal(loaded.next_observations[name], demos.next_observations[name])
    np.testing.assert_array_equal(loaded.actions, demos.actions)
    np.testing.assert_array_equal(loaded.episode, demos.episode)
    np.testing.assert_array_equal(loaded.states, demos.states)
    if rewards:
        np.testing.assert_array_equal(loaded.rewards, demos.rewards)
    else:
        assert loaded.rewards is None
    first = loaded.first_episodes(1)
    assert len(first) == 3 and first.n_episodes == 1 and first.observations["a"].shape == (3, 3)


def test_bad_demonstrations_files_fail_with_one_line(tmp_path):
    np.savez(tmp_path / "no_actions.npz", episode=np.zeros(2))
    with pytest.raises(ValueError, match="has no actions"):
        Demonstrations.load(tmp_path / "no_actions.npz")
    np.save(tmp_path / "one.npy", np.zeros(3))
    with pytest.raises(ValueError, match=r"holds one array, not a \.npz"):
        Demonstrations.load(tmp_path / "one.npy")
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(ValueError, match="cannot read"):
        Demonstrations.load(tmp_path / "text.npz")
    demos = _demos()
    with pytest.raises(ValueError, match=r"episode must count 0, 1, \.\.\."):
        Demonstrations(demos.observations, demos.next_observations, demos.actions, np.array([0, 2, 2, 2, 2]))
    with pytest.raises(ValueError, match="view 'a' must be"):
        Demonstrations({"a": np.zeros((4, 3))}, {"a": np.zeros((4, 3))}, demos.actions, demos.episode)
    with pytest.raises(ValueError, match="rewards must be"):
        Demonstrations(demos.observations, demos.next_observations, demos.actions, demos.episode, np.zeros(4))


def test_expert_episodes_follow_the_optimal_policy_first_from_the_start():
    run = grid(config())
    mdp, optimum = run.task.mdp, run.task.policy_metrics.optimal_return
    demos = expert_demonstrations(mdp, 4, seed=3)
    assert demos.n_episodes == 4 and demos.views == ("coords",)
    first = demos.episode == 0
    assert demos.states[first][0] == mdp.start_state
    assert demos.rewards[first].sum() == pytest.approx(optimum)  # the expert's return is the optimum
    for k in range(4):  # every episode ends with the goal: a terminal transition
        last = np.flatnonzero(demos.episode == k)[-1]
        assert mdp.terminal[demos.states[last], demos.actions[last]]
    # Consecutive steps chain through the task's transitions; the views are of s and s'.
    inner = np.flatnonzero(demos.episode[1:] == demos.episode[:-1])
    np.testing.assert_array_equal(
        mdp.next_state[demos.states[inner], demos.actions[inner]], demos.states[inner + 1]
    )
    np.testing.assert_array_equal(demos.observations["coords"], mdp.views["coords"][demos.states])
    assert expert_demonstrations(mdp, 4, seed=3, with_rewards=False).rewards is None
    again = expert_demonstrations(mdp, 4, seed=3)
    np.testing.assert_array_equal(again.states, demos.states)  # seeded


def _run(labels: bool, weight: float = 1.0, seed: int = 0) -> CoTrainingRun:
    demonstrations = {"episodes": 3, "labels": labels, "margin_loss_weight": weight}
    return grid(
        config("dospcot", ("esarsa_dqn", "dqn"), ("coords", "patch"), seed, demonstrations=demonstrations)
    )


def test_demonstrated_rewards_are_labels_for_the_classifiers_and_the_agents_own_steps():
    run = _run(labels=True)
    demos, store, mdp = run.task.demos, run.store, run.task.mdp
    keys = demos.states * mdp.n_actions + demos.actions
    drawn = StateActionMask(mdp.n_states, mdp.n_actions, LABEL_FRACTION, 0).labelled.ravel()
    # Before any step, the pool holds exactly the demonstrated keys as labelled, with their rewards.
    assert set(np.flatnonzero(store.labelled)) == set(keys.tolist())
    np.testing.assert_array_equal(store.label_value[keys], mdp.reward[demos.states, demos.actions])
    # Each demonstrated key into the goal ended its episode, as an agent's step there does (the goal
    # class kept to episode ends reads it: env.episode_end_classes).
    np.testing.assert_array_equal(store.terminated[keys], mdp.terminal[demos.states, demos.actions])
    assert store.terminated[keys].sum() >= 1 and not store.truncated.any()
    # The agents' mask reveals the drawn keys and the demonstrated ones, and no other.
    mask = run.agents[0].get_env().envs[0].get_wrapper_attr("mask")
    assert set(np.flatnonzero(mask.labelled.ravel())) == set(np.flatnonzero(drawn)) | set(keys.tolist())
    assert all(agent.n_demonstrations == len(demos) for agent in run.agents)


def test_without_labels_no_demonstrated_reward_reaches_a_learner():
    run = _run(labels=False)
    mdp = run.task.mdp
    assert run.task.demos.rewards is None and run.task.revealed_keys is None
    assert not run.store.visited.any() and not run.store.labelled.any()
    mask = run.agents[0].get_env().envs[0].get_wrapper_attr("mask")
    drawn = StateActionMask(mdp.n_states, mdp.n_actions, LABEL_FRACTION, 0).labelled
    np.testing.assert_array_equal(mask.labelled, drawn)
    assert all(agent.n_demonstrations == len(run.task.demos) for agent in run.agents)  # the loss only
    assert all(agent.n_demonstrations == 0 for agent in _run(labels=False, weight=0.0).agents)


def test_a_run_with_demonstrations_resumes_bit_identically():
    full = _run(labels=True, seed=1)
    records = full.run()
    first = _run(labels=True, seed=1)
    first.run_round()
    state = pickle.dumps(first.state_dict())  # before another run is built: that re-seeds the globals
    resumed = _run(labels=True, seed=1)
    resumed.load_state_dict(pickle.loads(state))
    assert all(agent.n_demonstrations > 0 for agent in resumed.agents)  # a loaded agent gets them again
    assert json.dumps(resumed.run_round()) == json.dumps(records[2:])


def test_the_margin_loss_alone_teaches_the_demonstrated_actions():
    # One input per cell, so any policy can be represented; 1% of the rewards revealed and the rest
    # weighing 0, so the TD loss says almost nothing and the demonstrated policy is arbitrary.
    n = LAYOUT.size**2
    cells = np.eye(n, dtype=np.float32)
    onehot = View("onehot", gym.spaces.Box(0.0, 1.0, (n,), np.float32), lambda s: cells[s])
    env = ViewObservationWrapper(RewardMaskWrapper(GridWorld(LAYOUT), 0.01), onehot)
    agent = ExpectedSarsaDQN(
        "MlpPolicy", env, learning_starts=100, seed=0, policy_kwargs={"net_arch": [32]}, demo_loss_weight=5.0
    )
    agent.learn(200)
    wanted = np.arange(n) % 4
    agent.set_demonstrations(cells, wanted)
    agent.update(1500)
    assert (agent.predict(cells, deterministic=True)[0] == wanted).all()


def _coords_env() -> gym.Env:
    return ViewObservationWrapper(RewardMaskWrapper(GridWorld(LAYOUT), 1.0), VIEWS["coords"])


def test_a_saved_agent_holds_no_demonstrations_and_plain_dqn_loads_it(tmp_path):
    agent = ExpectedSarsaDQN("MlpPolicy", _coords_env(), learning_starts=10, seed=0, demo_margin=0.5)
    agent.set_demonstrations(np.zeros((3, VIEWS["coords"].space.shape[0]), np.float32), np.array([0, 1, 2]))
    agent.learn(20)
    agent.save(tmp_path / "agent.zip")
    loaded = ExpectedSarsaDQN.load(tmp_path / "agent.zip")
    assert loaded.n_demonstrations == 0 and loaded.demo_margin == 0.5
    script = textwrap.dedent(f"""
        import sys
        from stable_baselines3 import DQN
        DQN.load({str(tmp_path / "agent.zip")!r})
        assert not any(m.startswith("dospcot") for m in sys.modules), "dospcot was imported"
    """)
    subprocess.run([sys.executable, "-c", script], check=True)


def test_bad_demonstrations_settings_fail_with_one_line():
    agent = ExpectedSarsaDQN("MlpPolicy", _coords_env(), seed=0)
    with pytest.raises(ValueError, match=r"observations \(N, 4\) and actions \(N,\)"):
        agent.set_demonstrations(np.zeros((3, 5)), np.zeros(3, int))
    with pytest.raises(ValueError, match=r"actions must lie in \[0, 4\), got 0 to 7"):
        agent.set_demonstrations(np.zeros((2, 4)), np.array([0, 7]))
    with pytest.raises(ValueError, match="demo_margin and demo_loss_weight must be >= 0"):
        ExpectedSarsaDQN("MlpPolicy", _coords_env(), demo_margin=-1.0)
    with pytest.raises(ConfigError, match="demonstrations: episodes must be >= 0, got -1"):
        load_config("grid16-dospcot", ["demonstrations.episodes=-1"])
    with pytest.raises(
        ConfigError, match=r'a task = "highway" run\'s demonstrations come from a file or a saved agent'
    ):
        load_config("fasthighway-dospcot", ["demonstrations.episodes=3"])
    with pytest.raises(ConfigError, match="tabular agents have no large-margin loss; set it to 0"):
        load_config("grid16-dospcot", ["demonstrations.episodes=3", "agent=tabular"])
    cfg = load_config(
        "grid16-dospcot",
        ["demonstrations.episodes=3", "agent=tabular", "demonstrations.margin_loss_weight=0"],
    )
    assert cfg.demonstrations.episodes == 3


def test_on_highway_a_saved_agent_demonstrates_in_every_view_of_the_run(tmp_path):
    env = make_masked_highway(FAST_HIGHWAY_ID, "kinematics", ("kinematics",), 1.0, 0)
    DQN("MlpPolicy", env, seed=0).save(tmp_path / "expert.zip")
    settings = [
        f"demonstrations.agent={str(tmp_path / 'expert.zip')!r}",
        "demonstrations.episodes=2",
        "training.steps_per_round=50",
    ]
    run = build_run(load_config("fasthighway-dospcot", settings))
    demos = run.task.demos
    assert demos.n_episodes == 2 and set(demos.views) == {"kinematics", "occupancy"}
    assert len(demos) <= 2 * run.cfg.highway.episode_steps
    # Within an episode each step starts where the last one ended, in every view.
    same_episode = demos.episode[1:] == demos.episode[:-1]
    for view in demos.views:
        np.testing.assert_array_equal(
            demos.observations[view][1:][same_episode], demos.next_observations[view][:-1][same_episode]
        )
    assert np.all((demos.rewards >= 0) & (demos.rewards <= 1))  # highway's normalised reward
    assert all(agent.n_demonstrations == len(demos) for agent in run.agents)
    labelled = run.store.labelled[: len(run.store)]
    assert labelled.sum() == len(demos)  # before any training step, the pool holds the demonstrations
