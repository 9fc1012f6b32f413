"""Masked CliffWalking with views: the seed paper's task and the tabular validation path.

Gymnasium's ``CliffWalking-v1``: a 4 x 12 grid, start at (3, 0), goal at (3, 11), cliff along row
3 between them. Each step costs -1; stepping into the cliff costs -100 and returns to the start.

Views (docs/design.md section 1):

- ``coords``: (row, column), each scaled to [0, 1];
- ``patch``: the 3 x 3 egocentric terrain patch, one-hot over (free, cliff, goal, off-grid), 36 values;
- ``onehot``: the 48-way one-hot of the state, a third view for studies with m = 3.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np

from dospcot.envs.masking import RewardMaskWrapper
from dospcot.envs.views import MultiViewWrapper, View, select_views

N_ROWS, N_COLS = 4, 12
N_STATES = N_ROWS * N_COLS
START_STATE = 36
GOAL_STATE = 47
MAX_EPISODE_STEPS = 100

FREE, CLIFF, GOAL, OFF_GRID = range(4)
N_TERRAIN = 4


def _terrain(row: int, col: int) -> int:
    if not (0 <= row < N_ROWS and 0 <= col < N_COLS):
        return OFF_GRID
    if row == N_ROWS - 1 and 0 < col < N_COLS - 1:
        return CLIFF
    if (row, col) == divmod(GOAL_STATE, N_COLS):
        return GOAL
    return FREE


def coords_view(state: int) -> np.ndarray:
    """(row, column) of ``state``, scaled to [0, 1]; shape (2,)."""
    row, col = divmod(int(state), N_COLS)
    return np.array([row / (N_ROWS - 1), col / (N_COLS - 1)], dtype=np.float32)


def patch_view(state: int) -> np.ndarray:
    """3 x 3 terrain around ``state`` (row-major, centre included), one-hot per cell; shape (36,)."""
    row, col = divmod(int(state), N_COLS)
    patch = np.zeros((3, 3, N_TERRAIN), dtype=np.float32)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            patch[dr + 1, dc + 1, _terrain(row + dr, col + dc)] = 1.0
    return patch.reshape(-1)


def onehot_view(state: int) -> np.ndarray:
    """One-hot of ``state``; shape (48,)."""
    features = np.zeros(N_STATES, dtype=np.float32)
    features[int(state)] = 1.0
    return features


CLIFF_VIEWS: dict[str, View] = {
    "coords": View("coords", gym.spaces.Box(0.0, 1.0, (2,), np.float32), coords_view),
    "patch": View("patch", gym.spaces.Box(0.0, 1.0, (9 * N_TERRAIN,), np.float32), patch_view),
    "onehot": View("onehot", gym.spaces.Box(0.0, 1.0, (N_STATES,), np.float32), onehot_view),
}
"""The views of CliffWalking, by name."""


def make_masked_cliffwalking(
    label_fraction: float = 0.1,
    views: Sequence[str] = ("coords", "patch"),
    mask_seed: int = 0,
    max_episode_steps: int = MAX_EPISODE_STEPS,
) -> gym.Env:
    """``CliffWalking-v1`` with a step limit, state-action reward masking and views in ``info``.

    :param label_fraction: share of the 192 (state, action) keys whose reward is revealed.
    :param views: names from :data:`CLIFF_VIEWS`.
    :param mask_seed: seed of the labelled key set.
    :param max_episode_steps: episode length limit (the paper uses 100).
    """
    selected = select_views(CLIFF_VIEWS, views)
    env = gym.make("CliffWalking-v1", max_episode_steps=max_episode_steps)
    env = RewardMaskWrapper(env, label_fraction, mode="state-action", mask_seed=mask_seed)
    return MultiViewWrapper(env, selected)
