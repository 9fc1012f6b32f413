"""Agents that learn from rewards and self-paced weights given by the co-trainer (``dospcot.policies``)."""
