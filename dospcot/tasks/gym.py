"""The gym task (``task = "gym"``, the ``[gym]`` section): any gymnasium env with discrete actions,
its views computed from its observation (:mod:`dospcot.envs.gym_sensors`; docs/your_env.md). Every step
is one pool sample, or with ``gym.state_key`` every (state key, action) pair; the sensor adapter
(:mod:`dospcot.adapters.sensor_adapter`) pools them."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from dospcot.config.errors import ConfigError
from dospcot.tasks.registry import register
from dospcot.tasks.sensor_tasks import MakeEnv, SensorTask

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig


@register
class GymTask(SensorTask):
    """A gymnasium env: an episode whose true return exceeds ``gym.success_return`` is a success."""

    name = "gym"
    section = "gym"

    def view_names(self, cfg: TrainConfig) -> tuple[str, ...]:
        return tuple(cfg.gym.views)

    def validate(self, cfg: TrainConfig) -> None:
        gym = cfg.gym
        if not gym.env_id:
            raise ConfigError('gym.env_id: a task = "gym" run needs one (a gymnasium id or a dotted path)')
        if not gym.views:
            raise ConfigError(
                'gym.views: a task = "gym" run needs its views, e.g. views = {state = "observation"}'
            )
        super().validate(cfg)
        demos = cfg.demonstrations
        reads_ends = [key for key in ("read_termination", "episode_end_classes") if getattr(gym, key)]
        if (demos.file or demos.agent) and demos.labels and reads_ends:
            raise ConfigError(
                f"gym.{reads_ends[0]}: demonstrations do not record which of their steps ended an episode, "
                "so as labels they cannot join a pool that reads it; set demonstrations.labels = false"
            )

    def check(self, cfg: TrainConfig) -> None:
        from dospcot.envs.gym_sensors import check_gym_task

        gym = cfg.gym
        try:
            check_gym_task(
                gym.env_id, gym.env_kwargs, gym.wrappers, gym.views, gym.state_key, gym.train_wrappers
            )
        except ValueError as err:  # the cause stays: a user's env or view that raised
            raise ConfigError(str(err)) from err.__cause__
        super().check(cfg)

    def env_factories(self, cfg: TrainConfig) -> tuple[MakeEnv, MakeEnv]:
        from dospcot.envs.gym_sensors import make_masked_gym

        gym = cfg.gym
        make_eval_env = partial(
            make_masked_gym,
            gym.env_id,
            view_specs=gym.views,
            env_kwargs=gym.env_kwargs,
            wrappers=gym.wrappers,
            state_key=gym.state_key,
        )
        queried, frames = cfg.training.queries, cfg.training.rater == "file"
        make_env = partial(make_eval_env, train_wrappers=gym.train_wrappers, queried=queried, frames=frames)
        return make_env, make_eval_env
