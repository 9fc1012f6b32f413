"""Any gymnasium env with discrete actions as a sensor task: views computed from its observation.

A view is a function of the env's observation that returns a fixed-shape array, e.g. a lidar reading
or the agent's position. :class:`ObservationSensors` gives an env the sensor interface that
:class:`~dospcot.envs.SensorViewWrapper` reads (``observe(name)``, ``view_space(name)``), so a user's
env co-trains like the highway tasks: one agent per view, every step one pool sample. An env whose
states can be named (a state key, :data:`STATE_KEYS` or a function of the env) pools (state, action)
pairs instead, as on the grid, masked per pair (:class:`~dospcot.envs.RewardMaskWrapper`'s ``"key"``
mode).

A view is named in a config by one of (:func:`resolve_view`):

- ``"observation"``: the whole observation, flattened (:data:`VIEW_REGISTRY`; a ``Discrete`` one
  one-hot);
- a key of a ``Dict`` observation space, e.g. ``"image"``: that entry, flattened;
- a dotted path ``"package.module:function"``: the function, imported when the env is built;
- ``"minigrid.full"``, ``"minigrid.position"``: MiniGrid's map and the agent's pose, read from the env
  (:mod:`dospcot.envs.minigrid_views`).

An env is named by a registered gymnasium id, or by a dotted path to a function that returns the env
(:func:`make_gym_env`). Wrappers are gymnasium's by class name (``"FlattenObservation"``) or any
wrapper class by dotted path.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Hashable, Mapping, Sequence
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator

from dospcot.envs import minigrid_views
from dospcot.envs.masking import RewardMaskWrapper
from dospcot.envs.sensors import SensorViewWrapper

ViewFn = Callable[[Any], np.ndarray]
"""A view: the env's observation in, an array of a fixed shape out."""
StateKeyFn = Callable[[gym.Env], Hashable]
"""A state key: the unwrapped env in, a hashable name of its current state out."""


STATE_KEYS: dict[str, StateKeyFn] = {"minigrid": minigrid_views.state_key}
"""State keys by name (a config may also name a function by its dotted path)."""

VIEW_REGISTRY: dict[str, Callable[[gym.Space], ViewFn]] = {
    "observation": lambda space: partial(gym.spaces.flatten, space),
}
"""Views by name that any env offers, each made from the env's observation space: ``observation`` is
the whole observation as gymnasium's ``flatten`` gives it (a ``Discrete`` one one-hot)."""


def import_dotted(path: str, what: str) -> Any:
    """The object at ``"package.module:name"`` (``name`` may hold dots, for a class attribute).

    :param what: what the path names, for the error message, e.g. ``"gym.views.lidar"``.
    """
    module_name, sep, attr = path.partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"{what}: {path!r} is not a dotted path of the form 'package.module:name'")
    try:
        target: Any = importlib.import_module(module_name)
    except ImportError as err:
        raise ValueError(
            f"{what}: cannot import module {module_name!r} ({err}); a module of your own must be "
            "importable from where dospcot runs (its folder on PYTHONPATH), not only beside the config"
        ) from None
    for part in attr.split("."):
        if not hasattr(target, part):
            raise ValueError(f"{what}: module {module_name!r} has no {attr!r}")
        target = getattr(target, part)
    return target


def import_callable(path: str, what: str) -> Callable[..., Any]:
    """The function or class at the dotted path ``path`` (:func:`import_dotted`); a ``ValueError`` if
    it is not callable."""
    fn = import_dotted(path, what)
    if not callable(fn):
        raise ValueError(f"{what}: {path!r} is not callable")
    return fn


def dotted_path(obj: Any, what: str) -> str:
    """The dotted path ``"module:qualname"`` that :func:`import_dotted` reads back as ``obj``, or a
    ``ValueError`` if there is none (a lambda, a nested function, a bound method)."""
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if not module or not qualname or "<" in qualname:
        raise ValueError(
            f"{what}: {obj!r} cannot be named by a dotted path: define it at the top level of a module"
        )
    path = f"{module}:{qualname}"
    if import_dotted(path, what) is not obj:
        raise ValueError(f"{what}: {path!r} does not import back as {obj!r}: define it at module level")
    return path


