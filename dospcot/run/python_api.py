"""Co-train on your own gymnasium env from Python (docs/your_env.md).

:func:`gym_config` turns an env, its views and any config keys into the ``task = "gym"``
:class:`~dospcot.config.loading.TrainConfig` that ``dospcot train`` would read from a TOML file, and
:func:`train_env` trains it in a run folder. Functions are stored in the run's ``config.toml`` by
their dotted paths, so the run resumes (``dospcot train --resume``), evaluates (``dospcot evaluate``)
and sweeps (``dospcot sweep <run>/config.toml``) like any other, wherever their module is importable.

Example (CartPole, two views: the whole state, and the pole alone)::

    import numpy as np
    from dospcot.run.python_api import train_env

    def pole(obs: np.ndarray) -> np.ndarray:  # at module level: it is saved by name
        return obs[2:]

    run_dir = train_env("CartPole-v1", {"state": "observation", "pole": pole},
                        settings={"training.rounds": 3})
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch as th

from dospcot.config.loading import set_key
from dospcot.config.run_configs import TrainConfig
from dospcot.envs.gym_sensors import dotted_path
from dospcot.run.train import train
from dospcot.tasks import config_from_table

ViewSpec = str | Callable[[Any], Any]
"""A view: a function of the observation (defined at module level), or a name: ``"observation"``, a
key of a ``Dict`` observation, or on MiniGrid ``"minigrid.full"`` / ``"minigrid.position"``."""


def gym_config(
    env: str | Callable[..., gym.Env],
    views: Mapping[str, ViewSpec],
    *,
    method: str = "dospcot",
    agent: str = "dqn",
    seed: int = 0,
    label_fraction: float | None = None,
    state_key: str | Callable[[gym.Env], Hashable] | None = None,
    name: str = "gym",
    settings: Mapping[str, Any] | None = None,
) -> TrainConfig:
    """The ``task = "gym"`` config of a run, checked as a TOML config would be.

    :param env: a registered gymnasium id, or a module-level function that returns the env.
    :param views: each agent's view by name; every view gets one agent.
    :param method: ``dospcot`` (DOSPCoT), ``oracle``, ``masked-zero``, ``labels-only`` or
        ``reward-model`` (the peer: ensembles fitted on the labels alone).
    :param agent: every agent's kind: ``dqn`` or ``esarsa_dqn``.
    :param seed: the run's seed.
    :param label_fraction: the share of steps (with ``state_key``: of (state, action) pairs) whose
        reward a uniform mask reveals, in (0, 1] (``training.label_fraction``); None: the labels the
        adopted version of the defaults buys (docs/guide/defaults.md). Refused where a rater buys a
        budget of answers, which would leave it unread: set ``training.label_strategy`` to
        ``"uniform"`` in ``settings`` with it.
    :param state_key: a module-level function of the unwrapped env that names its state by a hashable
        key, or ``"minigrid"``; the pool then holds (key, action) pairs, as on the grid.
    :param name: the run's name (its folder under the runs root).
    :param settings: any other config key by its dotted name, e.g. ``{"training.rounds": 3,
        "gym.episode_steps": 500, "dqn.learning_rate": 5e-4}``.
    """
    env_id = env if isinstance(env, str) else dotted_path(env, "env")
    specs = {
        view: spec if isinstance(spec, str) else dotted_path(spec, f"views[{view!r}]")
        for view, spec in views.items()
    }
    data: dict[str, Any] = {
        "name": name,
        "seed": seed,
        "method": method,
        "agent": agent,
        "task": "gym",
        "views": list(specs),
        "gym": {"env_id": env_id, "views": specs},
        "training": {} if label_fraction is None else {"label_fraction": label_fraction},
    }
    if state_key is not None:
        data["gym"]["state_key"] = (
            state_key if isinstance(state_key, str) else dotted_path(state_key, "state_key")
        )
    for key, value in (settings or {}).items():
        set_key(data, key.split("."), value, f"settings[{key!r}]")
    cfg = config_from_table(data)
    cfg.check_read({*(settings or {}), *(["training.label_fraction"] if label_fraction is not None else [])})
    return cfg


def train_env(
    env: str | Callable[..., gym.Env],
    views: Mapping[str, ViewSpec],
    *,
    runs_dir: str | Path = "runs",
    show_progress: bool = True,
    threads: int = 1,
    **kwargs: Any,
) -> Path:
    """Train a run of :func:`gym_config` (same arguments) in a new folder ``runs_dir/<name>/<stamp>/``;
    return the folder. It holds what ``dospcot train`` writes: the agents (plain SB3 ``DQN`` zips),
    ``metrics.csv``, ``summary.json`` and TensorBoard events (and, while it runs, a checkpoint).

    :param threads: torch's threads for this process (``torch.set_num_threads``), as ``dospcot train
        --threads``: small networks run fastest on one.
    """
    cfg = gym_config(env, views, **kwargs)
    th.set_num_threads(threads)
    return train(cfg, Path(runs_dir), show_progress=show_progress, command="dospcot.run.python_api.train_env")


__all__ = ["gym_config", "train_env"]
