"""Each agent's own random draws (``training.agent_draws = "own"``).

SB3 draws an agent's exploration and its replay batches from the global generators (Python's,
numpy's legacy one and torch's), and seeds them when it builds the agent. A run with several agents
therefore hands each agent whatever the agents before it left in those generators: under
``"shared"`` (the default, and every run's behaviour before the key existed) agent 0 of a two-view run
draws differently from agent 0 of a one-view run of the same seed, though both see the same env, the
same rewards and the same seeds.

Under ``"own"``, :class:`AgentDraws` keeps the generators' state per agent, as its construction left
them, and swaps it in around every ``learn()`` and policy update. Agent k's draws then depend on its
own seed alone, so with every reward labelled a co-trained agent computes bit for bit what a
one-view run's agent of the same view and index computes (tests/test_agent_draws.py), and any
difference between two arms' agents comes from their rewards, not from another agent's draws.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import torch as th


def global_draws() -> dict[str, Any]:
    """The state of the global generators SB3 draws from: Python's, numpy's legacy one and torch's."""
    return {"python": random.getstate(), "numpy": np.random.get_state(), "torch": th.get_rng_state()}  # noqa: NPY002


def set_global_draws(state: dict[str, Any]) -> None:
    """Continue the global generators from :func:`global_draws`'s ``state``."""
    random.setstate(state["python"])
    np.random.set_state(state["numpy"])  # noqa: NPY002
    th.set_rng_state(state["torch"])


class AgentDraws:
    """The global generators' state of each agent of a run, swapped in while that agent draws."""

    def __init__(self) -> None:
        self.states: list[dict[str, Any]] = []
        """Per agent (in the run's order), the generators' state as its last draw left it."""

    def add(self) -> None:
        """Keep the generators' state now, right after SB3 seeded them for the agent just built."""
        self.states.append(global_draws())

    @contextmanager
    def of(self, k: int) -> Iterator[None]:
        """Agent ``k`` draws from its own state inside the block; the global state outside it is
        left as it was."""
        outside = global_draws()
        set_global_draws(self.states[k])
        try:
            yield
        finally:
            self.states[k] = global_draws()
            set_global_draws(outside)