def resolve_view(spec: str, env: gym.Env, name: str) -> ViewFn:
    """The view function that ``spec`` names for ``env`` (a :data:`VIEW_REGISTRY` name, a view of
    :data:`~dospcot.envs.minigrid_views.ENV_VIEWS`, a ``Dict`` key or a dotted path; see the module
    docstring)."""
    observation_space = env.observation_space
    if spec in VIEW_REGISTRY:
        return VIEW_REGISTRY[spec](observation_space)
    if spec in minigrid_views.ENV_VIEWS:
        read = minigrid_views.ENV_VIEWS[spec]
        return lambda obs: read(env.unwrapped)
    if ":" in spec:
        return import_callable(spec, f"gym.views.{name}")
    if isinstance(observation_space, gym.spaces.Dict):
        if spec in observation_space.spaces:
            return lambda obs: obs[spec]
        keys = ", ".join(observation_space.spaces)
        raise ValueError(
            f"gym.views.{name}: {spec!r} is not a key of the observation ({keys}), a dotted path "
            f"'module:function' or one of {_named_views()}"
        )
    raise ValueError(
        f"gym.views.{name}: {spec!r} is neither a dotted path 'module:function' nor one of "
        f"{_named_views()} (the observation is not a Dict, so keys do not apply)"
    )


def _named_views() -> str:
    return ", ".join([*VIEW_REGISTRY, *minigrid_views.ENV_VIEWS])


def require_discrete_actions(env: gym.Env) -> None:
    """Raise ``ValueError`` unless ``env``'s actions are ``Discrete``, which Q-learning agents need."""
    if not isinstance(env.action_space, gym.spaces.Discrete):
        raise ValueError(
            f"{env.spec.id if env.spec else type(env.unwrapped).__name__} has a "
            f"{type(env.action_space).__name__} action space: DOSPCoT's Q-learning agents need "
            "Discrete actions (discretise the actions with a wrapper)"
        )


def resolve_state_key(spec: str) -> StateKeyFn:
    """The state-key function ``spec`` names: a name from :data:`STATE_KEYS` or a dotted path."""
    if spec in STATE_KEYS:
        return STATE_KEYS[spec]
    if ":" not in spec:
        raise ValueError(
            f"gym.state_key: {spec!r} is neither one of {sorted(STATE_KEYS)} nor a dotted path "
            "'module:function'"
        )
    return import_callable(spec, "gym.state_key")


