"""Expert demonstrations: whole episodes of an expert's steps, in every view, as a second label source.

A rater who cannot label every step can often show the task instead. A :class:`Demonstrations` holds
N episodes of an expert's steps: each view of s and of s', the action and, where the expert's rewards
are known, the reward. They serve two roles (docs/demonstrations.md):

- labelled samples for the reward classifiers, but only if the file holds rewards: a demonstration
  whose rewards are absent teaches the classifiers nothing and its hidden rewards reach no learner;
- a large-margin term in each agent's loss on the demonstrated actions
  (:func:`dospcot.policies.esarsa_dqn.large_margin_loss`, after DQfD, Hester et al. 2018).

The file format is one ``.npz`` (:meth:`Demonstrations.save`, :meth:`Demonstrations.load`):

========================  =============  ===============================================
key                       shape, dtype   meaning
========================  =============  ===============================================
``actions``               (N,) int64     the expert's action at step i
``episode``               (N,) int64     the episode of step i, 0, 1, ... non-decreasing
``obs/<view>``            (N, d) float32 view ``<view>`` of the state the step starts in
``next_obs/<view>``       (N, d) float32 the same view of the state it reaches
``rewards`` (optional)    (N,) float64   the step's reward, where the expert's are known
``states`` (optional)     (N,) int64     on a discrete task, the index of the state s
========================  =============  ===============================================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from dospcot.envs.tabular import TabularMDP


@dataclass(frozen=True)
class Demonstrations:
    """N demonstrated steps, grouped into episodes.

    :param observations: per view, (N, d) float32, the view of the state each step starts in.
    :param next_observations: per view, (N, d) float32, the view of the state it reaches.
    :param actions: (N,) int64, the expert's actions.
    :param episode: (N,) int64, each step's episode, non-decreasing from 0.
    :param rewards: (N,) float64, each step's reward; None where the expert's rewards are not known.
    :param states: (N,) int64, on a discrete task the index of each step's state; None otherwise.
    """

    observations: Mapping[str, np.ndarray]
    next_observations: Mapping[str, np.ndarray]
    actions: np.ndarray
    episode: np.ndarray
    rewards: np.ndarray | None = None
    states: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.actions)
        if self.actions.ndim != 1 or self.episode.shape != (n,):
            raise ValueError(
                f"demonstrations: actions and episode must both be (N,), got {self.actions.shape} "
                f"and {self.episode.shape}"
            )
        if n and (self.episode[0] != 0 or not np.all(np.isin(np.diff(self.episode), (0, 1)))):
            raise ValueError("demonstrations: episode must count 0, 1, ... in step order")
        if set(self.observations) != set(self.next_observations) or not self.observations:
            raise ValueError(
                f"demonstrations: obs and next_obs must name the same views, got {sorted(self.observations)} "
                f"and {sorted(self.next_observations)}"
            )
        for name in self.observations:
            obs, nxt = self.observations[name], self.next_observations[name]
            if obs.ndim != 2 or len(obs) != n or obs.shape != nxt.shape:
                raise ValueError(
                    f"demonstrations: view {name!r} must be (N, d) in obs and next_obs with N = {n} "
                    f"steps, got {obs.shape} and {nxt.shape}"
                )
        for key, value in (("rewards", self.rewards), ("states", self.states)):
            if value is not None and value.shape != (n,):
                raise ValueError(f"demonstrations: {key} must be (N,) with N = {n}, got {value.shape}")

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def n_episodes(self) -> int:
        """The number of episodes (0 for an empty set)."""
        return int(self.episode[-1]) + 1 if len(self) else 0

    @property
    def views(self) -> tuple[str, ...]:
        """The names of the views every step is recorded in."""
        return tuple(self.observations)

    def without_rewards(self) -> Demonstrations:
        """The same steps with no rewards: nothing the expert earned can reach a learner."""
        return dataclasses.replace(self, rewards=None)

    def first_episodes(self, n: int) -> Demonstrations:
        """The first ``n`` episodes."""
        keep = self.episode < n
        return Demonstrations(
            {v: o[keep] for v, o in self.observations.items()},
            {v: o[keep] for v, o in self.next_observations.items()},
            self.actions[keep],
            self.episode[keep],
            None if self.rewards is None else self.rewards[keep],
            None if self.states is None else self.states[keep],
        )

    def save(self, path: str | Path) -> None:
        """Write the ``.npz`` file of the module docstring."""
        arrays = {"actions": self.actions, "episode": self.episode}
        arrays |= {f"obs/{v}": o for v, o in self.observations.items()}
        arrays |= {f"next_obs/{v}": o for v, o in self.next_observations.items()}
        arrays |= {k: v for k, v in (("rewards", self.rewards), ("states", self.states)) if v is not None}
        np.savez(path, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> Demonstrations:
        """Read a file :meth:`save` wrote (or one written by hand to the same format); a
        ``ValueError`` names what is missing or malformed."""
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as err:
            raise ValueError(f"demonstrations: cannot read {str(path)!r} as a .npz file ({err})") from None
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise ValueError(
                f"demonstrations: {str(path)!r} holds one array, not a .npz file of named arrays"
            )
        with data:
            missing = [key for key in ("actions", "episode") if key not in data.files]
            if missing:
                raise ValueError(f"demonstrations: {str(path)!r} has no {', '.join(missing)}")
            return cls(
                _views(data, "obs/"),
                _views(data, "next_obs/"),
                data["actions"].astype(np.int64),
                data["episode"].astype(np.int64),
                data["rewards"].astype(np.float64) if "rewards" in data.files else None,
                data["states"].astype(np.int64) if "states" in data.files else None,
            )


def _views(data: Any, prefix: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` whose key starts with ``prefix``, by the rest of its key, float32."""
    return {k.removeprefix(prefix): data[k].astype(np.float32) for k in data.files if k.startswith(prefix)}


