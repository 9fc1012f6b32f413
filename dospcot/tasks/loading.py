"""Reading a config into its checked dataclass: the table (:mod:`dospcot.config.loading`) converted
into its task's config type, then checked by its task (:meth:`~dospcot.tasks.registry.Task.check_config`).
Nothing here imports torch, stable-baselines3 or an env, so a config reads at once."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dospcot.config.loading import config_table, from_mapping, read_config_data, renamed_to_now
from dospcot.config.run_configs import RunConfig
from dospcot.tasks.registry import get_task


def load_config(config: str, overrides: Sequence[str] = ()) -> RunConfig:
    """Read a preset or a TOML file, apply ``--set`` overrides and check the result (no I/O beyond the
    file): the root dataclass of its task (``task``, default ``"grid"``), a
    :class:`~dospcot.config.run_configs.PaperConfig` for ``"paper"``, else a
    :class:`~dospcot.config.run_configs.TrainConfig`.

    :raises ConfigError: one line naming the first bad key and what is allowed.
    """
    return config_from_table(config_table(config, overrides))


def config_from_table(data: Mapping[str, Any]) -> RunConfig:
    """The checked config of a table (as a TOML file holds it): every key and type, then its task."""
    task = get_task(data.get("task", "grid"))
    cfg = from_mapping(task.config_type(), data)
    task.check_config(cfg)
    return cfg


def load_run_config(path: Path) -> RunConfig:
    """The config a run folder holds (its ``config.toml``), checked as :func:`load_config` does, but
    with every key renamed since the folder was written read under its new name
    (:func:`~dospcot.config.loading.renamed_to_now`)."""
    data = read_config_data(str(path))
    cls = get_task(data.get("task", "grid")).config_type()
    return config_from_table(renamed_to_now(cls, data))
