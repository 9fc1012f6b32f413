"""MiniGrid's views, state key and action sets for ``task = "gym"`` (the ``minigrid`` extra;
docs/your_env.md).

MiniGrid's own observation is the egocentric view (``"image"``: the 7 x 7 cells ahead of the agent,
3 numbers each: object, colour, state) and the agent's ``"direction"``; name them as keys. These read
the env itself, as an agent with another sensor would:

- ``"minigrid.full"``: the whole map, 3 numbers per cell with the agent drawn in (what MiniGrid's
  ``FullyObsWrapper`` observes), W x H x 3;
- ``"minigrid.full_one_hot"``: the same map as indicators, W x H x 15 (:func:`full_one_hot`);
- ``"minigrid.egocentric_map"``: those indicators turned and shifted into the agent's frame (the
  agent at the centre, facing up), (2 M - 1) x (2 M - 1) x 15 for a map of longer side M
  (:func:`egocentric_map`);
- ``"minigrid.position"``: the agent's column, row and direction, each one-hot (W + H + 4), with
  nothing of the map: an agent on it must learn the map by heart, as the grid's ``coords`` agent.

MiniGrid offers 7 actions to every task, most of them no-ops in most tasks. :class:`MoveActions`
(turn left, turn right, forward) and :class:`DoorActions` (those, pick up and toggle) keep the ones
a task needs; name them in ``gym.wrappers`` by dotted path. A random policy on LavaGapS7 reaches the
goal more than twice as often with three actions as with seven (a test counts it), and a Q-learner
explores as a random policy at first.

Everything here reads ``env.unwrapped`` attributes or action numbers only, so nothing imports
minigrid.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

AGENT_CELL = (10, 0, 0)
"""How the full view draws the agent: MiniGrid's object index of an agent, colour red (0); the third
number is its direction."""


EMPTY_CELL = (1, 0, 0)
"""How MiniGrid encodes an empty cell: object "empty" (1), colour 0, state 0."""

_ENCODINGS: weakref.WeakKeyDictionary[gym.Env, tuple[object, int, np.ndarray]] = weakref.WeakKeyDictionary()


def map_encoding(env: gym.Env) -> np.ndarray:
    """(W, H, 3) ``env.grid.encode()``, read-only, encoded once per step: the full views and the
    state key all read it every step, and encoding the map cell by cell is most of their cost. A
    step moves ``env.step_count`` and a reset builds a new grid, so either one encodes afresh; the
    cache holds the grid itself, so a new grid cannot be mistaken for a freed one."""
    cached = _ENCODINGS.get(env)
    if cached is not None and cached[0] is env.grid and cached[1] == env.step_count:
        return cached[2]
    grid = env.grid
    # What grid.encode() returns, from its flat list of cells (row by row) in one pass: about 2.5
    # times faster than its per-cell get().
    cells = [EMPTY_CELL if obj is None else obj.encode() for obj in grid.grid]
    encoding = np.array(cells, dtype=np.uint8).reshape(grid.height, grid.width, 3).transpose(1, 0, 2)
    encoding.flags.writeable = False
    _ENCODINGS[env] = (env.grid, env.step_count, encoding)
    return encoding


def full_grid(env: gym.Env) -> np.ndarray:
    """(W, H, 3) the map's encoding with the agent drawn in."""
    grid = map_encoding(env).copy()
    x, y = env.agent_pos
    grid[x, y] = (AGENT_CELL[0], AGENT_CELL[1], env.agent_dir)
    return grid


OBJECT_TYPES = 11
"""MiniGrid's object indices: unseen, empty, wall, floor, door, key, ball, box, goal, lava, agent."""

_INDICATORS = np.eye(OBJECT_TYPES + 4, dtype=bool)
"""(15, 15) bool identity: row c marks object type c (c < 11), row 11 + s marks state s. bool, not
float32: a sensor view of bool values is stored as uint8 in a ``Box(0, 1)`` (:class:`~dospcot.envs.
gym_sensors.ObservationSensors`), a quarter of the memory, and a replay buffer packs it into bits
(:class:`~dospcot.policies.esarsa_dqn.RelabellingReplayBuffer`), a thirty-second; a network reads
the same 0.0 and 1.0."""


def full_one_hot(env: gym.Env) -> np.ndarray:
    """(W, H, 15) the full map as indicators: each cell's object type (11), then its state (4: a
    door's open / closed / locked, the agent's direction on its own cell). The raw encoding holds
    object indices as numbers (lava 9, agent 10), which an MLP reads as magnitudes; with indicators
    the agent's cell is one input per cell. With every reward revealed on LavaGapS7, a DQN agent on
    the indicators reached the goal more often than on the raw numbers (docs/your_env.md)."""
    grid = full_grid(env)
    return _INDICATORS[grid[..., 0]] | _INDICATORS[OBJECT_TYPES + grid[..., 2]]


