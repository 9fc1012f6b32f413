"""Sensor views of a continuous world: several observations of the same state, one per agent.

A *sensor env* offers ``observe(name)`` (the view ``name`` of its current state) and
``view_space(name)``, either itself (:class:`dospcot.envs.FastHighwayEnv`) or through a wrapper
(:class:`dospcot.envs.masked_highway.HighwayEnvSensors` around a highway-env env). :class:`SensorViewWrapper`
makes one view the agent's observation and records every view of the state reached in
``info["views"]``, so the co-trainer's store can give each view's reward classifier every step.
With ``lazy_views`` they are computed when read instead (:class:`StepViews`): a store keyed by
(state, action) pairs keeps only a pair's first visit, and a view such as MiniGrid's full map costs
as much as the step itself.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np


class StepViews(Mapping[str, np.ndarray]):
    """Every view of the state one step (or reset) reached, each computed on its first read.

    Valid until the env steps or resets again: a view read after that would describe a later state, so
    reading one not yet computed then raises ``RuntimeError``. Read what a step needs before the next.

    :param observe: ``observe(name)``, the view ``name`` of the env's current state.
    :param names: the views offered.
    """

    def __init__(self, observe: Callable[[str], np.ndarray], names: Sequence[str]) -> None:
        self._observe, self._names = observe, tuple(names)
        self._values: dict[str, np.ndarray] = {}
        self.current = True
        """Whether the env is still in the state these views describe."""

    def __getitem__(self, name: str) -> np.ndarray:
        value = self._values.get(name)
        if value is None:
            if name not in self._names:
                raise KeyError(name)
            if not self.current:
                raise RuntimeError(
                    f"view {name!r} was not read before the env stepped on: read a step's views before "
                    "the next step"
                )
            value = self._values[name] = self._observe(name)
        return value

    def __deepcopy__(self, memo: dict[int, Any]) -> StepViews:
        """A copy of the views read so far, never of the env: SB3's ``DummyVecEnv`` deep-copies every
        step's infos, and copying ``observe``'s env with them cost a whole env's copy per step. The
        copy is not current, so a view not read before the copy raises rather than describe a state the
        copy never saw."""
        views = StepViews(self._observe, self._names)
        views._values = {name: value.copy() for name, value in self._values.items()}
        views.current = False
        return views

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


class SensorViewWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe one sensor view; record every view of the state reached in ``info["views"]``.

    :param env: a sensor env (``observe`` and ``view_space`` reachable through ``get_wrapper_attr``).
    :param view: the view the agent observes.
    :param views: the views recorded in ``info["views"]`` (by default only ``view``).
    :param lazy_views: ``info["views"]`` is a :class:`StepViews`, each view computed when first read
        and readable only until the next step (the pool store's wrapper sets it); False: a dict of
        every view, computed at the step (what gymnasium's env checker can compare across steps).
    """

    def __init__(self, env: gym.Env, view: str, views: Sequence[str] = (), lazy_views: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, view=view, views=tuple(views), lazy_views=lazy_views)
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

        self.lazy_views = lazy_views
        self._last: StepViews | None = None

    def _views(self) -> Mapping[str, np.ndarray]:
        if not self.lazy_views:
            return {name: self._observe(name) for name in self.views}
        if self._last is not None:
            self._last.current = False
        self._last = StepViews(self._observe, self.views)
        return self._last

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        _, info = self.env.reset(**kwargs)
        views = self._views()
        return views[self.view], dict(info, views=views)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        _, reward, terminated, truncated, info = self.env.step(action)
        views = self._views()
        return views[self.view], reward, terminated, truncated, dict(info, views=views)
