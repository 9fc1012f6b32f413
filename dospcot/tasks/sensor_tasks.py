"""What the sensor tasks share (``task = "highway"`` and ``task = "gym"``): a spec base whose runs the
sensor adapter (:mod:`dospcot.adapters.sensor_adapter`) serves, named in messages by its section's env
id, its demonstrations from a file or a saved agent, checked before anything trains."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from dospcot.config.errors import ConfigError
from dospcot.tasks.registry import Task

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig

MakeEnv = Callable[..., Any]
"""``make_env(view, views, label_fraction, mask_seed)``: a masked sensor env of one agent's view
(:class:`~dospcot.adapters.sensor_adapter.SensorAdapter`)."""


class SensorTask(Task):
    """A task the sensor adapter serves, from the env factories it gives (:meth:`env_factories`)."""

    adapter = "sensor"

    def title(self, cfg: TrainConfig) -> str:
        return getattr(cfg, self.section).env_id

    def validate(self, cfg: TrainConfig) -> None:
        demos = cfg.demonstrations
        if demos.episodes and not (demos.file or demos.agent):
            raise ConfigError(
                f'demonstrations.episodes: a task = "{cfg.task}" run\'s demonstrations come from a file '
                "or a saved agent: set demonstrations.file or demonstrations.agent (docs/demonstrations.md)"
            )

    def check(self, cfg: TrainConfig) -> None:
        """A demonstrations file must load, and a saved agent with its algorithm."""
        from dospcot.demonstrations import Demonstrations, load_agent

        demos = cfg.demonstrations
        try:
            if demos.file:
                Demonstrations.load(demos.file)
        except ValueError as err:
            raise ConfigError(f"demonstrations.file: {err}") from None
        try:
            if demos.agent:
                load_agent(demos.agent, demos.agent_algorithm)
        except ValueError as err:
            raise ConfigError(f"demonstrations.{err}") from None

    def env_factories(self, cfg: TrainConfig) -> tuple[MakeEnv, MakeEnv]:
        """The factories of a run's training envs and of its evaluation envs (one per view)."""
        raise NotImplementedError
