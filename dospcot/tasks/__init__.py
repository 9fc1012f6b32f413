"""The tasks a config can name, as specs (:mod:`dospcot.tasks.registry`), and reading a config into
its checked dataclass (:func:`load_config`)."""

from dospcot.tasks.loading import config_from_table, load_config, load_run_config
from dospcot.tasks.registry import Task, get_task, register, tasks

__all__ = ["Task", "config_from_table", "get_task", "load_config", "load_run_config", "register", "tasks"]
