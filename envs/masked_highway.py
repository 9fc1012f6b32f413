"""highway-env with masked rewards and sensor views (the ``highway`` extra: ``pip install dospcot[highway]``).

Two sensors read the same simulated state every step, through highway-env's own observation types:

- ``kinematics``: ``Kinematics`` (5 x 5: presence, x, y, vx, vy of the ego and 4 nearby vehicles);
- ``occupancy``: ``OccupancyGrid`` (4 x 11 x 11: presence, vx, vy, on-road around the ego);
- ``ttc``: ``TimeToCollision`` (3 x 3 x 10: collision times per lane and speed), highway-env only.

Rewards are masked per transition (docs/design.md section 1): each step is revealed with probability
``label_fraction``, from a generator seeded by ``mask_seed``. Nothing here renders: the envs run
headless.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from dospcot.config.task_sections import FAST_HIGHWAY_ID, HIGHWAY_ENV_IDS, HIGHWAY_ENV_VIEWS, HighwayConfig
from dospcot.envs.fast_highway import FastHighwayEnv
from dospcot.envs.masking import RewardMaskWrapper
from dospcot.envs.sensors import SensorViewWrapper

HIGHWAY_VIEW_TYPES: dict[str, dict[str, Any]] = dict(
    zip(
        HIGHWAY_ENV_VIEWS,
        ({"type": "Kinematics"}, {"type": "OccupancyGrid"}, {"type": "TimeToCollision"}),
        strict=True,
    )
)
"""Each view's highway-env observation config (highway-env's defaults for that type)."""
# Keys the adapter owns: the views replace the observation, DQN needs the discrete meta-actions.
_OWNED_KEYS = {"observation": "set the views instead", "action": "agents need DiscreteMetaAction"}


def _import_highway_env() -> Any:
    try:
        import highway_env
    except ImportError:  # pragma: no cover - the extra is installed wherever tests run
        raise ImportError(
            "highway-env is not installed; install the extra: pip install 'dospcot[highway]'"
        ) from None
    gym.register_envs(highway_env)
    return highway_env


def check_highway_config(env_id: str, config: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``config`` as a dict if highway-env's ``env_id`` accepts every key of it.

    highway-env itself merges unknown keys silently; a typo would then change nothing. So an unknown
    key, or one the adapter owns (``observation``, ``action``), raises ``ValueError`` naming the
    allowed keys.
    """
    if env_id not in HIGHWAY_ENV_IDS:
        raise ValueError(f"unsupported highway-env task {env_id!r}; allowed: {', '.join(HIGHWAY_ENV_IDS)}")
    _import_highway_env()
    defaults = _default_config(env_id)
    allowed = sorted(set(defaults) - set(_OWNED_KEYS))
    for key, value in config.items():
        if key in _OWNED_KEYS:
            raise ValueError(f"highway config key {key!r} is set by dospcot ({_OWNED_KEYS[key]})")
        if key not in allowed:
            raise ValueError(f"{env_id} has no config key {key!r}; allowed: {', '.join(allowed)}")
        _check_type(key, value, defaults[key])
    return dict(config)


def try_highway_config(env_id: str, config: Mapping[str, Any]) -> None:
    """Raise ``ValueError`` if highway-env's ``env_id`` cannot reset and step with ``config``: values of
    the right type may still be out of range (``lanes_count = 0``), which highway-env finds only then."""
    check_highway_config(env_id, config)
    if not config:
        return
    try:
        env = gym.make(env_id, config=dict(config))
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.close()
    except Exception as err:  # highway-env raises whatever its maths hits
        reason = str(err).splitlines()[0] if str(err) else ""
        raise ValueError(f"{env_id} cannot run with {dict(config)}: {type(err).__name__}: {reason}") from None


def _check_type(key: str, value: Any, default: Any) -> None:
    """``value`` must have the type of highway-env's default (any number where that is a number)."""
    if default is None:
        return
    if isinstance(default, bool):
        kind, ok = "true or false", isinstance(value, bool)
    elif isinstance(default, int | float):  # an int default may stand for a number (vehicles_density = 1)
        kind, ok = "a number", not isinstance(value, bool) and isinstance(value, int | float)
    elif isinstance(default, list | tuple):
        kind, ok = "a list", isinstance(value, list | tuple)
    else:
        kind, ok = f"a {type(default).__name__}", isinstance(value, type(default))
    if not ok:
        raise ValueError(f"{key} must be {kind} (highway-env's default is {default!r}), got {value!r}")


