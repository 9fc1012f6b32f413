"""Stop a run at the first NaN or infinite reward or observation, or at an error the env raises,
naming the env and the step."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


class NonFiniteError(RuntimeError):
    """An env returned a NaN or infinite reward or observation."""


class EnvRaisedError(RuntimeError):
    """An env raised while an agent reset or stepped it; the env's own error is the cause."""


class FiniteCheckWrapper(gym.Wrapper):
    """Raise :class:`NonFiniteError` when a step or reset returns a non-finite observation, reward or
    hidden reward (``info["hidden_reward"]``, which the reward classifiers train on).

    A NaN that reaches a replay buffer or a classifier poisons every later update without an error,
    so the run is stopped where the value appears, with the env's name, the step count and what
    was wrong.

    :param name: how the error names this env (e.g. the agent and its view). Steps are counted
        from the wrapper's creation (a resumed run counts from its resume).
    """

    def __init__(self, env: gym.Env, name: str = "") -> None:
        super().__init__(env)
        spec = env.unwrapped.spec
        self.name = name or (spec.id if spec is not None else type(env.unwrapped).__name__)
        self.steps = 0
        self.episode_steps = 0

    def reset(self, **kwargs: Any):
        try:
            obs, info = self.env.reset(**kwargs)
        except Exception as err:  # a user's env may raise anything: named, its error the cause
            raise EnvRaisedError(f"env {self.name} raised {type(err).__name__} at reset: {err}") from err
        self.episode_steps = 0
        self._check("observation", obs, "at reset")
        return obs, info

    def step(self, action: Any):
        step, in_episode = self.steps + 1, self.episode_steps + 1
        where = f"at env step {step} (step {in_episode} of its episode, action {action})"
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except Exception as err:  # a user's env may raise anything: named, its error the cause
            raise EnvRaisedError(f"env {self.name} raised {type(err).__name__} {where}: {err}") from err
        self.steps += 1
        self.episode_steps += 1
        self._check("reward", reward, where)
        if "hidden_reward" in info:
            self._check("hidden reward", info["hidden_reward"], where)
        self._check("observation", obs, where)
        return obs, reward, terminated, truncated, info

    def _check(self, what: str, value: Any, where: str) -> None:
        array = np.asarray(value)
        if array.dtype.kind in "fc" and not np.isfinite(array).all():
            bad = array.flat[np.flatnonzero(~np.isfinite(array))[0]]
            raise NonFiniteError(f"env {self.name} returned a non-finite {what} ({bad}) {where}")
