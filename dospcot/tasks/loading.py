"""Reading a config into its checked dataclass: the table (:mod:`dospcot.config.loading`) converted
into its task's config type, then checked by its task (:meth:`~dospcot.tasks.registry.Task.check_config`).
Nothing here imports torch, stable-baselines3 or an env, so a config reads at once."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dospcot.config.errors import ConfigError
from dospcot.config.loading import (
    config_table,
    from_mapping,
    given_keys,
    read_config_data,
    renamed_to_now,
    type_hints,
)
from dospcot.config.run_configs import PaperConfig, RunConfig, TrainConfig
from dospcot.config.version_defaults import fit_budget, version_of, with_version_defaults
from dospcot.tasks.registry import get_task


def load_config(config: str, overrides: Sequence[str] = (), defaults: int | None = None) -> RunConfig:
    """Read a preset or a TOML file, apply ``--set`` overrides and check the result (no I/O beyond the
    file): the root dataclass of its task (``task``, default ``"grid"``), a
    :class:`~dospcot.config.run_configs.PaperConfig` for ``"paper"``, else a
    :class:`~dospcot.config.run_configs.TrainConfig`.

    A key that the config's method never reads, set by ``--set`` or by the file itself where it extends
    another (:func:`~dospcot.config.loading.given_keys`), is refused
    (:meth:`~dospcot.config.run_configs.TrainConfig.check_read`).

    :param defaults: the version of the defaults (:mod:`dospcot.config.versions`) where neither the file
        nor ``overrides`` names one (a sweep's trials resolve under the sweep's version); None: the
        adopted version.
    :raises ConfigError: one line naming the first bad key and what is allowed.
    """
    table = config_table(config, overrides)
    if defaults is not None:
        table.setdefault("defaults", defaults)
    cfg = config_from_table(table)
    if isinstance(cfg, TrainConfig):
        in_file, set_here = given_keys(config, overrides)
        cfg.check_read(in_file | set_here)
    return cfg


def config_from_table(data: Mapping[str, Any]) -> RunConfig:
    """The checked config of a table (as a TOML file holds it): the defaults of its version
    (:mod:`dospcot.config.versions`) where it sets nothing, every key and type, then its task."""
    task = get_task(data.get("task", "grid"))
    cls = task.config_type()
    _check_kind(cls, data)
    version_of(data)  # an unknown version, before any key it would have moved
    if cls is not TrainConfig:  # no version moves a paper-protocol key
        cfg = from_mapping(cls, data)
    else:
        section = task_section(task.section)
        cfg = from_mapping(cls, with_version_defaults(data, section))
        if (fitted := fit_budget(data, section, task.most_samples(cfg))) is not None:
            cfg = from_mapping(cls, with_version_defaults(fitted, section))
    task.check_config(cfg)
    return cfg


def task_section(name: str) -> tuple[str, type]:
    """A :class:`~dospcot.config.run_configs.TrainConfig` task section: its name and its dataclass."""
    return name, type_hints(TrainConfig)[name]


def _check_kind(cls: type, data: Mapping[str, Any]) -> None:
    """Refuse a key of the other kind of config (a training key in a ``task = "paper"`` config, or a
    paper-protocol key in a training one) by what it is, rather than as an unknown key."""
    other = TrainConfig if cls is PaperConfig else PaperConfig
    fields = {f.name for f in dataclasses.fields(cls)}
    stray = [key for key in data if key not in fields and key in {f.name for f in dataclasses.fields(other)}]
    if not stray:
        return
    if cls is PaperConfig:
        raise ConfigError(
            f'task = "paper" makes this a paper-protocol config, which has no {stray[0]!r} (a key of a '
            'dospcot train config); start a paper config from a paper preset: extends = "paper-text"'
        )
    raise ConfigError(
        f'{stray[0]!r} is a key of a paper-protocol config (task = "paper"), not of a task = '
        f'"{data.get("task", "grid")}" config'
    )


def load_run_config(path: Path) -> RunConfig:
    """The config a run folder holds (its ``config.toml``), checked as :func:`load_config` does, but
    with every key renamed since the folder was written read under its new name
    (:func:`~dospcot.config.loading.renamed_to_now`)."""
    data = read_config_data(str(path))
    cls = get_task(data.get("task", "grid")).config_type()
    return config_from_table(renamed_to_now(cls, data))
