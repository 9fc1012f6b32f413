"""The task registry: every task a config can name (``task = "..."``) is one module of
:mod:`dospcot.tasks` that subclasses :class:`Task` and registers it with :func:`register`.

A task says what its config allows (its views, what its section may hold together), checks what needs
files, imports or an env before anything trains, and builds the adapter a
:class:`~dospcot.core.cotraining_run.CoTrainingRun` drives (its env, views, pool and evaluation). A
task whose runs are not co-training runs of SB3 agents (the paper's tabular protocol) also says how it
trains, resumes, evaluates and reports a run folder. Nothing outside this package branches on a task's
name: adding a task is one new module here and its presets (docs/design.md, "Adding a task").

The modules are found, not listed: the first look-up imports every module of this package, so that
each registers itself.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from dospcot.config.errors import ConfigError

if TYPE_CHECKING:
    from dospcot.config.run_configs import RunConfig, TrainConfig
    from dospcot.core.cotraining_run import CoTrainingTask
    from dospcot.experiment.sweep_spec import SweepSpec

_TASKS: dict[str, Task] = {}


class Task:
    """A task of the registry; the defaults serve a co-training run of SB3 agents
    (:mod:`dospcot.experiment.train`)."""

    name: ClassVar[str]
    """The value of ``task`` in a config."""
    section: ClassVar[str]
    """The config section that sets the task up."""
    discrete_states: ClassVar[bool] = False
    """Whether every state and its views are known in advance, as ``tabular`` agents need."""
    seeds_train_together: ClassVar[bool] = False
    """Whether a sweep trains several seeds of one config in one process: such a task also has
    ``train_seeds_at(cfg, run_dirs, commands, progress)``, which trains each seed in its folder and
    calls ``progress`` with the share of one seed just done (the paper protocol's)."""

    def config_type(self) -> type:
        """The root dataclass of the task's configs."""
        from dospcot.config.run_configs import TrainConfig  # a task module is found by the config it serves

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

    def check(self, cfg: RunConfig) -> None:
        """Raise :class:`ConfigError` for what only files, imports or the env can tell (an unknown env
        id, a demonstrations file that does not load); runs before any run folder is made."""

    def build(self, cfg: TrainConfig) -> CoTrainingTask:
        """The adapter of one run (:class:`~dospcot.core.cotraining_run.CoTrainingTask`)."""
        raise NotImplementedError

    def train_at(self, run_dir: Path, cfg: RunConfig, *, show_progress: bool, command: str) -> Path:
        """Train ``cfg`` in ``run_dir``, which holds nothing yet."""
        from dospcot.experiment.train import train_cotraining_run

        return train_cotraining_run(run_dir, cfg, show_progress=show_progress, command=command)

    def resume(self, run_dir: Path, cfg: RunConfig, *, show_progress: bool, command: str) -> Path:
        """Continue the unfinished run of ``cfg`` in ``run_dir``."""
        from dospcot.experiment.train import resume_cotraining_run

        return resume_cotraining_run(run_dir, cfg, show_progress=show_progress, command=command)

    def evaluate(self, run_dir: Path, cfg: RunConfig) -> dict[str, Any]:
        """Re-evaluate the saved agents of a run folder."""
        from dospcot.experiment.train import evaluate_cotraining_run

        return evaluate_cotraining_run(run_dir, cfg)

    def result_line(self, run_dir: Path, summary: dict[str, Any]) -> str:
        """What ``dospcot train`` prints of a finished run's ``summary.json``."""
        mean = summary["mean"]
        figures = ", ".join(
            f"{name.replace('_', ' ')} {mean[name]:.{digits}f}"
            for name, digits in (("normalised_score", 3), ("agreement", 3), ("success", 2))
        )
        return f"{run_dir}: {figures} (mean over {summary['m']} agent(s), round {summary['rounds']})"

    def write_report(self, spec: SweepSpec, runs: list[Any], out_dir: Path) -> list[Path]:
        """Write a sweep's report into ``out_dir``; return the files."""
        from dospcot.experiment.report import write_cotraining_report

        return write_cotraining_report(spec, runs, out_dir)


def mask_fraction(cfg: TrainConfig) -> float:
    """The random share of a run's reward mask: every reward for the oracle, none where a rater buys
    the labels (an active ``training.label_strategy``), else ``training.label_fraction``."""
    if cfg.method == "oracle":
        return 1.0
    return cfg.training.label_fraction if cfg.training.label_strategy == "uniform" else 0.0


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
    from dospcot.config.run_configs import TrainConfig

    return sorted({task.section for task in tasks().values() if task.config_type() is TrainConfig})
