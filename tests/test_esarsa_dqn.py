"""ExpectedSarsaDQN: target, weighted loss, relabelling buffer, exploration, saving, learning."""

import pickle
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.evaluation import evaluate_policy

from dospcot.core.classifier import (
    BatchedRewardClassifier,
    ClassifierConfig,
    load_classifier,
    save_classifier,
)
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


@pytest.mark.parametrize("max_grad_norm", [10.0, 1e-3])  # the norm within the bound, and clipped
def test_gradients_are_clipped_bit_for_bit_as_clip_grad_norm_does(monkeypatch, max_grad_norm):
    kwargs = dict(learning_starts=50, train_freq=1, seed=3, buffer_size=1000, batch_size=16)
    ours = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), max_grad_norm=max_grad_norm, **kwargs)
    ours.learn(200)
    stock = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), max_grad_norm=max_grad_norm, **kwargs)
    monkeypatch.setattr(
        stock,
        "_clip_gradients",
        lambda: th.nn.utils.clip_grad_norm_(stock.policy.parameters(), stock.max_grad_norm),
    )
    stock.learn(200)
    for p, q in zip(ours.policy.parameters(), stock.policy.parameters(), strict=True):
        assert th.equal(p, q)


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


def test_a_pickled_buffer_keeps_its_written_rows_and_rebuilds_the_rest_bit_for_bit():
    table = RewardTable()
    buffer = RelabellingReplayBuffer(
        1000, gym.spaces.Box(0, 1, (2,)), gym.spaces.Discrete(3), device="cpu", reward_table=table
    )
    for step in range(3):
        _add(buffer, -1.0, step != 1, step)
    buffer.observations[2, 0, 1] = -0.0  # a written row; -0.0 == 0.0 by value, not by bit
    assert len(pickle.dumps(buffer)) < 0.05 * len(pickle.dumps(dict(vars(buffer))))  # 3 rows of 1000

    def same(a: RelabellingReplayBuffer, b: RelabellingReplayBuffer) -> None:
        arrays = [name for name, value in vars(a).items() if isinstance(value, np.ndarray)]
        assert len(arrays) >= 8 and not hasattr(b, "_unwritten_rows")
        for name in arrays:
            assert getattr(b, name).tobytes() == getattr(a, name).tobytes(), name

    copy = pickle.loads(pickle.dumps(buffer))
    same(buffer, copy)
    assert np.signbit(copy.observations[2, 0, 1]) and copy.store_ids[3:].tolist() == [[-1]] * 997
    # It goes on as the original does, and relabels as it does (its table is a copy, as pickled alone).
    for b in (buffer, copy):
        _add(b, -2.0, False, 3)
        b.reward_table.set(np.array([1, 3]), np.array([-5.0, -7.0]), np.array([1.0, 0.5]))
    same(buffer, copy)
    idx, env = np.arange(4), np.zeros(4, int)
    assert [a.tolist() for a in copy.relabel(idx, env)] == [a.tolist() for a in buffer.relabel(idx, env)]
    # A full buffer pickles whole.
    for step in range(996):
        _add(buffer, -1.0, True, step)
    assert buffer.full and "_unwritten_rows" not in buffer.__getstate__()


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


@pytest.mark.slow
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


def _linear_agent(**kwargs) -> ExpectedSarsaDQN:
    """An agent whose Q-network is one linear layer over CliffWalking's one-hot states, so Q(s, a) is
    the weight ``W[a, s]`` (biases zeroed)."""
    model = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), policy_kwargs={"net_arch": []}, seed=0, **kwargs)
    with th.no_grad():
        for net in (model.q_net, model.q_net_target):
            net.q_net[0].weight.zero_()
            net.q_net[0].bias.zero_()
        model.q_net.q_net[0].weight[:, 1] = th.tensor([1.0, 2.0, 2.0, 0.0])  # online: tied greedy 1, 2
        model.q_net_target.q_net[0].weight[:, 1] = th.tensor([0.5, 1.0, 3.0, -1.0])  # target: greedy 2
        model.q_net.q_net[0].weight[:, 0] = th.tensor([4.0, 5.0, 6.0, 7.0])
    model.exploration_rate = 0.2
    return model