def egocentric_map(env: gym.Env) -> np.ndarray:
    """(2 M - 1, 2 M - 1, 15) the whole map as indicators (:func:`full_one_hot`) in the agent's frame,
    M the map's longer side: the agent's cell at the centre (M - 1, M - 1), the map turned so that
    the agent faces up (the cell ahead at (M - 1, M - 2), as in MiniGrid's image); cells beyond the
    map are all 0. Unlike the image nothing is hidden behind walls or out of range, and unlike the
    full map a situation (lava ahead, the goal two cells to the left) reads the same wherever on the
    map it happens, which a network need not learn once per cell."""
    indicators = full_one_hot(env)
    width, height = indicators.shape[:2]
    side = max(width, height)
    canvas = np.zeros((2 * side - 1, 2 * side - 1, indicators.shape[2]), indicators.dtype)
    x, y = env.agent_pos
    canvas[side - 1 - x : side - 1 - x + width, side - 1 - y : side - 1 - y + height] = indicators
    # Directions: 0 +x, 1 +y, 2 -x, 3 -y (up); k quarter turns from axis 0 towards 1 bring each up.
    return np.ascontiguousarray(np.rot90(canvas, (3 - int(env.agent_dir)) % 4, axes=(0, 1)))


def position(env: gym.Env) -> np.ndarray:
    """(W + H + 4,) the agent's column, row and direction, each one-hot."""
    x, y = env.agent_pos
    return np.concatenate([np.eye(env.width)[x], np.eye(env.height)[y], np.eye(4)[env.agent_dir]]).astype(
        np.float32
    )


def state_key(env: gym.Env) -> Hashable:
    """A MiniGrid state's key: the agent's cell and direction, what it carries, and the map's encoding
    (walls, lava, doors open or locked, keys still lying), everything a step's outcome depends on but
    the step count (the goal pays ``1 - 0.9 t / T``). The map is part of the key because most MiniGrid
    tasks draw a new one every episode (LavaGap's gap, DoorKey's door and key)."""
    held = None if env.carrying is None else (env.carrying.type, env.carrying.color)
    return (tuple(int(v) for v in env.agent_pos), int(env.agent_dir), held, map_encoding(env).tobytes())


ENV_VIEWS: dict[str, Callable[[gym.Env], np.ndarray]] = {
    "minigrid.full": full_grid,
    "minigrid.full_one_hot": full_one_hot,
    "minigrid.egocentric_map": egocentric_map,
    "minigrid.position": position,
}
"""Views that read the unwrapped env, by name."""


class MiniGridActions(gym.ActionWrapper):
    """Offer only ``actions`` of MiniGrid's (0 left, 1 right, 2 forward, 3 pick up, 4 drop,
    5 toggle, 6 done), numbered 0, 1, ... in that order.

    :param env: a MiniGrid env.
    :param actions: MiniGrid's numbers of the actions kept.
    """

    def __init__(self, env: gym.Env, actions: Sequence[int]) -> None:
        super().__init__(env)
        self.actions = tuple(int(a) for a in actions)
        self.action_space = gym.spaces.Discrete(len(self.actions))

    def action(self, action: int) -> int:
        return self.actions[int(action)]


class MoveActions(MiniGridActions):
    """Turn left, turn right, move forward: what a task without objects needs (LavaGap, Empty,
    LavaCrossing)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env, (0, 1, 2))


class DoorActions(MiniGridActions):
    """Turn left, turn right, move forward, pick up, toggle: what DoorKey needs."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env, (0, 1, 2, 3, 5))


class RandomStart(gym.Wrapper):
    """Exploring starts: every episode begins on a random empty cell of the new map, facing a random
    direction, drawn with the env's own generator (so the env's seed fixes them). A goal that a
    random walk from the task's start seldom reaches is then reached often enough to learn its
    value everywhere; name it in ``gym.train_wrappers`` so that evaluation keeps the task's start.
    Put it inside any observation wrapper (``gym.train_wrappers`` are).
    """

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        _, info = self.env.reset(**kwargs)
        env = self.env.unwrapped
        free = self.start_cells(env)
        x, y = free[int(env.np_random.integers(len(free)))]
        env.agent_pos = (x, y)
        env.agent_dir = int(env.np_random.integers(4))
        return env.gen_obs(), info

    def start_cells(self, env: gym.Env) -> list[tuple[int, int]]:
        """The cells an episode may start on: every empty one, column by column."""
        grid = env.grid
        return [(x, y) for x in range(grid.width) for y in range(grid.height) if grid.get(x, y) is None]


class ReachableStart(RandomStart):
    """Exploring starts on the empty cells the task's start connects to: through empty cells, doors
    (open, closed or locked, as a key opens them) and any object but walls and lava. Where every empty
    cell connects, as on DoorKey, it draws what :class:`RandomStart` draws; on a map whose rooms sit
    in unreachable empty space (MultiRoom's), no episode starts out there. Version 9 of the defaults
    names it for a MiniGrid task that sets no training wrapper.
    """

    def start_cells(self, env: gym.Env) -> list[tuple[int, int]]:
        """The empty cells connected to the agent's start, column by column."""
        grid, seen = env.grid, {tuple(int(v) for v in env.agent_pos)}
        frontier = list(seen)
        while frontier:
            x, y = frontier.pop()
            for cell in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
                if cell in seen or not (0 <= cell[0] < grid.width and 0 <= cell[1] < grid.height):
                    continue
                thing = grid.get(*cell)
                if thing is None or thing.type not in ("wall", "lava"):
                    seen.add(cell)
                    frontier.append(cell)
        return [cell for cell in super().start_cells(env) if cell in seen]
