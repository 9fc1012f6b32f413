"""MiniGrid's views, state key and action sets for ``task = "gym"`` (the ``minigrid`` extra;
docs/your_env.md).

MiniGrid's own observation is the egocentric view (``"image"``: the 7 x 7 cells ahead of the agent,
3 numbers each: object, colour, state) and the agent's ``"direction"``; name them as keys. These read
the env itself, as an agent with another sensor would:

- ``"minigrid.full"``: the whole map, 3 numbers per cell with the agent drawn in (what MiniGrid's
  ``FullyObsWrapper`` observes), W x H x 3;
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

from collections.abc import Callable, Hashable, Sequence

import gymnasium as gym
import numpy as np

AGENT_CELL = (10, 0, 0)
"""How the full view draws the agent: MiniGrid's object index of an agent, colour red (0); the third
number is its direction."""


def full_grid(env: gym.Env) -> np.ndarray:
    """(W, H, 3) the map's encoding with the agent drawn in."""
    grid = env.grid.encode()
    x, y = env.agent_pos
    grid[x, y] = (AGENT_CELL[0], AGENT_CELL[1], env.agent_dir)
    return grid


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
    return (tuple(int(v) for v in env.agent_pos), int(env.agent_dir), held, env.grid.encode().tobytes())


ENV_VIEWS: dict[str, Callable[[gym.Env], np.ndarray]] = {
    "minigrid.full": full_grid,
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
