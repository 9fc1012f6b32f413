"""Tabular agents vectorised over independent learners: the validation path of DOSPCoT."""

from dospcot.policies.tabular.agents import (
    AGENT_KINDS,
    TabularAgents,
    check_agent_kind,
    epsilon_greedy_probs,
    expected_value,
)

__all__ = ["AGENT_KINDS", "TabularAgents", "check_agent_kind", "epsilon_greedy_probs", "expected_value"]
