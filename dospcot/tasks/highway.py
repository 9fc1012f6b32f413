"""The highway task (``task = "highway"``, the ``[highway]`` section): highway-env's driving tasks
(the ``highway`` extra) or the project's fast numpy highway, with sensor views and rewards revealed per
step; the sensor adapter (:mod:`dospcot.adapters.sensor_adapter`) pools every step."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from dospcot.config.errors import ConfigError
from dospcot.config.task_sections import FAST_HIGHWAY_ID, HIGHWAY_ENV_IDS
from dospcot.tasks.registry import register
from dospcot.tasks.sensor_tasks import MakeEnv, SensorTask

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig


@register
class HighwayTask(SensorTask):
    """A highway: an episode that lasts all its ``episode_steps`` (no crash) is a success."""

    name = "highway"
    section = "highway"

    def validate(self, cfg: TrainConfig) -> None:
        if cfg.highway.env_id not in (*HIGHWAY_ENV_IDS, FAST_HIGHWAY_ID):
            allowed = ", ".join((*HIGHWAY_ENV_IDS, FAST_HIGHWAY_ID))
            raise ConfigError(f"highway.env_id: unknown task {cfg.highway.env_id!r}; allowed: {allowed}")
        super().validate(cfg)

    def has_monitor(self, cfg: TrainConfig) -> bool:
        return cfg.highway.reveal_first_steps > 0

    def view_names(self, cfg: TrainConfig) -> tuple[str, ...]:
        return cfg.highway.view_names

    def check(self, cfg: TrainConfig) -> None:
        from dospcot.envs.fast_highway import FastHighwayEnv
        from dospcot.envs.masked_highway import try_highway_config

        highway = cfg.highway
        if highway.env_id == FAST_HIGHWAY_ID:
            check = FastHighwayEnv.check_overrides
        else:  # highway-env finds some bad values only when it resets and steps
            check = partial(try_highway_config, highway.env_id)
        try:
            check(highway.config)
        except ValueError as err:
            raise ConfigError(f"highway.config: {err}") from None
        super().check(cfg)

    def env_factories(self, cfg: TrainConfig) -> tuple[MakeEnv, MakeEnv]:
        from dospcot.envs.masked_highway import make_masked_highway

        highway = cfg.highway
        make_eval_env = partial(
            make_masked_highway,
            highway.env_id,
            config=highway.config,
            reveal_first_steps=highway.reveal_first_steps,
            queried=cfg.training.queries,
        )
        # A file rater's queries show frames: the training envs draw them, the evaluation envs need not.
        make_env = partial(make_eval_env, frames=cfg.training.rater == "file")
        return make_env, make_eval_env
