"""A replay buffer that relabels rewards and self-paced weights at sample time.

Modelled on stable-baselines3's HER buffer: instead of rewriting stored rewards when the
co-trainer's pseudo-labels change, each stored transition keeps its id in the co-trainer's shared
store and whether its reward was observed; :meth:`RelabellingReplayBuffer._get_samples` looks the
current reward and weight up in a :class:`RewardTable`. Relabelling therefore never copies the buffer.
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.vec_env import VecNormalize

from dospcot.policies.in_place_state import InPlaceState


class WeightedReplayBufferSamples(NamedTuple):
    """SB3's ``ReplayBufferSamples`` plus per-sample self-paced weights of shape (batch, 1)."""

    observations: th.Tensor
    actions: th.Tensor
    next_observations: th.Tensor
    dones: th.Tensor
    rewards: th.Tensor
    discounts: th.Tensor | None
    weights: th.Tensor


class RewardTable(InPlaceState):
    """Current reward and self-paced weight of every transition in the co-trainer's shared store.

    The co-trainer writes it after each round; buffers read it at sample time. Storage grows by
    doubling, so writing ids one round at a time stays linear.
    """

    def __init__(self) -> None:
        self._reward = np.zeros(0, dtype=np.float32)
        self._weight = np.zeros(0, dtype=np.float32)
        self._size = 0

    def __len__(self) -> int:
        return self._size

    @property
    def reward(self) -> np.ndarray:
        """(len,) reward of each store id."""
        return self._reward[: self._size]

    @property
    def weight(self) -> np.ndarray:
        """(len,) self-paced weight of each store id, in [0, 1]."""
        return self._weight[: self._size]

    def set(self, ids: np.ndarray, reward: np.ndarray, weight: np.ndarray) -> None:
        """Set the reward and weight of store ids ``ids`` (growing the table as needed).

        :raises ValueError: on a NaN or infinite reward or a weight outside [0, 1].
        """
        ids = np.asarray(ids, dtype=np.int64)
        reward = np.broadcast_to(np.asarray(reward, dtype=np.float64), ids.shape)
        weight = np.broadcast_to(np.asarray(weight, dtype=np.float64), ids.shape)
        bad = ~np.isfinite(reward)
        if bad.any():
            raise ValueError(f"reward must be finite, got {reward[bad][0]} (store id {ids[bad][0]})")
        outside = ~((weight >= 0) & (weight <= 1))
        if outside.any():
            raise ValueError(
                f"weight must lie in [0, 1], got {weight[outside][0]} (store id {ids[outside][0]})"
            )
        if ids.size:
            needed = int(ids.max()) + 1
            if needed > self._reward.size:
                capacity = max(needed, 2 * self._reward.size)
                self._reward = np.concatenate(
                    [self._reward, np.zeros(capacity - self._reward.size, np.float32)]
                )
                self._weight = np.concatenate(
                    [self._weight, np.zeros(capacity - self._weight.size, np.float32)]
                )
            self._size = max(self._size, needed)
        self._reward[ids] = reward
        self._weight[ids] = weight