class ObservationSensors(gym.Wrapper):
    """Give an env with ``Discrete`` actions the sensor interface: each view a function of the last
    observation, flattened: to uint8 where the view gives uint8 or bool values, else to float32. A
    view of bool values has the space ``Box(0, 1)`` (a replay buffer stores it as bits), one of uint8
    values ``Box(0, 255)``.

    Each view's shape is read from the observation of a reset (seed 0) at construction; a view that
    raises, returns a non-numeric value or changes shape later fails with one line naming it.

    :param env: the env.
    :param views: the view functions, by name.
    :param state_key: a function of the unwrapped env that names its current state by a hashable key
        (read by :class:`~dospcot.envs.RewardMaskWrapper` in ``"key"`` mode through :meth:`state_key`);
        None: the states have no names.
    """

    def __init__(
        self, env: gym.Env, views: Mapping[str, ViewFn], state_key: StateKeyFn | None = None
    ) -> None:
        super().__init__(env)
        require_discrete_actions(env)
        if not views:
            raise ValueError("need at least one view")
        self._fns = dict(views)
        self._key_fn = state_key
        try:
            self._obs, _ = env.reset(seed=0)
        except Exception as err:  # a user's env may raise anything
            raise ValueError(f"the env's reset failed: {type(err).__name__}: {err}") from err
        if not env.observation_space.contains(self._obs):
            shape, dtype = np.shape(self._obs), getattr(self._obs, "dtype", type(self._obs).__name__)
            raise ValueError(
                f"the env's first observation (shape {shape}, {dtype}) does not fit its observation_space "
                f"{env.observation_space}; an agent would learn from values its space does not allow"
            )
        self._spaces = {}
        for name in self._fns:
            value, kind = self._read(name)
            low, high = {"bool": (0, 1), "uint8": (0, 255)}.get(kind, (-np.inf, np.inf))
            self._spaces[name] = gym.spaces.Box(low, high, value.shape, value.dtype)
        if state_key is not None:
            self.state_key()  # an unhashable key fails here, before anything trains

    def state_key(self) -> str:
        """The current state's name: the ``repr`` of its key. Keys are told apart by their ``repr``
        (the mask hashes it, :func:`~dospcot.envs.masking.key_is_labelled`), so the store and the mask
        always agree: ``3`` and ``3.0`` are two states, and a key should be a tuple of plain values
        (ints, strings, bytes) whose ``repr`` is the same in every process, unlike a set's."""
        if self._key_fn is None:
            raise ValueError("this env has no state key")
        try:
            key = self._key_fn(self.env.unwrapped)
        except Exception as err:  # a user's function may raise anything
            raise ValueError(f"gym.state_key failed on the env: {type(err).__name__}: {err}") from None
        try:
            hash(key)
        except TypeError:
            raise ValueError(
                f"gym.state_key returned an unhashable {type(key).__name__} ({key!r}); a key must be "
                "hashable, best a tuple of plain values"
            ) from None
        return repr(key)

    def _read(self, name: str) -> tuple[np.ndarray, str]:
        """The view ``name`` of the last observation, flat: uint8 where the view gives uint8 or bool
        values (MiniGrid's image and indicator maps: a quarter of float32's memory in the store and
        the replay buffers, and the same floats where read, as a network reads them through
        ``float()``), float32 otherwise; and the kind of values the view gave ("bool", "uint8" or
        "float")."""
        try:
            raw = self._fns[name](self._obs)
            value = np.asarray(raw)
            kind = {np.dtype(bool): "bool", np.dtype(np.uint8): "uint8"}.get(value.dtype, "float")
            value = np.asarray(raw, dtype=np.float32 if kind == "float" else np.uint8)
        except Exception as err:  # a user's function may raise anything: named, its error the cause
            raise ValueError(f"view {name!r} failed on an observation: {type(err).__name__}: {err}") from err
        if raw is None:
            raise ValueError(f"view {name!r} returned None; a view returns an array of numbers")
        return value.ravel(), kind

    def view_space(self, name: str) -> gym.spaces.Box:
        """The flat ``Box`` of a view."""
        if name not in self._spaces:
            raise ValueError(f"unknown view {name!r}; allowed: {', '.join(self._spaces)}")
        return self._spaces[name]

    def observe(self, name: str) -> np.ndarray:
        """The view ``name`` of the last observation, of ``view_space(name)``'s shape and type."""
        (value, kind), space = self._read(name), self.view_space(name)
        if value.shape != space.shape:
            raise ValueError(
                f"view {name!r} changed shape: {space.shape[0]} values at the first "
                f"reset, {value.size} now; a view must return the same shape on every observation"
            )
        if value.dtype != space.dtype or (space.high.max() == 1 and kind != "bool"):
            first = "bool" if space.high.max() == 1 else space.dtype
            raise ValueError(
                f"view {name!r} changed type: {first} at the first reset, {kind} now; a view must return "
                "values of one type (uint8 or bool, stored as uint8; any other, as float32)"
            )
        return value

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self._obs, info = self.env.reset(**kwargs)
        return self._obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self._obs, reward, terminated, truncated, info = self.env.step(action)
        return self._obs, reward, terminated, truncated, info


