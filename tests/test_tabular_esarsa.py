"""TabularExpectedSarsa: the exact tabular update, aliasing views, learning, saving."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor

from dospcot.envs import CLIFF_VIEWS, ViewObservationWrapper
from dospcot.policies import TabularExpectedSarsa

N_STATES = 48


def cliff(view: str = "coords") -> gym.Env:
    return ViewObservationWrapper(gym.make("CliffWalking-v1", max_episode_steps=100), CLIFF_VIEWS[view])


def every_observation(view: str = "coords") -> np.ndarray:
    """(48, d) the view of every CliffWalking state."""
    return np.stack([CLIFF_VIEWS[view].fn(s) for s in range(N_STATES)])


def _agent(**kwargs) -> TabularExpectedSarsa:
    kwargs = {"learning_rate": 0.5, "gamma": 0.9, "learning_starts": 0, "seed": 0, **kwargs}
    return TabularExpectedSarsa("MlpPolicy", cliff(), every_observation(), **kwargs)


def _q(agent: TabularExpectedSarsa, state: int) -> th.Tensor:
    """(A,) the table's values of a CliffWalking state."""
    return agent.q_net(th.as_tensor(every_observation()[[state]]))[0]


@pytest.mark.parametrize(("target", "expected"), [("expected_sarsa", 0.0825), ("q", 0.15)])
def test_one_update_by_hand_with_a_shared_entry_and_a_weight_zero_sample(target, expected):
    agent = _agent(target=target)
    obs = every_observation()
    rows = agent.q_net.features_extractor.rows
    table = agent.q_table.data  # (A, U)
    table[:, rows(th.as_tensor(obs[[24]]))[0]] = th.tensor([1.0, 2.0, 2.0, 0.0])
    table[0, rows(th.as_tensor(obs[[36]]))[0]] = 0.5
    buffer = agent.replay_buffer
    for s, a, s2, r, observed in [(36, 0, 24, -1.0, True), (36, 0, 24, -3.0, True), (24, 1, 25, -1.0, False)]:
        info = {"reward_observed": observed}
        buffer.add(obs[[s]], obs[[s2]], np.array([a]), np.array([r]), np.array([False]), [info])
    buffer.sample = lambda batch_size, env=None: buffer._get_samples(np.arange(3))
    agent.exploration_rate = 0.2
    agent.set_logger(Logger(None, []))
    agent.train(gradient_steps=1, batch_size=3)
    # Expected SARSA at s' = 24, eps .2, ties on actions 1 and 2: .2 * mean(1, 2, 2, 0) + .8 * 2 = 1.85
    # (Q-learning: max = 2). Targets -1 + .9 * 1.85 and -3 + .9 * 1.85; both samples are the entry
    # (36, up), so it moves by alpha times their mean TD error: .5 + .5 * mean(.165, -1.835) = .0825
    # (Q-learning: .5 + .5 * mean(.3, -1.7) = .15).
    assert _q(agent, 36)[0].item() == pytest.approx(expected)
    assert th.equal(_q(agent, 24), th.tensor([1.0, 2.0, 2.0, 0.0]))  # the masked step weighs 0


def test_states_that_look_alike_share_a_row_and_unknown_observations_are_refused():
    patches = every_observation("patch")
    agent = TabularExpectedSarsa("MlpPolicy", cliff("patch"), patches, seed=0)
    n_rows = len(np.unique(patches, axis=0))
    assert agent.q_table.shape == (4, n_rows) and n_rows < N_STATES
    aliased = [s for s in range(N_STATES) if np.array_equal(patches[s], patches[13])]
    assert len(aliased) > 1
    agent.q_table.data.normal_()
    actions = agent.predict(patches[aliased], deterministic=True)[0]
    assert len(set(actions.tolist())) == 1
    with pytest.raises(ValueError, match=r"is not among the \d+ rows of this tabular agent's table"):
        agent.predict(np.full((1, patches.shape[1]), 0.5, dtype=np.float32))


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="needs observations"):
        TabularExpectedSarsa("MlpPolicy", cliff())
    with pytest.raises(ValueError, match=r"learning_rate \(alpha\) must lie in \(0, 1\]"):
        _agent(learning_rate=1.5)
    with pytest.raises(ValueError, match="policy_kwargs cannot be set"):
        _agent(policy_kwargs={"net_arch": [8]})


def test_q_learning_finds_the_cliff_shortest_path_and_the_zip_round_trips(tmp_path):
    agent = _agent(target="q", gamma=1.0, exploration_initial_eps=0.2, exploration_final_eps=0.2)
    agent.learn(6_000)
    returns, _ = evaluate_policy(agent, Monitor(cliff()), n_eval_episodes=1, deterministic=True)
    assert returns == -13.0  # 13 steps along the cliff edge, the optimum
    agent.save(tmp_path / "agent.zip")
    greedy = agent.predict(every_observation(), deterministic=True)[0]
    stock = DQN.load(tmp_path / "agent.zip", device="cpu")  # SB3's own loader
    assert np.array_equal(stock.predict(every_observation(), deterministic=True)[0], greedy)
    loaded = TabularExpectedSarsa.load(tmp_path / "agent.zip", env=cliff())
    assert th.equal(loaded.q_table, agent.q_table)
    loaded.learn(200, reset_num_timesteps=False)  # keeps learning after a load
    assert loaded.num_timesteps == 6_200
