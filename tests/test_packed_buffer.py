"""Views of 0s and 1s are stored as bits: a bool sensor view's space is ``Box(0, 1)`` of uint8, and the
replay buffer packs such observations, returning the same samples as an unpacked buffer."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

from dospcot.envs.gym_sensors import ObservationSensors
from dospcot.policies import RelabellingReplayBuffer

WIDTH = 21  # not a multiple of 8: the last byte is part padding


def _filled(space: gym.spaces.Box, steps: int, seed: int = 0) -> RelabellingReplayBuffer:
    buffer = RelabellingReplayBuffer(64, space, gym.spaces.Discrete(3), device="cpu")
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        obs, next_obs = rng.integers(0, 2, (2, 1, WIDTH), dtype=np.uint8)
        buffer.add(obs, next_obs, rng.integers(0, 3, (1, 1)), rng.normal(size=1), np.zeros(1), [{}])
    return buffer


def test_a_binary_box_is_stored_as_bits_and_samples_as_the_unpacked_buffer() -> None:
    binary, bytes_ = gym.spaces.Box(0, 1, (WIDTH,), np.uint8), gym.spaces.Box(0, 255, (WIDTH,), np.uint8)
    packed, plain = _filled(binary, 40), _filled(bytes_, 40)
    assert packed.packed and not plain.packed
    assert packed.observations.shape == (64, 1, 3) and plain.observations.shape == (64, 1, WIDTH)
    np.random.seed(7)  # noqa: NPY002 (SB3 draws its batches from numpy's global generator)
    ours = packed.sample(16)
    np.random.seed(7)  # noqa: NPY002
    theirs = plain.sample(16)
    for name in ("observations", "next_observations", "actions", "rewards"):
        a, b = getattr(ours, name), getattr(theirs, name)
        assert a.dtype == b.dtype and a.shape == b.shape and bool((a == b).all()), name


def test_a_packed_buffer_round_trips_through_pickle() -> None:
    buffer = _filled(gym.spaces.Box(0, 1, (WIDTH,), np.uint8), 10)
    copy = pickle.loads(pickle.dumps(buffer))
    assert copy.packed and copy.observations.tobytes() == buffer.observations.tobytes()
    np.random.seed(3)  # noqa: NPY002
    a = buffer.sample(4).observations
    np.random.seed(3)  # noqa: NPY002
    assert bool((copy.sample(4).observations == a).all())


def test_a_value_the_binary_space_does_not_allow_is_refused() -> None:
    buffer = RelabellingReplayBuffer(8, gym.spaces.Box(0, 1, (3,), np.uint8), gym.spaces.Discrete(2), "cpu")
    with pytest.raises(ValueError, match=r"Box\(0, 1\) space holds 2"):
        buffer.add(np.array([[0, 2, 1]]), np.zeros((1, 3)), np.zeros((1, 1)), np.zeros(1), np.zeros(1), [{}])


def test_a_bool_view_gets_a_binary_space_and_may_not_turn_into_bytes() -> None:
    calls = {"n": 0}

    def flips(obs: int) -> np.ndarray:
        calls["n"] += 1
        value = np.eye(4, dtype=bool)[obs % 4]
        return value if calls["n"] == 1 else value.astype(np.uint8) * 2

    env = ObservationSensors(
        gym.make("FrozenLake-v1"), {"onehot": lambda obs: np.eye(16, dtype=bool)[obs], "flips": flips}
    )
    space = env.view_space("onehot")
    assert space.dtype == np.uint8 and space.high.max() == 1 and space.low.min() == 0
    assert env.observe("onehot").sum() == 1
    with pytest.raises(ValueError, match="view 'flips' changed type: bool at the first reset, uint8 now"):
        env.observe("flips")