def make_gym_env(
    env_id: str,
    env_kwargs: Mapping[str, Any] | None = None,
    wrappers: Sequence[str] = (),
    train_wrappers: Sequence[str] = (),
    frames: bool = False,
) -> gym.Env:
    """The env ``env_id`` names, built with ``env_kwargs`` and wrapped by ``train_wrappers``, then
    ``wrappers``, in order (the first named is the innermost).

    :param env_id: a registered gymnasium id; ``"package:Env-v0"`` (gymnasium's own form) imports the
        package that registers it first; ``"package.module:function"`` calls a function that returns
        the env.
    :param frames: a registered env that lists the render mode ``"rgb_array"`` is made with it, so
        that it can draw the frames a person is shown (a function's env draws them if it was made so).
    """
    kwargs = dict(env_kwargs or {})
    module, sep, name = env_id.partition(":")
    factory = import_dotted(env_id, "gym.env_id") if sep and not _registers(module, name) else None
    if factory is not None:
        if not callable(factory):
            raise ValueError(f"gym.env_id: {env_id!r} is neither a registered env id nor callable")
        try:
            env = factory(**kwargs)
        except TypeError as err:  # an env_kwargs key the function does not take
            raise ValueError(f"gym.env_kwargs: {err}") from None
        except Exception as err:  # a user's function may raise anything: named, its error the cause
            raise ValueError(f"gym.env_id: {env_id} raised {type(err).__name__}: {err}") from err
        if not isinstance(env, gym.Env):
            raise ValueError(f"gym.env_id: {env_id!r} returned a {type(env).__name__}, not a gymnasium Env")
    else:
        registered = name if sep else env_id
        if frames and "rgb_array" in _render_modes(registered):
            kwargs["render_mode"] = "rgb_array"
        try:
            env = gym.make(registered, **kwargs)
        except gym.error.Error as err:
            raise ValueError(f"gym.env_id: {err}") from None
        except TypeError as err:  # an env_kwargs key the env does not take
            raise ValueError(f"gym.env_kwargs: {err}") from None
    # Training-only wrappers innermost: an exploring start moves the agent in the env itself, before
    # any observation wrapper reads it.
    for key, names in (("gym.train_wrappers", train_wrappers), ("gym.wrappers", wrappers)):
        for wrapper in names:
            env = _wrap(env, wrapper, key)
    return env


def _wrap(env: gym.Env, wrapper: str, key: str) -> gym.Env:
    cls = import_dotted(wrapper, key) if ":" in wrapper else getattr(gym.wrappers, wrapper, None)
    if cls is None:
        raise ValueError(
            f"{key}: gymnasium.wrappers has no {wrapper!r}; name another wrapper by its dotted path "
            "'module:Class'"
        )
    try:
        return cls(env)
    except TypeError as err:  # a wrapper that needs more than the env
        raise ValueError(f"{key}: {wrapper} cannot wrap the env by itself ({err})") from None


def _render_modes(env_id: str) -> list[str]:
    """The render modes a registered env's class lists, read without building it (none if unknown)."""
    try:
        entry = gym.spec(env_id).entry_point
    except gym.error.Error:  # gym.make names the problem
        return []
    creator = entry if callable(entry) else load_env_creator(entry)
    return list(getattr(creator, "metadata", {}).get("render_modes", []))


def _registers(module: str, env_id: str) -> bool:
    """Whether importing ``module`` registers the gymnasium id ``env_id``."""
    try:
        importlib.import_module(module)
    except ImportError as err:
        raise ValueError(f"gym.env_id: cannot import module {module!r} ({err})") from None
    return env_id in gym.registry


