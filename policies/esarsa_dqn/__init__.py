"""ExpectedSarsaDQN: stable-baselines3 DQN with an Expected-SARSA target and relabelled weighted replay."""

from dospcot.policies.esarsa_dqn.buffers import (
    RelabellingReplayBuffer,
    RewardTable,
    WeightedReplayBufferSamples,
)
from dospcot.policies.esarsa_dqn.esarsa_dqn import (
    ExpectedSarsaDQN,
    epsilon_greedy_expectation,
    large_margin_loss,
    weighted_huber_loss,
)

MlpPolicy = "MlpPolicy"
CnnPolicy = "CnnPolicy"
MultiInputPolicy = "MultiInputPolicy"

__all__ = [
    "CnnPolicy",
    "ExpectedSarsaDQN",
    "MlpPolicy",
    "MultiInputPolicy",
    "RelabellingReplayBuffer",
    "RewardTable",
    "WeightedReplayBufferSamples",
    "epsilon_greedy_expectation",
    "large_margin_loss",
    "weighted_huber_loss",
]
