"""Sensor views of a continuous world: several observations of the same state, one per agent.

A *sensor env* offers ``observe(name)`` (the view ``name`` of its current state) and
``view_space(name)``, either itself (:class:`dospcot.envs.FastHighwayEnv`) or through a wrapper
(:class:`dospcot.envs.highway.HighwayEnvSensors` around a highway-env env). :class:`SensorViewWrapper`
makes one view the agent's observation and records every view of the state reached in
``info["views"]``, so the co-trainer's store can give each view's reward classifier every step.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np


class SensorViewWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe one sensor view; put every view of the state reached in ``info["views"]``.

    :param env: a sensor env (``observe`` and ``view_space`` reachable through ``get_wrapper_attr``).
    :param view: the view the agent observes.
    :param views: the views recorded in ``info["views"]`` (by default only ``view``).
    """

    def __init__(self, env: gym.Env, view: str, views: Sequence[str] = ()) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, view=view, views=tuple(views))
        super().__init__(env)
        self._observe = env.get_wrapper_attr("observe")
        view_space = env.get_wrapper_attr("view_space")
        self.view = view
        self.views = tuple(views) or (view,)
        if view not in self.views:
            raise ValueError(f"the observed view {view!r} must be among the recorded views {self.views}")
        self.observation_space = view_space(view)
        for name in self.views:
            view_space(name)  # an unknown view fails here, naming the allowed ones

    def _views(self) -> dict[str, np.ndarray]:
        return {name: self._observe(name) for name in self.views}

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        _, info = self.env.reset(**kwargs)
        views = self._views()
        return views[self.view], dict(info, views=views)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        _, reward, terminated, truncated, info = self.env.step(action)
        views = self._views()
        return views[self.view], reward, terminated, truncated, dict(info, views=views)