def check_gym_task(
    env_id: str,
    env_kwargs: Mapping[str, Any],
    wrappers: Sequence[str],
    view_specs: Mapping[str, str],
    state_key: str = "",
    train_wrappers: Sequence[str] = (),
) -> None:
    """Build the task once and read every view of a reset; raise ``ValueError`` with one line naming
    what is wrong (an unknown id or path, continuous actions, a view that fails)."""
    make_gym_sensors(
        env_id, view_specs, tuple(view_specs), env_kwargs, wrappers, state_key, train_wrappers
    ).close()


def make_gym_sensors(
    env_id: str,
    view_specs: Mapping[str, str],
    views: Sequence[str],
    env_kwargs: Mapping[str, Any] | None = None,
    wrappers: Sequence[str] = (),
    state_key: str = "",
    train_wrappers: Sequence[str] = (),
    frames: bool = False,
) -> ObservationSensors:
    """The env ``env_id`` names (:func:`make_gym_env`, which reads ``frames``) with the sensor interface
    for ``views``, each resolved from ``view_specs`` (:func:`resolve_view`), and the state key
    ``state_key`` names (empty: none)."""
    unknown = [name for name in views if name not in view_specs]
    if unknown:
        raise ValueError(f"unknown view(s) {unknown}; allowed: {', '.join(view_specs)}")
    env = make_gym_env(env_id, env_kwargs, wrappers, train_wrappers, frames)
    try:
        # Before the views: an env with continuous actions is refused for that, whatever its views.
        require_discrete_actions(env)
        fns = {name: resolve_view(view_specs[name], env, name) for name in views}
        return ObservationSensors(env, fns, resolve_state_key(state_key) if state_key else None)
    except Exception:  # whatever failed, the env is not handed out: close it
        env.close()
        raise


def make_masked_gym(
    env_id: str,
    view: str,
    views: Sequence[str],
    label_fraction: float,
    mask_seed: int = 0,
    *,
    view_specs: Mapping[str, str],
    env_kwargs: Mapping[str, Any] | None = None,
    wrappers: Sequence[str] = (),
    state_key: str = "",
    train_wrappers: Sequence[str] = (),
    queried: bool = False,
    frames: bool = False,
) -> gym.Env:
    """A gymnasium task whose rewards are revealed per step with probability ``label_fraction``.

    :param env_id: a registered gymnasium id, or a dotted path to a function returning the env.
    :param view: the view the agent observes.
    :param views: every view recorded in ``info["views"]``.
    :param label_fraction: probability that a step's reward is revealed (with ``state_key``: that a
        (state, action) pair's is, for all its visits), in (0, 1].
    :param mask_seed: seed of the reveal draws (with ``state_key``: of the pairs' hash).
    :param view_specs: what each view name means (:func:`resolve_view`).
    :param env_kwargs: keyword arguments of the env.
    :param wrappers: wrappers applied to the env before the views read it.
    :param train_wrappers: wrappers applied inside ``wrappers`` (training envs: evaluation leaves them
        out), e.g. :class:`~dospcot.envs.minigrid_views.RandomStart`.
    :param state_key: a name from :data:`STATE_KEYS` or a dotted path to a function of the unwrapped
        env: the mask then labels (state key, action) pairs (``"key"`` mode); empty: single steps.
    :param queried: reward queries buy the labels: a ``label_fraction`` of 0 is allowed.
    :param frames: make a registered env that can draw itself with render mode ``"rgb_array"``.
    """
    sensors = make_gym_sensors(
        env_id, view_specs, views, env_kwargs, wrappers, state_key, train_wrappers, frames
    )
    mask = RewardMaskWrapper(
        sensors,
        label_fraction,
        mode="key" if state_key else "transition",
        mask_seed=mask_seed,
        queried=queried,
    )
    return SensorViewWrapper(mask, view, views)


__all__ = [
    "STATE_KEYS",
    "VIEW_REGISTRY",
    "ObservationSensors",
    "check_gym_task",
    "dotted_path",
    "import_callable",
    "import_dotted",
    "make_gym_env",
    "make_gym_sensors",
    "make_masked_gym",
    "resolve_state_key",
    "resolve_view",
]