@pytest.mark.parametrize(
    ("greedy", "expected"),
    [
        # eps .2: every action .05 of target's values (sum 3.5); the greedy .8 on argmax.
        ("online", 0.05 * 3.5 + 0.4 * 1.0 + 0.4 * 3.0),  # online ties 1 and 2 split the .8
        ("target", 0.05 * 3.5 + 0.8 * 3.0),  # the target net's own greedy action 2
    ],
)
def test_speed_path_target_by_hand(greedy, expected):
    model = _linear_agent(greedy=greedy)
    s, s_next = th.eye(48)[[0]], th.eye(48)[[1]]
    current, next_value = model._current_and_next_value(s, s_next)
    assert next_value.item() == pytest.approx(expected)
    assert current.tolist() == [[4.0, 5.0, 6.0, 7.0]] and current.requires_grad
    assert not next_value.requires_grad
    with pytest.raises(ValueError, match="greedy must be one of"):
        ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), greedy="double")


def _window_buffer(table=None, n_steps=3, gamma=0.5, size=10):
    return RelabellingReplayBuffer(
        size,
        gym.spaces.Box(-100, 100, (2,)),
        gym.spaces.Discrete(3),
        device="cpu",
        reward_table=table,
        n_steps=n_steps,
        gamma=gamma,
    )


def _add_step(buffer, k, reward, observed=True, done=False, truncated=False, explored=False):
    """Step k: obs (k, 0) -> next obs (k + 1, 0), store id k."""
    info = {"reward_observed": observed, "store_id": k, "TimeLimit.truncated": truncated}
    info["explored"] = explored
    buffer.add(
        np.array([[k, 0.0]]),
        np.array([[k + 1, 0.0]]),
        np.array([1]),
        np.array([reward]),
        np.array([done]),
        [info],
    )


def _windows(buffer, indices):
    samples = buffer._get_samples(np.array(indices))
    return {
        name: getattr(samples, name).flatten().tolist()
        for name in ("rewards", "discounts", "dones", "weights")
    } | {"next": samples.next_observations[:, 0].tolist()}


def test_n_step_windows_relabelled_by_hand():
    table = RewardTable()
    buffer = _window_buffer(table)
    _add_step(buffer, 0, -1.0)
    _add_step(buffer, 1, -2.0)
    _add_step(buffer, 2, 0.0, observed=False)  # unlabelled: weight 0 until the table labels it
    _add_step(buffer, 3, -4.0, done=True)  # the episode ends here
    _add_step(buffer, 4, -8.0, done=True, truncated=True)  # cut by a time limit: bootstraps
    _add_step(buffer, 5, -16.0)
    _add_step(buffer, 6, -32.0)  # the newest step: no successor stored yet
    got = _windows(buffer, [0, 1, 2, 3, 4, 5, 6])
    # From 0: steps 0, 1, cut before the weight-0 step 2, bootstrapping from its state (2). From 2:
    # steps 2, 3 (weight 0: it drives nothing). From 3: the terminal step alone. From 4: the
    # truncated step alone, not done. From 5: 5 and the newest, 6.
    assert got["rewards"] == [-1 + 0.5 * -2, -2.0, 0.5 * -4, -4.0, -8.0, -16 + 0.5 * -32, -32.0]
    assert got["discounts"] == [0.25, 0.5, 0.25, 0.5, 0.5, 0.25, 0.5]
    assert got["next"] == [2.0, 2.0, 4.0, 4.0, 5.0, 7.0, 7.0]
    assert got["dones"] == [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]
    assert got["weights"] == [1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0]
    # The co-trainer labels step 2 (reward -3, weight .5): the windows through it grow, weighing .5.
    table.set(np.array([2]), np.array([-3.0]), np.array([0.5]))
    got = _windows(buffer, [0, 1, 2])
    assert got["rewards"] == [-1 + 0.5 * -2 + 0.25 * -3, -2 + 0.5 * -3 + 0.25 * -4, -3 + 0.5 * -4]
    assert got["discounts"] == [0.125, 0.125, 0.25]
    assert got["next"] == [3.0, 4.0, 4.0]
    assert got["dones"] == [0.0, 1.0, 1.0]
    assert got["weights"] == [0.5, 0.5, 0.5]


def test_n_step_windows_end_before_an_exploratory_action():
    buffer = _window_buffer()
    _add_step(buffer, 0, -1.0)
    _add_step(buffer, 1, -2.0, explored=True)  # a random action: the greedy policy would not take it
    _add_step(buffer, 2, -4.0)
    _add_step(buffer, 3, -8.0)
    got = _windows(buffer, [0, 1])
    # From 0: step 0 alone, bootstrapping from the state where the random action was taken (1). From
    # 1: the exploratory action is the window's own first action, so 1, 2, 3 as usual.
    assert got["rewards"] == [-1.0, -2 + 0.5 * -4 + 0.25 * -8]
    assert got["discounts"] == [0.5, 0.125]
    assert got["next"] == [1.0, 4.0]