class RelabellingReplayBuffer(ReplayBuffer):
    """SB3 ``ReplayBuffer`` whose samples carry relabelled rewards and self-paced weights.

    Reads three keys of each step's ``info``: ``reward_observed`` (default True: an unmasked env),
    ``store_id`` (the transition's id in the co-trainer's store, default -1: none) and ``explored``
    (default False: the agent took an exploratory, non-greedy action; it ends n-step windows).

    At sample time a transition whose reward was observed keeps it with weight 1. Otherwise, if the
    reward table knows its store id, it takes the table's reward and weight; if not, its weight is 0
    (``masked_reward="ignore"``, the labels-only rule) or its stored reward, 0.0, counts with
    weight 1 (``masked_reward="zero"``, the masked-zero baseline).

    With ``n_steps`` > 1 a sample is a window of up to n consecutive steps of one env, every reward in
    it relabelled at sample time: its reward is ``sum_k gamma^k r_k`` over the window, its next
    observation the window's last, its discount ``gamma^len``. A window ends at the first step that
    ends an episode (terminated or truncated; included) and before the first later step whose weight
    is 0 (an unlabelled step's reward is unknown, so the window bootstraps from that step's state) or
    whose action was ``explored`` (the greedy policy a max target values would not have taken it, as
    in Watkins's Q(lambda)). A sample weighs the least weight in its window, so a sample whose first
    step weighs 0 drives nothing.

    :param reward_table: the co-trainer's table, or None.
    :param masked_reward: ``"ignore"`` or ``"zero"``.
    :param n_steps: the longest window, in steps (1: one-step samples, ``discounts`` None).
    :param gamma: the discount inside a window (the agent's).
    Other parameters: as SB3's ``ReplayBuffer``.
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        reward_table: RewardTable | None = None,
        masked_reward: Literal["ignore", "zero"] = "ignore",
        n_steps: int = 1,
        gamma: float = 0.99,
    ) -> None:
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            n_envs,
            optimize_memory_usage,
            handle_timeout_termination,
        )
        if masked_reward not in ("ignore", "zero"):
            raise ValueError(f"masked_reward must be 'ignore' or 'zero', got {masked_reward!r}")
        if int(n_steps) != n_steps or n_steps < 1:
            raise ValueError(f"n_steps must be a positive integer, got {n_steps}")
        if n_steps > 1 and optimize_memory_usage:
            raise ValueError("n-step windows need optimize_memory_usage=False (they read next_observations)")
        if not 0 < gamma <= 1:
            raise ValueError(f"gamma must lie in (0, 1], got {gamma}")
        self.n_steps, self.gamma = int(n_steps), float(gamma)
        self.packed = _binary(observation_space)
        if self.packed:  # SB3's arrays are calloc'd, never touched: replacing them costs nothing
            width = (int(np.prod(self.obs_shape)) + 7) // 8
            self.observations = np.zeros((self.buffer_size, self.n_envs, width), dtype=np.uint8)
            if not optimize_memory_usage:
                self.next_observations = np.zeros_like(self.observations)
        self.reward_table = reward_table
        self.masked_reward = masked_reward
        self.store_ids = np.full((self.buffer_size, self.n_envs), -1, dtype=np.int64)
        self.observed = np.ones((self.buffer_size, self.n_envs), dtype=bool)
        self.explored = np.zeros((self.buffer_size, self.n_envs), dtype=bool)

    packed = False
    """Whether observations are stored as bits (a ``Box(0, 1)`` of uint8: one-hot views); a buffer
    pickled before the attribute existed reads False."""

    def __getstate__(self) -> dict[str, Any]:
        """The buffer for pickling, its rows not yet written as the one row they all repeat: a run's
        checkpoint after round 1 of 5 holds a fifth of the preallocated arrays (a MiniGrid run's was
        1.2 GB), and :meth:`__setstate__` rebuilds them bit for bit."""
        state = dict(vars(self))
        if self.full:
            return state
        unwritten = {}
        for name, value in vars(self).items():
            if isinstance(value, np.ndarray) and value.shape[:1] == (self.buffer_size,):
                rows = value[self.pos :].reshape(self.buffer_size - self.pos, -1).view(np.uint8)
                if (rows == rows[:1]).all():  # bytes, not values: -0.0 and NaN rows stay as they are
                    state[name], unwritten[name] = value[: self.pos], value[self.pos].copy()
        state["_unwritten_rows"] = unwritten
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        for name, row in state.pop("_unwritten_rows", {}).items():
            written = state[name]
            whole = np.empty((state["buffer_size"], *row.shape), dtype=written.dtype)
            whole[: len(written)], whole[len(written) :] = written, row
            state[name] = whole
        vars(self).update(state)

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        reward = np.asarray(reward)
        if not np.isfinite(reward).all():
            raise ValueError(f"reward must be finite, got {reward} at buffer position {self.pos}")
        for i, info in enumerate(infos):
            self.observed[self.pos, i] = info.get("reward_observed", True)
            self.store_ids[self.pos, i] = info.get("store_id", -1)
            self.explored[self.pos, i] = info.get("explored", False)
        if self.packed:
            obs, next_obs = self._pack(obs), self._pack(next_obs)
        super().add(obs, next_obs, action, reward, done, infos)

    def _pack(self, obs: np.ndarray) -> np.ndarray:
        """(n_envs, ceil(d / 8)) uint8: ``obs`` (n_envs, *obs_shape) of 0s and 1s as bits."""
        flat = np.asarray(obs).reshape(self.n_envs, -1)
        if flat.max(initial=0) > 1:
            raise ValueError(
                f"an observation of a Box(0, 1) space holds {flat.max()} at buffer position {self.pos}"
            )
        return np.packbits(flat, axis=-1)

    def _unpack(self, rows: np.ndarray) -> np.ndarray:
        """(batch, *obs_shape) uint8: the observations that :meth:`_pack` stored as ``rows``."""
        if not self.packed:
            return rows
        flat = np.unpackbits(rows, axis=-1, count=int(np.prod(self.obs_shape)))
        return flat.reshape(len(rows), *self.obs_shape)

    def relabel(self, batch_inds: np.ndarray, env_indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Current (reward, weight) of the stored transitions ``(batch_inds, env_indices)`` (arrays of
        one shape, or broadcasting to one)."""
        reward = self.rewards[batch_inds, env_indices]
        observed = self.observed[batch_inds, env_indices]
        if self.masked_reward == "zero":
            weight = np.ones(observed.shape, dtype=np.float32)
        else:
            weight = observed.astype(np.float32)
        table = self.reward_table
        if table is not None and len(table):
            ids = self.store_ids[batch_inds, env_indices]
            known = ~observed & (ids >= 0) & (ids < len(table))
            safe = np.where(known, ids, 0)
            reward = np.where(known, table.reward[safe], reward)
            weight = np.where(known, table.weight[safe], weight)
        return reward, weight

    def _get_samples(
        self, batch_inds: np.ndarray, env: VecNormalize | None = None
    ) -> WeightedReplayBufferSamples:
        # Same draws, in the same order, as ReplayBuffer._get_samples, so seeds match stock DQN.
        env_indices = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))  # noqa: NPY002
        if self.n_steps > 1:
            return self._window_samples(batch_inds, env_indices, env)
        if self.optimize_memory_usage:
            next_obs = self.observations[(batch_inds + 1) % self.buffer_size, env_indices, :]
        else:
            next_obs = self.next_observations[batch_inds, env_indices, :]
        reward, weight = self.relabel(batch_inds, env_indices)
        dones = self.dones[batch_inds, env_indices] * (1 - self.timeouts[batch_inds, env_indices])
        return self._samples(batch_inds, env_indices, next_obs, dones, reward, None, weight, env)

    def _window_samples(
        self, batch_inds: np.ndarray, env_indices: np.ndarray, env: VecNormalize | None
    ) -> WeightedReplayBufferSamples:
        """n-step samples (see the class docstring); all arrays (batch, n_steps) until the sums."""
        steps = np.arange(self.n_steps)
        window = (batch_inds[:, None] + steps) % self.buffer_size
        envs = env_indices[:, None]
        reward, weight = self.relabel(window, envs)
        # The newest step has no successor in the buffer yet: a window must end there.
        newest = (self.pos - 1) % self.buffer_size
        ends = (self.dones[window, envs] > 0) | (self.timeouts[window, envs] > 0) | (window == newest)
        cut_before = np.zeros_like(ends)
        cut_before[:, 1:] = ends[:, :-1] | (weight[:, 1:] == 0) | self.explored[window, envs][:, 1:]
        inside = np.cumprod(~cut_before, axis=1).astype(bool)
        length = inside.sum(axis=1)
        discounted = np.where(inside, reward * self.gamma**steps, 0.0).sum(axis=1)
        weight = np.where(inside, weight, 1.0).min(axis=1)
        last = window[np.arange(len(window)), length - 1]
        next_obs = self.next_observations[last, env_indices, :]
        dones = self.dones[last, env_indices] * (1 - self.timeouts[last, env_indices])
        discounts = (self.gamma**length).astype(np.float32)
        return self._samples(batch_inds, env_indices, next_obs, dones, discounted, discounts, weight, env)

    def _samples(
        self,
        batch_inds: np.ndarray,
        env_indices: np.ndarray,
        next_obs: np.ndarray,
        dones: np.ndarray,
        reward: np.ndarray,
        discounts: np.ndarray | None,
        weight: np.ndarray,
        env: VecNormalize | None,
    ) -> WeightedReplayBufferSamples:
        observations = self._unpack(self.observations[batch_inds, env_indices, :])
        return WeightedReplayBufferSamples(
            observations=self.to_torch(self._normalize_obs(observations, env)),
            actions=self.to_torch(self.actions[batch_inds, env_indices, :]),
            next_observations=self.to_torch(self._normalize_obs(self._unpack(next_obs), env)),
            dones=self.to_torch(dones.reshape(-1, 1)),
            rewards=self.to_torch(
                self._normalize_reward(reward.reshape(-1, 1).astype(np.float32, copy=False), env)
            ),
            discounts=None if discounts is None else self.to_torch(discounts.reshape(-1, 1)),
            weights=self.to_torch(weight.reshape(-1, 1).astype(np.float32, copy=False)),
        )


def _binary(space: spaces.Space) -> bool:
    """Whether ``space`` holds 0s and 1s alone: a ``Box`` of uint8 from 0 to 1."""
    return (
        isinstance(space, spaces.Box)
        and space.dtype == np.uint8
        and bool(np.all(space.low == 0))
        and bool(np.all(space.high == 1))
    )
