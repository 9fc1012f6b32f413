"""The sensor adapter's stores (:mod:`dospcot.adapters.sensor_adapter`): every step the agents of a run took,
with every view of s and s' (:class:`StepStore`), or each (state key, action) pair once
(:class:`KeyedStepStore`), and the wrapper that writes an agent's steps into one
(:class:`SensorStoreWrapper`)."""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from dospcot.policies.in_place_state import InPlaceState
from dospcot.raters.file_rater import encode_png


class StepStore(InPlaceState):
    """Every step the agents of one run took, one pool sample each, with every view of s and s'.

    A state reading is stored once as a *row*: a step refers to the row of its s (the reset's or the
    previous step's s') and of its s', so consecutive steps share rows.

    :param view_shapes: the shape of each view, by name.
    :param view_dtypes: the type each view's rows are stored as, by name (a view the env gives as
        uint8 is stored as uint8: a quarter of float32's memory, the same floats in :meth:`features`);
        float32 for a view it does not name.
    """

    STEP_ARRAYS = (
        "state_row",
        "next_row",
        "action",
        "labelled",
        "terminal",
        "truncated",
        "label_value",
        "hidden_reward",
    )
    """The arrays that hold one entry per step."""

    def __init__(
        self, view_shapes: dict[str, tuple[int, ...]], view_dtypes: Mapping[str, Any] | None = None
    ) -> None:
        dtypes = view_dtypes or {}
        self.rows = {
            name: np.zeros((0, int(np.prod(shape))), dtypes.get(name, np.float32))
            for name, shape in view_shapes.items()
        }
        self._n_rows = 0
        self._n = 0
        self.state_row = np.zeros(0, np.int64)
        self.next_row = np.zeros(0, np.int64)
        self.action = np.zeros(0, np.int64)
        self.labelled = np.zeros(0, bool)
        self.terminal = np.zeros(0, bool)
        """Whether each step ended its episode (the env's ``terminated``, which the mask leaves visible)."""
        self.truncated = np.zeros(0, bool)
        """Whether the time limit cut each step's episode there (read by the reward queries)."""
        self.frames: dict[int, bytes] = {}
        """A PNG of the state of each row, where the env draws itself for a person (a file rater)."""
        self.label_value = np.zeros(0)
        self.hidden_reward = np.zeros(0)
        """The true reward of each step: metrics only, never the learners."""
        self._features: dict[tuple[str, int, bool, np.dtype], tuple[np.ndarray, int]] = {}
        """:meth:`features` of the steps built so far, by its arguments, with their count: a stored step's
        features never change, and a score pass asks for the pool's ten times a round."""

    def state_dict(self) -> dict[str, Any]:
        """:meth:`InPlaceState.state_dict` without the features built so far, which the steps rebuild."""
        state = super().state_dict()
        del state["_features"]
        return state

    def __len__(self) -> int:
        return self._n

    @property
    def n_rows(self) -> int:
        """The state readings stored (each view once per reading)."""
        return self._n_rows

    def add_row(self, views: dict[str, np.ndarray]) -> int:
        """Store one state reading (every view); return its row."""
        if self._n_rows == len(next(iter(self.rows.values()))):
            grow = max(1024, self._n_rows)
            self.rows = {name: _grow(rows, grow) for name, rows in self.rows.items()}
        for name, rows in self.rows.items():
            rows[self._n_rows] = np.ravel(views[name])
        self._n_rows += 1
        return self._n_rows - 1

    def add(
        self,
        state_row: int,
        action: int,
        next_row: int,
        observed: bool,
        reward: float,
        hidden: float,
        key: Hashable = None,
        ends: tuple[bool, bool] = (False, False),
    ) -> int:
        """Record one step between two stored rows (``ends``: whether it ended its episode, whether the
        time limit cut it); return its store id: a new one, unless the step revisits a sample (a
        :class:`KeyedStepStore`'s pair named by ``key`` and ``action``), whose label and hidden reward
        it then updates."""
        n = self.sample_of(key, action)
        if n is not None:
            if observed:  # the mask labels every visit of a pair or none
                self.label_value[n] = reward
            self.hidden_reward[n] = hidden
            return n
        if self._n == self.action.size:
            grow = max(1024, self._n)
            for name in self.STEP_ARRAYS:
                setattr(self, name, _grow(getattr(self, name), grow))
        n = self._n
        self.state_row[n], self.action[n], self.next_row[n] = state_row, action, next_row
        self.terminal[n], self.truncated[n] = ends
        self.labelled[n], self.label_value[n], self.hidden_reward[n] = (
            observed,
            reward if observed else 0.0,
            hidden,
        )
        self._n += 1
        self.first_visit(key, action, n)
        return n

    def sample_of(self, key: Hashable, action: int) -> int | None:
        """The sample a step of ``action`` from the state named ``key`` revisits: none here."""
        return None

    def first_visit(self, key: Hashable, action: int, n: int) -> None:
        """Note that sample ``n`` is the step of ``action`` from the state named ``key``."""

    def load_state_dict(self, state: dict[str, Any]) -> None:
        # A checkpoint from before ``terminal`` or ``truncated`` was stored: no run of that code read it.
        unread = {name: np.zeros(state["action"].size, bool) for name in ("terminal", "truncated")}
        super().load_state_dict({**unread, **state})
        self._features = {}

    def is_new(self, key: Hashable, action: int) -> bool:
        """Whether a step of ``action`` from the state named ``key`` starts a new sample."""
        return self.sample_of(key, action) is None

    def features(
        self, view: str, n_actions: int, termination: bool = False, dtype: type = np.float32
    ) -> np.ndarray:
        """(len, 2 d + A) in ``dtype`` (float32 or float64, whatever the rows' type): view of s, one-hot
        action, view of s' of every step; with ``termination``, (len, 2 d + A + 1): then whether the
        step ended its episode (0 or 1). The views' values are float32's in either ``dtype``.

        Only the steps stored since the last call with the same arguments are built: the array returned
        is a view of the features kept for the next call, so a caller reads it and never writes it."""
        key, n = (view, n_actions, termination, np.dtype(dtype)), self._n
        kept, built = self._features.get(key, (None, 0))
        if kept is None or kept.shape[0] < n:
            # Room for twice the steps: a copy each time the store doubles, not each call; np.empty's pages
            # take memory only once rows are written to them.
            grown = np.empty((2 * n, self._feature_width(view, n_actions, termination)), dtype)
            if kept is not None:
                grown[:built] = kept[:built]
            kept = grown
        if built < n:
            kept[built:n] = self._build_features(view, n_actions, termination, dtype, built, n)
        self._features[key] = (kept, n)
        return kept[:n]

    def _feature_width(self, view: str, n_actions: int, termination: bool) -> int:
        return 2 * self.rows[view].shape[1] + n_actions + int(termination)

    def _build_features(
        self, view: str, n_actions: int, termination: bool, dtype: type, start: int, stop: int
    ) -> np.ndarray:
        """:meth:`features` of the steps ``start`` to ``stop`` (not included), built from the rows."""
        rows, steps = self.rows[view], slice(start, stop)
        onehot = np.eye(n_actions, dtype=dtype)[self.action[steps]]
        state, next_state = (_as_float32_values(rows[r[steps]]) for r in (self.state_row, self.next_row))
        parts = [state, onehot, next_state]
        if termination:
            parts.append(self.terminal[steps, None].astype(dtype))
        return np.concatenate(parts, axis=1, dtype=dtype)


