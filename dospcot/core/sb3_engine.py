"""The one door to stable-baselines3's internals: every private attribute of an SB3 ``DQN`` or replay
buffer that the batched engine (:mod:`dospcot.core.batched_runs`) reads or writes, so that it steps
many agents in lock step exactly as each agent's own ``learn()`` would.

SB3 has no public API for stepping an agent one env step at a time; its ``collect_rollouts`` does it
through these attributes. They are listed, with every other private SB3 member the project touches,
in :data:`dospcot.policies.sb3_private.SB3_PRIVATE_MEMBERS`, which ``tests/test_sb3_engine.py``
checks against the installed SB3.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3 import DQN
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples

LOG_INTERVAL = 4
"""Episodes between SB3's ``rollout/`` dumps, as ``DQN.learn``'s default ``log_interval``."""


def start_collection(agent: DQN, steps: int) -> None:
    """What ``learn(steps)`` sets up before it collects: the env's seeded reset, the episode buffers."""
    agent._setup_learn(steps, reset_num_timesteps=False)


def last_observation(agent: DQN) -> np.ndarray:
    """The observation the agent's next action answers."""
    return agent._last_obs


def record_step(
    agent: DQN, action: np.ndarray, new_obs: np.ndarray, rewards: np.ndarray, dones: np.ndarray, infos: list
) -> None:
    """Book one env step of ``agent`` as SB3's ``collect_rollouts`` and ``DQN._on_step`` do: the step
    count, the episode buffers, the replay buffer and the ``rollout/`` scalars."""
    agent.num_timesteps += 1
    agent._update_info_buffer(infos, dones)
    agent._store_transition(agent.replay_buffer, action, new_obs, rewards, dones, infos)
    agent._n_calls += 1
    agent.logger.record("rollout/exploration_rate", agent.exploration_rate)
    for _ in range(int(dones.sum())):
        agent._episode_num += 1
        if agent._episode_num % LOG_INTERVAL == 0:
            agent.dump_logs()


def calls(agent: DQN) -> int:
    """Env steps the agent has booked (the count target-network syncs follow)."""
    return agent._n_calls


def record_update(agent: DQN, loss: float | None) -> None:
    """Log one ``train()`` call's scalars as ``DQN.train`` does; ``loss`` None: no step updated."""
    agent.logger.record("train/learning_rate", agent.lr_schedule(agent._current_progress_remaining))
    agent.logger.record("train/n_updates", agent._n_updates, exclude="tensorboard")
    if loss is not None:
        agent.logger.record("train/loss", loss)


def count_gradient_step(agent: DQN) -> None:
    """One more gradient step of the agent's, as ``DQN.train`` counts them."""
    agent._n_updates += 1


def samples_at(buffer: ReplayBuffer, indices: np.ndarray) -> ReplayBufferSamples | Any:
    """The buffer's samples at ``indices`` (what ``sample`` returns, with the draw made by the caller)."""
    return buffer._get_samples(indices)
