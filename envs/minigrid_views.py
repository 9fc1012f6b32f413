"""MiniGrid's views and state key for ``task = "gym"`` (the ``minigrid`` extra; docs/your_env.md).

MiniGrid's own observation is the egocentric view (``"image"``: the 7 x 7 cells ahead of the agent,
3 numbers each: object, colour, state) and the agent's ``"direction"``; name them as keys. These read
the env itself, as an agent with another sensor would:

- ``"minigrid.full"``: the whole map, 3 numbers per cell with the agent drawn in (what MiniGrid's
  ``FullyObsWrapper`` observes), W x H x 3;
- ``"minigrid.position"``: the agent's column, row and direction, each one-hot (W + H + 4), with
  nothing of the map: an agent on it must learn the map by heart, as the grid's ``coords`` agent.

Every function reads ``env.unwrapped`` attributes only, so none imports minigrid.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable

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
