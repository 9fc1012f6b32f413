"""Tabular agents vectorised over independent learners: the validation path of DOSPCoT."""

from dospcot.policies.tabular.agents import (
    TABULAR_KINDS,
    TabularAgents,
    check_agent_kind,
    epsilon_greedy_probs,
    expected_value,
)

__all__ = ["TABULAR_KINDS", "TabularAgents", "check_agent_kind", "epsilon_greedy_probs", "expected_value"]
