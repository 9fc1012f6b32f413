"""The grid task (``task = "grid"``, the ``[env]`` section): DOSPCoT on the masked grid world of
:class:`dospcot.envs.GridWorld`. The adapter it builds (:mod:`dospcot.tasks.adapters.grid`) serves any
deterministic discrete task (a toy-text env with ``P`` and ``s``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from dospcot.config.errors import ConfigError
from dospcot.tasks.registry import Task, register

GRID_ACTIONS = 4
"""The grid world's actions: its four moves (``dospcot.envs.gridworld.MOVES``)."""

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig
    from dospcot.tasks.adapters.grid import GridAdapter

GRID_VIEWS: tuple[str, ...] = ("coords", "patch", "rays")


@register
class GridWorldTask(Task):
    """The masked grid world: a map from a seed, (s, a) keys labelled at random (and, with
    ``env.monitored_columns``, every key of the first columns), value iteration's optimum for the
    metrics and for the grid's demonstrations."""

    name = "grid"
    section = "env"
    discrete_states = True

    def title(self, cfg: TrainConfig) -> str:
        return "grid world"

    def view_names(self, cfg: TrainConfig) -> tuple[str, ...]:
        return GRID_VIEWS

    def validate(self, cfg: TrainConfig) -> None:
        demos = cfg.demonstrations
        if demos.file or demos.agent:
            source = "file" if demos.file else "agent"
            raise ConfigError(
                f"demonstrations.{source}: a grid run's demonstrations come from value iteration "
                '(demonstrations.episodes); a file or a saved agent serves task = "highway" or "gym"'
            )

    def has_monitor(self, cfg: TrainConfig) -> bool:
        return cfg.env.monitored_columns > 0

    def pool_keys(self, cfg: TrainConfig) -> int:
        return cfg.env.size**2 * GRID_ACTIONS

    def check(self, cfg: TrainConfig) -> None:
        from dospcot.tasks.adapters.grid import grid_world

        try:  # a map the densities cannot make solvable fails after its draws, not in round 1
            grid_world(cfg)
        except (ValueError, RuntimeError) as err:
            raise ConfigError(f"env: {err}") from None

    def build(self, cfg: TrainConfig) -> GridAdapter:
        from dospcot.envs import monitored_states
        from dospcot.tasks.adapters.grid import GridAdapter, grid_world

        make_env, views, layout = grid_world(cfg)
        columns = cfg.env.monitored_columns
        return GridAdapter(cfg, make_env, views, monitored_states(layout.size, columns) if columns else None)
