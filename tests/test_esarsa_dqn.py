"""ExpectedSarsaDQN: target, weighted loss, relabelling buffer, exploration, saving, learning."""

import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.evaluation import evaluate_policy

from dospcot.classifier import BatchedRewardClassifier, ClassifierConfig, load_classifier, save_classifier
from dospcot.envs import CLIFF_VIEWS, ViewObservationWrapper
from dospcot.policies import ExpectedSarsaDQN, RelabellingReplayBuffer, RewardTable
from dospcot.policies.esarsa_dqn import epsilon_greedy_expectation, weighted_huber_loss


def onehot_cliff(max_steps: int = 100) -> gym.Env:
    return ViewObservationWrapper(
        gym.make("CliffWalking-v1", max_episode_steps=max_steps), CLIFF_VIEWS["onehot"]
    )


def test_target_by_hand_on_three_actions_with_ties():
    online = th.tensor([[1.0, 2.0, 2.0]])
    target = th.tensor([[0.5, 1.0, 3.0]])
    # eps .3: every action .1, the greedy .7 split over the tied actions 1 and 2.
    expected = 0.1 * 0.5 + 0.45 * 1.0 + 0.45 * 3.0
    assert epsilon_greedy_expectation(online, target, 0.3).item() == pytest.approx(expected)


def test_target_at_eps_0_is_sb3_max_and_at_eps_1_the_mean():
    model = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), seed=0, learning_starts=0)
    obs = th.eye(48)
    online, target = model.q_net(obs), model.q_net_target(obs)  # a fresh target net equals the online net
    assert th.equal(epsilon_greedy_expectation(online, target, 0.0), target.max(dim=1).values)
    assert th.allclose(epsilon_greedy_expectation(online, target, 1.0), target.mean(dim=1))


def test_q_target_training_matches_stock_dqn():
    kwargs = dict(
        learning_starts=50,
        train_freq=1,
        target_update_interval=1,
        seed=3,
        buffer_size=1000,
        exploration_initial_eps=0.0,
        exploration_final_eps=0.0,
        batch_size=16,
    )
    ours = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), **kwargs)
    ours.learn(300)
    stock = DQN("MlpPolicy", onehot_cliff(), **kwargs)
    stock.learn(300)
    for p, q in zip(ours.policy.parameters(), stock.policy.parameters(), strict=True):
        assert th.allclose(p, q, atol=1e-6)


def test_weighted_huber_loss_by_hand_and_zero_weight_gradient():
    current = th.tensor([[1.0], [2.0], [3.0]], requires_grad=True)
    target = th.tensor([[1.5], [0.0], [3.2]])
    weights = th.tensor([[1.0], [0.0], [0.5]])
    loss = weighted_huber_loss(current, target, weights)
    # Huber: .5 * .5^2 = .125; |2| -> 2 - .5 = 1.5; .5 * .2^2 = .02. Weighted mean: (.125 + .5 * .02) / 1.5.
    assert loss.item() == pytest.approx((0.125 + 0.5 * 0.02) / 1.5)
    loss.backward()
    assert current.grad[1].item() == 0.0 and current.grad[0].item() != 0.0


def _buffer(table=None, masked_reward="ignore"):
    return RelabellingReplayBuffer(
        10,
        gym.spaces.Box(0, 1, (2,)),
        gym.spaces.Discrete(3),
        device="cpu",
        reward_table=table,
        masked_reward=masked_reward,
    )


def _add(buffer, reward, observed, store_id):
    buffer.add(
        np.zeros(2),
        np.ones(2),
        np.array([1]),
        np.array([reward]),
        np.array([False]),
        [{"reward_observed": observed, "store_id": store_id}],
    )


def test_buffer_relabels_after_the_table_changes():
    table = RewardTable()
    buffer = _buffer(table)
    _add(buffer, -1.0, True, 0)
    _add(buffer, 0.0, False, 1)
    _add(buffer, 0.0, False, 2)
    idx, env = np.arange(3), np.zeros(3, int)
    reward, weight = buffer.relabel(idx, env)
    assert reward.tolist() == [-1.0, 0.0, 0.0] and weight.tolist() == [1.0, 0.0, 0.0]
    table.set(np.array([1, 2]), np.array([-100.0, -1.0]), np.array([1.0, 0.5]))
    reward, weight = buffer.relabel(idx, env)
    assert reward.tolist() == [-1.0, -100.0, -1.0] and weight.tolist() == [1.0, 1.0, 0.5]
    table.set(np.array([1]), np.array([-1.0]), np.array([0.0]))
    assert buffer.relabel(idx, env)[1].tolist() == [1.0, 0.0, 0.5]
    samples = buffer.sample(8)
    assert samples.weights.shape == (8, 1)
    assert _buffer(masked_reward="zero").masked_reward == "zero"


