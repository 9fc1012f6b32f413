"""What a config must pass before any run folder is made: what only files, imports, the env or the
machine can tell."""

from __future__ import annotations

import torch

from dospcot.config.errors import ConfigError
from dospcot.config.run_configs import RunConfig, TrainConfig
from dospcot.tasks import get_task


def check_config(cfg: RunConfig) -> None:
    """The task's check step (:meth:`~dospcot.tasks.registry.Task.check`): what only files, imports or
    the env can tell, before any run folder is made; and that a GPU the ``[dqn]`` section names is there.
    """
    get_task(cfg.task).check(cfg)
    if isinstance(cfg, TrainConfig) and set(cfg.agent_kinds) - {"tabular"}:
        device = cfg.dqn.device
        index = int(device.partition(":")[2] or 0)
        if device.startswith("cuda") and index >= torch.cuda.device_count():
            raise ConfigError(
                f"dqn.device = {device!r}, but torch sees {torch.cuda.device_count()} CUDA device(s) "
                f"(torch {torch.__version__}); set dqn.device = 'cpu'"
            )