def _default_config(env_id: str) -> dict[str, Any]:
    creator = gym.envs.registration.load_env_creator(gym.spec(env_id).entry_point)
    return creator.default_config()


def check_views(env_id: str, views: Sequence[str]) -> None:
    """Raise ``ValueError`` for a view the task ``env_id`` lacks, naming the allowed ones."""
    allowed = HighwayConfig(env_id=env_id).view_names
    for view in views:
        if view not in allowed:
            raise ValueError(f"{env_id} has no view {view!r}; allowed: {', '.join(allowed)}")


class HighwayEnvSensors(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Give a highway-env env the sensor interface: ``observe(name)`` and ``view_space(name)``.

    Each view is a highway-env observation type built on the unwrapped env, so it reads the same
    state as the env's own observation.

    :param env: a highway-env env (e.g. ``gym.make("highway-fast-v0")``).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        super().__init__(env)
        from highway_env.envs.common.observation import observation_factory

        self._sensors = {
            name: observation_factory(env.unwrapped, dict(config))
            for name, config in HIGHWAY_VIEW_TYPES.items()
        }

    def _sensor(self, name: str) -> Any:
        if name not in self._sensors:
            raise ValueError(f"unknown view {name!r}; allowed: {', '.join(self._sensors)}")
        return self._sensors[name]

    def view_space(self, name: str) -> gym.spaces.Box:
        """The ``Box`` of a view."""
        sensor = self._sensor(name)
        if name == "ttc":  # its space() observes, which needs a road: the shape is known up front
            horizon = int(sensor.horizon * self.env.unwrapped.config["policy_frequency"])
            return gym.spaces.Box(0.0, 1.0, (3, 3, horizon), np.float32)
        return sensor.space()

    def observe(self, name: str) -> np.ndarray:
        """The view ``name`` of the current state, float32 of ``view_space(name).shape``."""
        return np.asarray(self._sensor(name).observe(), dtype=np.float32)


def make_highway(
    env_id: str = "highway-fast-v0", config: Mapping[str, Any] | None = None, frames: bool = False
) -> gym.Env:
    """A sensor env: highway-env's ``env_id`` (checked ``config`` applied) or our fast env; with
    ``frames``, highway-env's is made with render mode ``"rgb_array"`` (ours draws nothing)."""
    if env_id == FAST_HIGHWAY_ID:
        return FastHighwayEnv(**dict(config or {}))
    cfg = check_highway_config(env_id, config or {})
    return HighwayEnvSensors(gym.make(env_id, config=cfg, render_mode="rgb_array" if frames else None))


def make_masked_highway(
    env_id: str = "highway-fast-v0",
    view: str = "kinematics",
    views: Sequence[str] = ("kinematics", "occupancy"),
    label_fraction: float = 0.1,
    mask_seed: int = 0,
    config: Mapping[str, Any] | None = None,
    reveal_first_steps: int = 0,
    queried: bool = False,
    frames: bool = False,
) -> gym.Env:
    """A highway task whose rewards are revealed per transition with probability ``label_fraction``.

    :param env_id: a highway-env task of :data:`HIGHWAY_ENV_IDS` or :data:`FAST_HIGHWAY_ID`.
    :param view: the view the agent observes.
    :param views: every view recorded in ``info["views"]``.
    :param label_fraction: probability that a step's reward is revealed, in (0, 1].
    :param mask_seed: seed of the reveal draws.
    :param config: the task's config overrides (highway-env's keys, or :class:`FastHighwayConfig`'s).
    :param reveal_first_steps: a reward monitor: the first this many steps of every episode are revealed.
    :param queried: reward queries buy the labels: a ``label_fraction`` of 0 is allowed.
    :param frames: make highway-env's env able to draw itself (:func:`make_highway`).
    """
    check_views(env_id, views)
    env = RewardMaskWrapper(
        make_highway(env_id, config, frames),
        label_fraction,
        mode="transition",
        mask_seed=mask_seed,
        reveal_first_steps=reveal_first_steps,
        queried=queried,
    )
    return SensorViewWrapper(env, view, views)
