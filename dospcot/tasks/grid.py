"""The grid task (``task = "grid"``, the ``[env]`` section): DOSPCoT on the masked grid world of
:class:`dospcot.envs.GridWorld`. Its runs are served by the grid adapter
(:mod:`dospcot.adapters.grid_adapter`), which serves any deterministic discrete task (a toy-text env
with ``P`` and ``s``)."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from dospcot.config.errors import ConfigError
from dospcot.tasks.registry import Task, register

GRID_ACTIONS = 4
"""The grid world's actions: its four moves (``dospcot.envs.gridworld.MOVES``)."""

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy as np

    from dospcot.config.run_configs import TrainConfig
    from dospcot.envs import GridLayout, GridWorld
    from dospcot.envs.views import View

GRID_VIEWS: tuple[str, ...] = ("coords", "patch", "rays")


@register
class GridWorldTask(Task):
    """The masked grid world: a map from a seed, (s, a) keys labelled at random (and, with
    ``env.monitored_columns``, every key of the first columns), value iteration's optimum for the
    metrics and for the grid's demonstrations."""

    name = "grid"
    section = "env"
    discrete_states = True
    adapter = "grid"

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

    def discrete_world(
        self, cfg: TrainConfig
    ) -> tuple[Callable[[], GridWorld], dict[str, View], np.ndarray | None]:
        from dospcot.envs import monitored_states

        make_env, views, layout = grid_world(cfg)
        columns = cfg.env.monitored_columns
        return make_env, views, monitored_states(layout.size, columns) if columns else None

    def check(self, cfg: TrainConfig) -> None:
        try:  # a map the densities cannot make solvable fails after its draws, not in round 1
            grid_world(cfg)
        except (ValueError, RuntimeError) as err:
            raise ConfigError(f"env: {err}") from None


def grid_world(cfg: TrainConfig) -> tuple[Callable[[], GridWorld], dict[str, View], GridLayout]:
    """The env factory, the views (with the run's blind spots, if any) and the map of a grid config."""
    from dospcot.envs import GridLayout, GridWorld, grid_views, view_blind_spots

    env = cfg.env
    layout = GridLayout.random(env.size, env.layout_seed, env.lava_density, env.wall_density)
    make_env = partial(
        GridWorld,
        layout,
        step_cost=env.step_cost,
        lava_penalty=env.lava_penalty,
        goal_reward=env.goal_reward,
        exploring_starts=env.exploring_starts,
    )
    blind = (
        view_blind_spots(layout, env.blind_spot_rate, cfg.seed, identical=env.blind_spots == "identical")
        if env.blind_spot_rate > 0
        else None
    )
    return make_env, grid_views(layout, env.patch_size, env.compass, blind, env.ray_encoding), layout
