"""The batched engine's door to SB3's internals (:mod:`dospcot.core.sb3_engine`): every private
attribute it reads or writes exists on the installed SB3, and a step booked through it is the step
SB3's own ``learn()`` books."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import stable_baselines3
from stable_baselines3 import DQN
from stable_baselines3.common.buffers import ReplayBuffer

from dospcot.core import sb3_engine


@pytest.fixture(scope="module")
def agent() -> DQN:
    model = DQN(
        "MlpPolicy", gym.make("CartPole-v1"), learning_starts=0, buffer_size=100, seed=0, device="cpu"
    )
    model.learn(8)
    return model


@pytest.mark.parametrize(
    ("owner", "name"),
    [(owner, name) for owner, names in sb3_engine.PRIVATE_ATTRIBUTES.items() for name in names],
)
def test_every_private_attribute_the_engine_uses_is_there(agent, owner, name):
    holder = {"DQN": agent, "ReplayBuffer": agent.replay_buffer}[owner]
    assert isinstance(agent.replay_buffer, ReplayBuffer)
    assert hasattr(holder, name), (
        f"stable-baselines3 {stable_baselines3.__version__} has no {owner}.{name}, which "
        "dospcot/core/sb3_engine.py uses: adapt that module or pin SB3 to the tested range"
    )


def test_a_booked_step_counts_and_stores_as_sb3_does():
    model = DQN(
        "MlpPolicy", gym.make("CartPole-v1"), learning_starts=0, buffer_size=100, seed=0, device="cpu"
    )
    sb3_engine.start_collection(model, 5)
    env = model.get_env()
    before = (model.num_timesteps, sb3_engine.calls(model), model.replay_buffer.pos)
    obs = sb3_engine.last_observation(model)
    assert obs.shape == (1, 4)
    action = np.array([1])
    new_obs, rewards, dones, infos = env.step(action)
    sb3_engine.record_step(model, action, new_obs, rewards, dones, infos)
    assert (model.num_timesteps, sb3_engine.calls(model), model.replay_buffer.pos) == tuple(
        b + 1 for b in before
    )
    stored = sb3_engine.samples_at(model.replay_buffer, np.array([0]))
    np.testing.assert_array_equal(stored.observations.numpy(), obs)
    assert int(stored.actions.item()) == 1
