"""TabularExpectedSarsa: a Q-table over a view's observations inside stable-baselines3's DQN loop."""

from dospcot.policies.tabular_esarsa.tabular_esarsa import TabularExpectedSarsa, ViewTableExtractor

__all__ = ["TabularExpectedSarsa", "ViewTableExtractor"]