class KeyedStepStore(StepStore):
    """A :class:`StepStore` whose samples are (state key, action) pairs, as on the grid: every visit of
    a pair returns the pair's id, so the pool holds each pair once. The mask labels a pair for all its
    visits or none (mode ``"key"``): a labelled pair's steps train on their own revealed rewards, an
    unlabelled pair's steps all read the pair's pseudo-reward. A pair keeps the views of s and s' of
    its first visit (later visits store none); its label is the reward of its latest visit, its hidden
    reward its latest (metrics only).

    :param view_shapes: the shape of each view, by name.
    :param view_dtypes: the type of each view's rows, as for :class:`StepStore`.
    """

    def __init__(
        self, view_shapes: dict[str, tuple[int, ...]], view_dtypes: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(view_shapes, view_dtypes)
        self.ids: dict[tuple[Hashable, int], int] = {}
        """The store id of each (state key, action) pair seen."""

    def sample_of(self, key: Hashable, action: int) -> int | None:
        """The pair's id, once it was visited: a revisit reads no rows (nor whether it ended its episode)."""
        return self.ids.get((key, action))

    def first_visit(self, key: Hashable, action: int, n: int) -> None:
        self.ids[key, action] = n


def _as_float32_values(rows: np.ndarray) -> np.ndarray:
    """``rows`` rounded to float32 where their type is a wider float (an env's float64 view), so that a
    sample's classifier inputs hold the same values whichever dtype they are built in."""
    return rows.astype(np.float32) if rows.dtype.kind == "f" and rows.dtype.itemsize > 4 else rows


def _grow(array: np.ndarray, extra: int) -> np.ndarray:
    return np.concatenate([array, np.zeros((extra, *array.shape[1:]), array.dtype)])


class SensorStoreWrapper(gym.Wrapper):
    """Write every step, with the views of s and s' (``info["views"]``), into a :class:`StepStore`
    and put its id in ``info["store_id"]``. Sits above :class:`~dospcot.envs.RewardMaskWrapper`.

    Views are read only for a step that starts a new sample (on a keyed store, a pair's first visit):
    the wrapper turns on the views' ``lazy_views`` (:class:`~dospcot.envs.sensors.StepViews`, each
    computed when read) and asks the store before the env steps, while s's views can still be read.
    With ``draw``, an env in render mode ``"rgb_array"`` draws each stored reading's frame, what a
    person answering the run's queries is shown (``store.frames``)."""

    def __init__(self, env: gym.Env, store: StepStore, draw: bool = False) -> None:
        super().__init__(env)
        env.set_wrapper_attr("lazy_views", True, force=False)
        self.store = store
        self._draw = draw and env.render_mode == "rgb_array"
        self._state_key = env.get_wrapper_attr("current_state_key")
        self._row = -1
        self._views: Mapping[str, np.ndarray] = {}

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        self._views, self._row = info["views"], -1  # stored by the first step that needs them
        return obs, info

    def step(self, action: Any):
        action = int(action)
        new = self.store.is_new(self._state_key(), action)
        if new and self._row < 0:  # consecutive new samples share the row between them
            self._row = self._add_row(self._views)
        obs, reward, terminated, truncated, info = self.env.step(action)
        views = info["views"]
        next_row = self._add_row(views) if new else -1
        info = dict(info)
        info["store_id"] = self.store.add(
            self._row if new else -1,
            action,
            next_row,
            info["reward_observed"],
            float(reward),
            info["hidden_reward"],
            key=info.get("state_key"),
            ends=(terminated, truncated),
        )
        self._views, self._row = views, next_row
        return obs, reward, terminated, truncated, info

    def _add_row(self, views: Mapping[str, np.ndarray]) -> int:
        """Store the env's current state reading (and, where it draws itself, its frame)."""
        row = self.store.add_row(views)
        if self._draw:
            self.store.frames[row] = encode_png(self.env.render())
        return row


__all__ = ["KeyedStepStore", "SensorStoreWrapper", "StepStore"]
