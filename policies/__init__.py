"""Agents that learn from rewards and self-paced weights given by the co-trainer (``dospcot.policies``)."""

from dospcot.policies.esarsa_dqn import ExpectedSarsaDQN, RelabellingReplayBuffer, RewardTable
from dospcot.policies.tabular_esarsa import TabularExpectedSarsa

__all__ = ["ExpectedSarsaDQN", "RelabellingReplayBuffer", "RewardTable", "TabularExpectedSarsa"]
