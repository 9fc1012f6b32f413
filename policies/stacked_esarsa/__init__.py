"""S seeds' ExpectedSarsaDQN networks trained in lock step: stacked weights, batched matmul, one Adam
whose every member keeps its own state (docs/batched_seeds.md)."""

from dospcot.policies.stacked_esarsa.stacked_adam import StackedAdam
from dospcot.policies.stacked_esarsa.stacked_esarsa import StackedExpectedSarsa, stack_samples
from dospcot.policies.stacked_esarsa.stacked_q_network import StackedQNetwork

__all__ = ["StackedAdam", "StackedExpectedSarsa", "StackedQNetwork", "stack_samples"]