def expert_demonstrations(
    mdp: TabularMDP, n_episodes: int, seed: int, discount: float = 1.0, with_rewards: bool = True
) -> Demonstrations:
    """``n_episodes`` episodes of value iteration's optimal policy on ``mdp``, in every view it holds.

    The first episode starts where the task does; the others start on states drawn uniformly (seeded)
    from those that can reach the end, since on a deterministic task every episode from one start
    would repeat the first. An episode ends at a terminal transition or after ``max_episode_steps``.

    :param discount: of the value iteration (1: the undiscounted optimum the metrics measure against;
        ties between optimal actions go to the lowest action).
    :param with_rewards: record the expert's rewards (then they may serve as labels).
    """
    if n_episodes < 0:
        raise ValueError(f"demonstration episodes must be >= 0, got {n_episodes}")
    policy = mdp.value_iteration(discount).argmax(axis=1)
    candidates = np.flatnonzero(mdp.can_terminate())
    rng = np.random.default_rng(seed)
    starts = [mdp.start_state, *rng.choice(candidates, max(n_episodes - 1, 0)).tolist()][:n_episodes]
    states, actions, episode = [], [], []
    for k, s in enumerate(starts):
        for _ in range(mdp.max_episode_steps):
            a = int(policy[s])
            states.append(s), actions.append(a), episode.append(k)
            if mdp.terminal[s, a]:
                break
            s = int(mdp.next_state[s, a])
    s_arr, a_arr = np.array(states, np.int64), np.array(actions, np.int64)
    nxt = mdp.next_state[s_arr, a_arr]
    return Demonstrations(
        {v: f[s_arr] for v, f in mdp.views.items()},
        {v: f[nxt] for v, f in mdp.views.items()},
        a_arr,
        np.array(episode, np.int64),
        mdp.reward[s_arr, a_arr].astype(np.float64) if with_rewards else None,
        s_arr,
    )


class Policy(Protocol):
    """Anything with SB3's ``predict`` (a loaded SB3 model)."""

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = False
    ) -> Any: ...


def load_agent(path: str | Path, algorithm: str = "DQN") -> Policy:
    """A saved SB3 agent, loaded on the CPU by ``algorithm``, a class of ``stable_baselines3`` or
    ``sb3_contrib``; a ``ValueError`` names what is wrong."""
    import stable_baselines3

    cls = getattr(stable_baselines3, algorithm, None)
    if cls is None:
        try:
            import sb3_contrib

            cls = getattr(sb3_contrib, algorithm, None)
        except ImportError:
            pass
    if cls is None or not hasattr(cls, "load"):
        raise ValueError(
            f"agent_algorithm: {algorithm!r} is not an SB3 or sb3-contrib algorithm, e.g. DQN, PPO"
        )
    if not Path(path).is_file():
        raise ValueError(f"agent: no file {str(path)!r}")
    try:
        return cls.load(path, device="cpu")
    except Exception as err:  # zipfile, pickle and torch raise many types for a damaged or foreign file
        raise ValueError(
            f"agent: cannot load {str(path)!r} as {algorithm} ({type(err).__name__}: {err})"
        ) from None


def record_demonstrations(policy: Policy, env: gym.Env, n_episodes: int, seed: int) -> Demonstrations:
    """``n_episodes`` greedy episodes of ``policy`` on a sensor env, in every view it records.

    :param policy: the expert, e.g. :func:`load_agent`'s; it reads the env's observations.
    :param env: an env whose ``reset`` and ``step`` infos hold ``info["views"]`` (every view to record,
        :class:`~dospcot.envs.SensorViewWrapper`) and that ends its episodes (a time limit). Its
        reward is recorded, or ``info["hidden_reward"]`` where a mask hid it.
    :param seed: episode i resets with seed ``seed + i``.
    """
    if n_episodes < 1:
        raise ValueError(f"record at least one episode, got {n_episodes}")
    obs_rows: dict[str, list[np.ndarray]] = {}
    next_rows: dict[str, list[np.ndarray]] = {}
    actions, episode, rewards = [], [], []
    for k in range(n_episodes):
        obs, info = env.reset(seed=seed + k)
        views, done = {v: np.ravel(x) for v, x in info["views"].items()}, False
        while not done:
            action = int(np.asarray(policy.predict(obs, deterministic=True)[0]).item())
            obs, reward, terminated, truncated, info = env.step(action)
            following = {v: np.ravel(x) for v, x in info["views"].items()}
            for v in views:
                obs_rows.setdefault(v, []).append(views[v])
                next_rows.setdefault(v, []).append(following[v])
            actions.append(action), episode.append(k)
            rewards.append(float(info.get("hidden_reward", reward)))
            views, done = following, terminated or truncated
    return Demonstrations(
        {v: np.asarray(rows, np.float32) for v, rows in obs_rows.items()},
        {v: np.asarray(rows, np.float32) for v, rows in next_rows.items()},
        np.asarray(actions, np.int64),
        np.asarray(episode, np.int64),
        np.asarray(rewards, np.float64),
    )


__all__ = [
    "Demonstrations",
    "expert_demonstrations",
    "load_agent",
    "record_demonstrations",
]
