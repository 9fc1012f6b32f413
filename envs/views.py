"""Views: several observation functions of the same world, one per agent.

A view maps the env's underlying state to a feature vector. :class:`MultiViewWrapper` computes
every view of the current state at each step and puts them in ``info["views"]``, so that each
agent's reward classifier can score every transition.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np


@dataclass(frozen=True)
class View:
    """One observation function.

    :param name: the view's name, e.g. ``"coords"``.
    :param space: the ``Box`` its features live in.
    :param fn: maps the env's current state (an int for discrete envs) to a ``float32`` array of
        ``space.shape``.
    """

    name: str
    space: gym.spaces.Box
    fn: Callable[[Any], np.ndarray]


def select_views(available: Mapping[str, View], names: Sequence[str]) -> list[View]:
    """Return the views named in ``names``; raise ``ValueError`` naming the allowed ones."""
    if len(names) == 0:
        raise ValueError(f"views must name at least one view; allowed: {sorted(available)}")
    unknown = [name for name in names if name not in available]
    if unknown:
        raise ValueError(f"unknown view(s) {unknown}; allowed: {sorted(available)}")
    return [available[name] for name in names]


class MultiViewWrapper(gym.Wrapper):
    """Record every view of the state reached by ``reset`` and ``step`` in ``info["views"]``.

    The observation itself is unchanged (for the discrete envs: the state index).

    :param env: the env; ``state_fn(env)`` must return its current state.
    :param views: the views to compute.
    :param state_fn: reads the current state from the env, by default ``env.unwrapped.s``.
    """

    def __init__(
        self,
        env: gym.Env,
        views: Sequence[View],
        state_fn: Callable[[gym.Env], Any] | None = None,
    ) -> None:
        super().__init__(env)
        self.views = list(views)
        self._state_fn = state_fn or (lambda e: e.unwrapped.s)

    def _views(self) -> dict[str, np.ndarray]:
        state = self._state_fn(self.env)
        return {view.name: view.fn(state) for view in self.views}

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return obs, dict(info, views=self._views())

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, dict(info, views=self._views())


class ViewObservationWrapper(gym.ObservationWrapper):
    """Make one view the observation, for an agent that reads its own view only.

    :param env: the env; ``state_fn(env)`` must return its current state.
    :param view: the view to observe.
    :param state_fn: reads the current state from the env, by default ``env.unwrapped.s``.
    """

    def __init__(self, env: gym.Env, view: View, state_fn: Callable[[gym.Env], Any] | None = None) -> None:
        super().__init__(env)
        self.view = view
        self.observation_space = view.space
        self._state_fn = state_fn or (lambda e: e.unwrapped.s)

    def observation(self, observation: Any) -> np.ndarray:
        return self.view.fn(self._state_fn(self.env))
