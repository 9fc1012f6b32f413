"""The worked toy task of docs/design.md ("Adding a task"): a corridor of ``env.size`` cells, registered
as ``task = "chain"``. It is all a new task needs: the env, its views, and a :class:`Task` that gives
them to the grid adapter."""

from __future__ import annotations

from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np

from dospcot.config.run_configs import TrainConfig
from dospcot.envs.views import View
from dospcot.tasks.registry import Task, register


class Chain(gym.Env):
    """A corridor of ``n`` cells: start in cell 0, the goal in cell n - 1; action 1 steps right, 0 left;
    every step costs 1. A deterministic toy-text env: ``P``, ``s`` and ``initial_state_distrib``."""

    def __init__(self, n: int) -> None:
        self.observation_space, self.action_space = gym.spaces.Discrete(n), gym.spaces.Discrete(2)
        self.P: dict[int, dict[int, list[tuple[float, int, float, bool]]]] = {
            s: {a: [(1.0, min(max(s + 2 * a - 1, 0), n - 1), -1.0, s + 2 * a - 1 == n - 1)] for a in (0, 1)}
            for s in range(n)
        }
        self.initial_state_distrib = np.eye(n)[0]
        self.s = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.s = 0
        return self.s, {}

    def step(self, action: int):
        _, self.s, reward, done = self.P[self.s][int(action)][0]
        return self.s, reward, done, False, {}


def chain_views(n: int) -> dict[str, View]:
    """Two views of a cell: a one-hot of it, and how far along the corridor it lies."""
    box = partial(gym.spaces.Box, 0.0, 1.0, dtype=np.float32)
    return {
        "cell": View("cell", box(shape=(n,)), lambda s: np.eye(n, dtype=np.float32)[s]),
        "progress": View("progress", box(shape=(1,)), lambda s: np.array([s / (n - 1)], np.float32)),
    }


@register
class ChainTask(Task):
    """The corridor: its length is ``env.size``."""

    name = "chain"
    section = "env"
    discrete_states = True
    adapter = "grid"

    def view_names(self, cfg: TrainConfig) -> tuple[str, ...]:
        return ("cell", "progress")

    def discrete_world(self, cfg: TrainConfig) -> tuple[Any, dict[str, View], None]:
        return partial(Chain, cfg.env.size), chain_views(cfg.env.size), None
