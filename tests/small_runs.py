"""Small grid runs the tests build with their own envs and views."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from dospcot.adapters.grid_adapter import GridAdapter
from dospcot.config.run_configs import TrainConfig
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.tasks import config_from_table

SB3_DQN = {"learning_rate": 1e-4, "batch_size": 32, "gamma": 0.99, "target_update_interval": 10_000}
"""stable-baselines3 ``DQN``'s own defaults where ``[dqn]``'s differ: the small-grid tests were tuned
on them."""
SB3_TABULAR = {"gamma": 0.99, "train_freq": 4, "learning_starts": 100}
"""Likewise for ``[tabular_agent]``: the tabular agent's own defaults (SB3's, but its step size)."""
MECHANISMS = 3
"""The version of the defaults the tests of co-training's mechanisms were written against: one
co-training a round over a uniform mask, so each test's hand-computed counts and bit-for-bit
comparisons hold what they were written to. A test of a later version's moves names its version."""
PINNED = (f"defaults={MECHANISMS}",)
"""``--set`` overrides that pin :data:`MECHANISMS`, for the tests that load a preset."""


def grid_config(
    method: str = "dospcot",
    agents: Sequence[str] = ("esarsa_dqn",),
    views: Sequence[str] = ("coords",),
    seed: int = 0,
    **sections: dict[str, Any],
) -> TrainConfig:
    """A grid run's config, checked as a TOML file's would be; ``sections`` are tables by name
    (``training={"rounds": 2}``); ``[dqn]`` and ``[tabular_agent]`` start from the agents' own defaults
    (:data:`SB3_DQN`, :data:`SB3_TABULAR`)."""
    data = {"defaults": MECHANISMS, "method": method, "agents": list(agents), "views": list(views)}
    data.update(seed=seed, **sections)
    data["dqn"] = {**SB3_DQN, **sections.get("dqn", {})}
    data["tabular_agent"] = {**SB3_TABULAR, **sections.get("tabular_agent", {})}
    return config_from_table(data)


def grid_run(
    cfg: TrainConfig,
    make_env: Callable[[], Any],
    views: dict[str, Any],
    monitored: Any = None,
) -> CoTrainingRun:
    """A co-training run of ``cfg`` on a grid-like task of the test's own (``make_env`` and its views)."""
    return CoTrainingRun(GridAdapter(cfg, make_env, views, monitored), cfg)
