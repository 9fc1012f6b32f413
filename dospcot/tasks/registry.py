"""The task registry: every task a config can name (``task = "..."``) is one module of
:mod:`dospcot.tasks` that subclasses :class:`Task` and registers it with :func:`register`.

A task is a spec: it says what its config allows (its views, what its section may hold together),
checks what needs files, imports or an env before anything trains, and names the adapter that serves
its runs (:attr:`Task.adapter`; the adapters, a layer above the core, are :mod:`dospcot.adapters`). A
spec module imports neither torch nor an env at import time, so reading a config costs no training
stack, and it never imports the core or an adapter. How a run of a task trains is not the spec's to say: the
run layer chooses by the type of its config (:mod:`dospcot.run.runners`). Nothing outside this
package branches on a task's name: adding a task is one new module here and its presets
(docs/design.md, "Adding a task").

The modules are found, not listed: the first look-up imports every module of this package, so that
each registers itself.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from typing import Any, ClassVar

from dospcot.config.errors import ConfigError
from dospcot.config.run_configs import RUN_AGENT_KINDS, RunConfig, TrainConfig

_TASKS: dict[str, Task] = {}


class Task:
    """A task of the registry, its config a :class:`~dospcot.config.run_configs.TrainConfig` unless
    :meth:`config_type` says otherwise."""

    name: ClassVar[str]
    """The value of ``task`` in a config."""
    section: ClassVar[str]
    """The config section that sets the task up."""
    discrete_states: ClassVar[bool] = False
    """Whether every state and its views are known in advance, as ``tabular`` agents need."""
    adapter: ClassVar[str | None] = None
    """The adapter that serves the task's co-training runs (:func:`dospcot.adapters.build_adapter`):
    ``"grid"`` (a deterministic discrete task, from :meth:`discrete_world`), ``"sensor"`` (from
    :meth:`~dospcot.tasks.sensor_tasks.SensorTask.env_factories`), or None for a task whose runs
    train without one (the paper protocol)."""

    def config_type(self) -> type:
        """The root dataclass of the task's configs."""
        return TrainConfig

    def title(self, cfg: TrainConfig) -> str:
        """The task, in words (error messages name it)."""
        return self.name

    def view_names(self, cfg: TrainConfig) -> tuple[str, ...]:
        """The views the task offers."""
        raise NotImplementedError

    def validate(self, cfg: TrainConfig) -> None:
        """Raise :class:`ConfigError` for settings of the task that cannot go together (no I/O)."""

    def has_monitor(self, cfg: TrainConfig) -> bool:
        """Whether a reward monitor reveals rewards beside the label fraction."""
        return False

    def pool_keys(self, cfg: TrainConfig) -> int | None:
        """The most distinct samples a run's pool can hold whatever its length (a discrete task's
        (state, action) keys), or None: every step is a sample of its own."""
        return None

    def most_samples(self, cfg: TrainConfig) -> int:
        """An upper bound on the samples of a run's pool, which bounds the queries it can ask: every
        step of every agent, and at most :meth:`pool_keys`."""
        steps = cfg.training.total_steps * len(cfg.views)
        keys = self.pool_keys(cfg)
        return steps if keys is None else min(steps, keys)

    def check(self, cfg: RunConfig) -> None:
        """Raise :class:`ConfigError` for what only files, imports or the env can tell (an unknown env
        id, a demonstrations file that does not load); runs before any run folder is made."""

    def discrete_world(self, cfg: TrainConfig) -> tuple[Callable[[], Any], dict[str, Any], Any]:
        """What the grid adapter serves (``adapter = "grid"``): a factory of the task's env (a
        deterministic toy-text env with ``P`` and ``s``), its views by name
        (:class:`~dospcot.envs.views.View`), and bool (S,) the states whose every reward a monitor
        reveals, or None."""
        raise NotImplementedError

    def check_config(self, cfg: RunConfig) -> None:
        """Every check of ``cfg`` that needs the task (no I/O): the views it offers, the sections it
        reads, the agents its states allow, then the task's own :meth:`validate`.

        :raises ConfigError: one line naming the key and what is allowed.
        """
        if not isinstance(cfg, TrainConfig):
            return
        self.validate(cfg)
        views = self.view_names(cfg)
        allowed, task_name = ", ".join(views), self.title(cfg)
        if not cfg.views:
            raise ConfigError(f"views: need at least one view; allowed: {allowed}")
        for view in cfg.views:
            if view not in views:
                raise ConfigError(f"views: the {task_name} has no view {view!r}; allowed: {allowed}")
        # Another task's section would be accepted and change nothing; at its defaults (as in the
        # config.toml of a run folder written before it was left out) it says nothing either.
        for unread in self._unread_sections():
            if getattr(cfg, unread) != type(getattr(cfg, unread))():
                raise ConfigError(
                    f'{unread}: a task = "{cfg.task}" run does not read the [{unread}] section; its task '
                    f"is set in [{self.section}]"
                )
        if not self.discrete_states and "tabular" in cfg.agent_kinds:
            key = "agents" if cfg.agents else "agent"
            neural = ", ".join(kind for kind in RUN_AGENT_KINDS if kind != "tabular")
            raise ConfigError(
                f"{key}: 'tabular' needs a discrete task (task = \"grid\"); allowed on {task_name}: {neural}"
            )
        demos = cfg.demonstrations
        if demos.agent and demos.agent_view and demos.agent_view not in views:
            raise ConfigError(
                f"demonstrations.agent_view: the {task_name} has no view {demos.agent_view!r}; "
                f"allowed: {allowed}"
            )
        samples = self.most_samples(cfg)
        if cfg.training.label_budget > samples:
            bound = "rounds x steps_per_round x views" + (
                ", or the task's keys" * (self.pool_keys(cfg) is not None)
            )
            raise ConfigError(
                f"training.label_budget: {cfg.training.label_budget:,} answers cannot be spent: the run "
                f"meets at most {samples:,} samples to ask about ({bound}); give at most {samples:,}, or 0 "
                "for the share label_fraction"
            )
        if cfg.training.segment_length > 1 and self.has_monitor(cfg):
            raise ConfigError(
                "training.segment_length: segment labels reveal no single reward, so they cannot be "
                "combined with a reward monitor"
            )

    def config_table(self, cfg: RunConfig) -> dict[str, Any]:
        """What a run folder's ``config.toml`` holds: ``cfg`` as plain TOML values, without the
        sections of the other tasks, which this run does not read."""
        data = cfg.to_dict()
        if isinstance(cfg, TrainConfig):
            for unread in self._unread_sections():
                del data[unread]
        return data

    def _unread_sections(self) -> list[str]:
        return [section for section in task_sections() if section != self.section]


def register(cls: type[Task]) -> type[Task]:
    """Class decorator: add a :class:`Task` to the registry under its ``name``."""
    if cls.name in _TASKS and type(_TASKS[cls.name]) is not cls:
        raise ValueError(f"task {cls.name!r} is registered twice")
    _TASKS[cls.name] = cls()
    return cls


def tasks() -> dict[str, Task]:
    """Every registered task, by name (importing the modules of :mod:`dospcot.tasks` first)."""
    package = importlib.import_module("dospcot.tasks")
    for module in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"dospcot.tasks.{module.name}")
    return _TASKS


def get_task(name: str) -> Task:
    """The registered task ``name``; a :class:`ConfigError` naming the others if there is none."""
    if not isinstance(name, str):
        raise ConfigError(f"task: expected a string, got {name!r}")
    registered = _TASKS if name in _TASKS else tasks()
    if name not in registered:
        raise ConfigError(f"task: unknown task {name!r}; allowed: {', '.join(sorted(registered))}")
    return registered[name]


def task_sections() -> list[str]:
    """The sections of :class:`~dospcot.config.run_configs.TrainConfig` that set up a task."""
    return sorted({task.section for task in tasks().values() if task.config_type() is TrainConfig})
