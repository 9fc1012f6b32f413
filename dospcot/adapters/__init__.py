"""What one co-training run of a task needs beside the round: the adapters a
:class:`~dospcot.core.sb3_round.CoTrainingRun` drives (their envs, stores, pools and evaluators), a
layer above the core. They import torch and the envs; a task spec (:mod:`dospcot.tasks`) names its
adapter and gives its envs, and :func:`build_adapter` puts the two together.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from dospcot.tasks import get_task

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig
    from dospcot.core.task_adapter import TaskAdapter


def build_adapter(cfg: TrainConfig) -> TaskAdapter:
    """The adapter of one run of ``cfg``, the one its task's spec names (:attr:`Task.adapter
    <dospcot.tasks.registry.Task.adapter>`), over the envs and views the spec gives.

    :raises ValueError: the task's runs have no adapter (the paper protocol trains its own way).
    """
    task = get_task(cfg.task)
    if task.adapter == "grid":
        from dospcot.adapters.grid_adapter import GridAdapter

        return GridAdapter(cfg, *task.discrete_world(cfg))
    if task.adapter == "sensor":
        from dospcot.adapters.sensor_adapter import SensorAdapter

        make_env, make_eval_env = task.env_factories(cfg)
        return SensorAdapter(cfg, getattr(cfg, task.section), make_env, make_eval_env)
    raise ValueError(f"task {cfg.task!r} has no co-training adapter")
