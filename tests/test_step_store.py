"""The sensor adapter's step store (dospcot.adapters.sensor_store.StepStore): the classifiers' inputs
of every step, built once per step however often the pool is asked for."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from dospcot.adapters.sensor_store import StepStore

ACTIONS = 3


def _store(steps: int, rng: np.random.Generator, store: StepStore | None = None) -> StepStore:
    """A store of ``steps`` more steps of a uint8 view ``ego`` (4 inputs) and a float64 view ``xy`` (2)."""
    store = store or StepStore({"ego": (2, 2), "xy": (2,)}, {"ego": np.uint8, "xy": np.float64})
    row = store.add_row({"ego": rng.integers(0, 2, (2, 2)), "xy": rng.normal(size=2)})
    for _ in range(steps):
        after = store.add_row({"ego": rng.integers(0, 2, (2, 2)), "xy": rng.normal(size=2)})
        ended = bool(rng.random() < 0.2)
        store.add(row, int(rng.integers(ACTIONS)), after, False, 0.0, 0.0, ends=(ended, False))
        row = after
    return store


def _by_hand(store: StepStore, view: str, dtype: type) -> np.ndarray:
    rows, n = store.rows[view].astype(np.float32).astype(dtype), len(store)
    onehot = np.eye(ACTIONS, dtype=dtype)[store.action[:n]]
    ends = store.terminal[:n, None].astype(dtype)
    return np.hstack([rows[store.state_row[:n]], onehot, rows[store.next_row[:n]], ends])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_features_asked_for_as_steps_arrive_equal_those_built_at_once(dtype):
    rng = np.random.default_rng(0)
    store = _store(5, rng)
    early = {view: store.features(view, ACTIONS, True, dtype).copy() for view in ("ego", "xy")}
    for grown in (1, 40, 3):  # steps arrive between asks, past the room kept for them
        _store(grown, rng, store)
        for view in ("ego", "xy"):
            got = store.features(view, ACTIONS, True, dtype)
            assert got.dtype == dtype and got.shape == (len(store), 2 * store.rows[view].shape[1] + 4)
            assert np.array_equal(got, _by_hand(store, view, dtype))
    assert all(np.array_equal(early[v], _by_hand(store, v, dtype)[:5]) for v in early)
    # Without termination: the same columns but the last, built apart from those with it.
    assert np.array_equal(store.features("xy", ACTIONS, False, dtype), _by_hand(store, "xy", dtype)[:, :-1])


def test_a_checkpoint_holds_no_features_and_a_loaded_store_builds_them_again():
    rng = np.random.default_rng(1)
    store = _store(30, rng)
    store.features("ego", ACTIONS)
    state = pickle.loads(pickle.dumps(store.state_dict()))
    assert "_features" not in state
    other = _store(10, np.random.default_rng(2))
    other.features("ego", ACTIONS)  # features of other steps, which loading must drop
    other.load_state_dict(state)
    assert np.array_equal(other.features("ego", ACTIONS), _by_hand(store, "ego", np.float32)[:, :-1])