@pytest.mark.parametrize(
    ("target", "cut", "n_steps", "records"),
    [
        ("q", True, 3, True),
        ("q", False, 3, False),
        ("q", True, 1, False),
        ("expected_sarsa", True, 3, False),
    ],
)
def test_the_agent_flags_its_exploratory_actions_where_windows_are_cut(target, cut, n_steps, records):
    # learning_starts beyond the run: every action is a warm-up draw and the network never changes.
    model = ExpectedSarsaDQN(
        "MlpPolicy",
        onehot_cliff(),
        target=target,
        cut_windows=cut,
        n_steps=n_steps,
        learning_starts=1000,
        seed=0,
    )
    model.learn(200)
    buffer = model.replay_buffer
    flags = buffer.explored[:200, 0]
    if not records:
        assert not flags.any()
        return
    greedy = model.q_net(th.as_tensor(buffer.observations[:200, 0])).argmax(dim=1).numpy()
    assert np.array_equal(flags, buffer.actions[:200, 0, 0] != greedy)
    assert 0.6 < flags.mean() < 0.9  # 3 in 4 uniform draws differ from the greedy action


def test_flagging_agents_act_as_dqn_predict_does():
    # Past learning_starts with no gradient step, the network stays put: an agent that flags its
    # exploration (and reuses that forward pass to act) must draw the very actions DQN.predict draws.
    def actions(cut: bool) -> np.ndarray:
        model = ExpectedSarsaDQN(
            "MlpPolicy",
            onehot_cliff(),
            target="q",
            cut_windows=cut,
            n_steps=3,
            learning_starts=10,
            gradient_steps=0,
            exploration_initial_eps=0.5,
            exploration_final_eps=0.5,
            seed=3,
        )
        model.learn(300)
        flags = model.replay_buffer.explored[:300, 0]
        greedy = model.q_net(th.as_tensor(model.replay_buffer.observations[:300, 0])).argmax(dim=1).numpy()
        taken = model.replay_buffer.actions[:300, 0, 0]
        if cut:
            assert np.array_equal(flags, taken != greedy)
        return taken

    taken = actions(cut=True)
    assert np.array_equal(taken, actions(cut=False))
    # Both act from their own forward pass, not through policy.predict: stock DQN draws the same.
    stock = DQN(
        "MlpPolicy",
        onehot_cliff(),
        n_steps=3,
        learning_starts=10,
        gradient_steps=0,
        exploration_initial_eps=0.5,
        exploration_final_eps=0.5,
        seed=3,
    )
    stock.learn(300)
    assert np.array_equal(taken, stock.replay_buffer.actions[:300, 0, 0])
    assert 0.2 < (taken[10:] != taken[9:-1]).mean()  # not one action repeated: both explore


def test_n_step_windows_stop_at_the_oldest_step_of_a_full_buffer():
    buffer = _window_buffer(size=4)
    for k in range(6):  # positions 0, 1 now hold steps 4, 5; position 2 the oldest step, 2
        _add_step(buffer, k, -float(k))
    got = _windows(buffer, [3, 0, 1])
    # From step 3 (position 3): 3, 4, 5, not on into the overwritten position 2. From 5: the newest.
    assert got["rewards"] == [-3 + 0.5 * -4 + 0.25 * -5, -4 + 0.5 * -5, -5.0]
    assert got["next"] == [6.0, 6.0, 6.0]


def test_n_steps_reach_the_buffer_and_plain_dqn_reads_the_zip(tmp_path, recwarn):
    model = ExpectedSarsaDQN("MlpPolicy", onehot_cliff(), n_steps=3, gamma=0.9, learning_starts=10, seed=0)
    assert (model.n_steps, model.replay_buffer.n_steps, model.replay_buffer.gamma) == (3, 3, 0.9)
    assert not [w for w in recwarn if "n_steps" in str(w.message)]  # SB3 would warn it ignores them
    model.learn(60)
    model.save(tmp_path / "agent.zip")
    assert ExpectedSarsaDQN.load(tmp_path / "agent.zip").replay_buffer.n_steps == 3
    assert DQN.load(tmp_path / "agent.zip").n_steps == 3
    with pytest.raises(ValueError, match="n_steps must be a positive integer"):
        _window_buffer(n_steps=0)