def test_masked_zero_buffer_counts_masked_rewards_as_zero():
    buffer = _buffer(masked_reward="zero")
    _add(buffer, 0.0, False, -1)
    assert buffer.relabel(np.array([0]), np.array([0]))[1].tolist() == [1.0]


def test_exploration_follows_the_pace_and_continues_across_learn_calls():
    kw = dict(
        exploration_initial_eps=1.0,
        exploration_final_eps=0.0,
        exploration_fraction=1.0,
        exploration_horizon=400,
        learning_starts=1000,
        seed=0,
    )
    split = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), **kw)
    split.learn(200)
    split.learn(100, reset_num_timesteps=False)
    whole = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), **kw)
    whole.learn(300)
    assert split.exploration_rate == pytest.approx(whole.exploration_rate) == pytest.approx(0.25, abs=0.01)
    split.set_pace(0.5)
    assert split.exploration_rate == pytest.approx(0.5)
    split.learn(10, reset_num_timesteps=False)
    assert split.exploration_rate == pytest.approx(0.5)


def test_bad_input_raises_clear_errors():
    with pytest.raises(ValueError, match="Discrete action space"):
        ExpectedSarsaDQN("MlpPolicy", gym.make("Pendulum-v1"))
    with pytest.raises(ValueError, match="exploration_final_eps must lie in"):
        ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), exploration_final_eps=1.5)
    with pytest.raises(ValueError, match="target must be one of"):
        ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), target="double")
    model = ExpectedSarsaDQN("MlpPolicy", onehot_cliff())
    with pytest.raises(ValueError, match="pace must lie in"):
        model.set_pace(-0.1)
    with pytest.raises(ValueError, match=r"weight must lie in \[0, 1\], got 1.2"):
        RewardTable().set(np.array([0]), np.array([1.0]), np.array([1.2]))
    with pytest.raises(ValueError, match="reward must be finite, got nan"):
        RewardTable().set(np.array([0]), np.array([np.nan]), np.array([1.0]))
    with pytest.raises(ValueError, match="reward must be finite"):
        _add(_buffer(), np.nan, True, 0)


def test_save_load_round_trip_keeps_parameters_pace_and_eps(tmp_path):
    model = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), learning_starts=10, seed=1)
    model.learn(50)
    model.set_pace(0.3)
    model.save(tmp_path / "agent.zip")
    loaded = ExpectedSarsaDQN.load(tmp_path / "agent.zip", env=onehot_cliff())
    assert loaded.pace == 0.3 and loaded.exploration_rate == model.exploration_rate
    assert loaded.target == "expected_sarsa" and loaded.replay_buffer_class is RelabellingReplayBuffer
    for p, q in zip(model.policy.parameters(), loaded.policy.parameters(), strict=True):
        assert th.equal(p, q)
    loaded.learn(20)  # it can go on training


def test_plain_dqn_loads_the_zip_in_a_process_without_dospcot(tmp_path):
    model = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), learning_starts=10, seed=2)
    model.learn(100)
    model.save(tmp_path / "agent.zip")
    obs = np.eye(48, dtype=np.float32)
    ours = model.predict(obs, deterministic=True)[0]
    np.save(tmp_path / "obs.npy", obs)
    script = textwrap.dedent(f"""
        import sys
        import numpy as np
        from stable_baselines3 import DQN
        model = DQN.load({str(tmp_path / "agent.zip")!r})
        assert not any(m.startswith("dospcot") for m in sys.modules), "dospcot was imported"
        actions = model.predict(np.load({str(tmp_path / "obs.npy")!r}), deterministic=True)[0]
        print(",".join(map(str, actions)))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ",".join(map(str, ours))


def test_reward_classifier_files_round_trip_with_weights_only(tmp_path):
    clf = BatchedRewardClassifier(2, 5, 3, ClassifierConfig(hidden=8), seeds=[1, 2])
    save_classifier(clf, tmp_path / "g.pt")
    loaded = load_classifier(tmp_path / "g.pt")
    x = th.randn(2, 4, 5, dtype=th.float64)
    mask = th.ones(2, 3, dtype=th.bool)
    assert th.equal(clf(x, mask), loaded(x, mask))


def test_learns_cliffwalking_to_the_optimal_return():
    # A linear Q-network on one-hot states, full rewards, 20k steps: the cliff-edge optimum, -13.
    model = ExpectedSarsaDQN(
        "MlpPolicy",
        onehot_cliff(),
        learning_rate=1e-2,
        buffer_size=50_000,
        learning_starts=1000,
        batch_size=64,
        gamma=0.99,
        train_freq=1,
        target_update_interval=100,
        exploration_initial_eps=1.0,
        exploration_final_eps=0.0,
        exploration_fraction=0.3,
        policy_kwargs={"net_arch": []},
        seed=0,
    )
    model.learn(20_000)
    mean_return, _ = evaluate_policy(model, onehot_cliff(), n_eval_episodes=1, deterministic=True, warn=False)
    assert mean_return == -13.0
