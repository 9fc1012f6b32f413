"""Masked-reward grid worlds of the project's own: N x N, start, goal, lava, walls, a step cost.

Layouts come from a text map or from a seed (always solvable). Stepping is a table look-up in
arrays built once per layout, and the env exposes the toy-text ``P`` table, so
:meth:`dospcot.envs.TabularMDP.from_env` gives value iteration for the exact optimum.

Dynamics: actions 0 up, 1 right, 2 down, 3 left. A move into a wall or off the grid stays put.
Every step costs ``step_cost``; entering lava costs ``lava_penalty`` and returns to the start (the
episode goes on, as CliffWalking's cliff); entering the goal pays ``goal_reward`` and ends the episode.

Views (docs/design.md section 1):

- ``coords``: (row, column) and the goal's offset (d_row, d_column), divided by N - 1; 4 values;
- ``patch``: the k x k egocentric terrain patch, one-hot over (free, wall, lava, goal, off-grid);
- ``rays``: along the 8 compass directions, the distance d (in cells) to the nearest lava, wall (or
  edge) and goal; 24 values, encoded (``ray_encoding``) as ``"distance"``: d / N (1.0 where there is
  none), or ``"inverse"``: 1 / d (0 where there is none). Scaled by N, the cell next to the agent and
  the one after it differ by 1 / N, which shrinks as the map grows (0.03 on a 32 x 32 map); inverse,
  a hazard next to the agent reads 1 and one two cells away 0.5, on any map.

A goal compass (``compass``) makes every view also read where the goal lies from the agent: a local
sensor alone tells a cell only by its neighbourhood, so an agent that reads only it must learn the
whole map by heart to find the goal, which a neural network does unreliably on maps it was not tuned
on. Two encodings of the goal's offset (d_row, d_column):

- ``"axes"``: each offset one-hot over its 2N - 1 values (4N - 2 more inputs);
- ``"cell"``: the offset pair one-hot over the N^2 pairs a cell of the map can have (N^2 more
  inputs, one per cell, since the goal is fixed): the first layer of an MLP then holds a separate
  embedding for every cell, so a value learned in one cell is not blurred into its row and column.

Scaled numbers (as ``coords`` holds) make neighbouring cells differ by 1 / (N - 1) in two inputs, and
a small MLP's values blur across them (greedy loops between neighbours).

Sensors with errors (``blind_spots`` of :func:`grid_views`): a view may have a persistent blind spot,
a set of lava cells it reads as free (the patch shows free terrain there, the rays pass through).
:func:`lava_blind_spots` draws one from a seed; two views with different seeds misread different
cells, so neither alone tells every lava step while together they can (docs/preregistration.md).
The dynamics and rewards do not change, only what the views report.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from dospcot.envs.masking import RewardMaskWrapper
from dospcot.envs.views import MultiViewWrapper, View, select_views

FREE, WALL, LAVA, GOAL, OFF_GRID = range(5)
N_TERRAIN = 5
MOVES = np.array([(-1, 0), (0, 1), (1, 0), (0, -1)])
DIRECTIONS_8 = [(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)]
COMPASSES: tuple[str, ...] = ("none", "axes", "cell")
RAY_ENCODINGS: tuple[str, ...] = ("distance", "inverse")
_CHARS = {".": FREE, "#": WALL, "L": LAVA, "G": GOAL, "S": FREE}


@dataclass(frozen=True)
class GridLayout:
    """A square map.

    :param terrain: int array (N, N) of FREE, WALL, LAVA or GOAL; exactly one GOAL.
    :param start: (row, column) of the start, a FREE cell.
    """

    terrain: np.ndarray
    start: tuple[int, int]

    def __post_init__(self) -> None:
        n = self.terrain.shape[0]
        if self.terrain.ndim != 2 or self.terrain.shape != (n, n) or n < 2:
            raise ValueError(f"a layout must be a square of side >= 2, got shape {self.terrain.shape}")
        if (self.terrain == GOAL).sum() != 1:
            raise ValueError(f"a layout needs exactly one goal, got {(self.terrain == GOAL).sum()}")
        if self.terrain[self.start] != FREE:
            raise ValueError(f"the start {self.start} must be a free cell")

    @property
    def size(self) -> int:
        return int(self.terrain.shape[0])

    @property
    def goal(self) -> tuple[int, int]:
        row, col = np.argwhere(self.terrain == GOAL)[0]
        return int(row), int(col)

    @classmethod
    def from_text(cls, text: str) -> GridLayout:
        """Parse a map: ``.`` free, ``#`` wall, ``L`` lava, ``S`` start, ``G`` goal; one row a line."""
        lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
        unknown = sorted({ch for line in lines for ch in line} - set(_CHARS))
        if unknown:
            raise ValueError(f"unknown map character(s) {unknown}; allowed: {sorted(_CHARS)}")
        starts = [(r, c) for r, line in enumerate(lines) for c, ch in enumerate(line) if ch == "S"]
        if len(starts) != 1:
            raise ValueError(f"a map needs exactly one start 'S', got {len(starts)}")
        if len({len(line) for line in lines}) != 1:
            raise ValueError("every map row must have the same length")
        terrain = np.array([[_CHARS[ch] for ch in line] for line in lines], dtype=np.int64)
        return cls(terrain, starts[0])

    def to_text(self) -> str:
        """The map as :meth:`from_text` reads it."""
        chars = {FREE: ".", WALL: "#", LAVA: "L", GOAL: "G"}
        rows = [[chars[int(t)] for t in row] for row in self.terrain]
        rows[self.start[0]][self.start[1]] = "S"
        return "\n".join("".join(row) for row in rows)

    @classmethod
    def random(
        cls, size: int, seed: int, lava_density: float = 0.1, wall_density: float = 0.1, max_tries: int = 1000
    ) -> GridLayout:
        """A seeded solvable layout: start in the bottom-left corner box, goal in the top-right one
        (boxes of side N // 4), so the shortest path crosses the map.

        Lava and walls are drawn cell by cell; a draw whose goal cannot be reached without lava is
        discarded and drawn again from the same generator.
        """
        if size < 4:
            raise ValueError(f"size must be >= 4 for a random layout, got {size}")
        if not (0 <= lava_density < 1 and 0 <= wall_density < 1 and lava_density + wall_density < 0.9):
            raise ValueError(
                f"lava_density and wall_density must lie in [0, 1) with a sum below 0.9, "
                f"got {lava_density} and {wall_density}"
            )
        rng = np.random.default_rng(seed)
        box = max(size // 4, 1)
        for _ in range(max_tries):
            terrain = np.full((size, size), FREE, dtype=np.int64)
            u = rng.random((size, size))
            terrain[u < lava_density] = LAVA
            terrain[(u >= lava_density) & (u < lava_density + wall_density)] = WALL
            start = (int(rng.integers(size - box, size)), int(rng.integers(0, box)))
            goal = (int(rng.integers(0, box)), int(rng.integers(size - box, size)))
            terrain[start] = FREE
            terrain[goal] = GOAL
            layout = cls(terrain, start)
            if layout.solvable():
                return layout
        raise RuntimeError(f"no solvable layout in {max_tries} draws; lower lava_density or wall_density")

    def solvable(self) -> bool:
        """Whether the goal can be reached from the start through free cells (no lava)."""
        n = self.size
        seen = np.zeros((n, n), dtype=bool)
        queue = deque([self.start])
        seen[self.start] = True
        while queue:
            r, c = queue.popleft()
            if self.terrain[r, c] == GOAL:
                return True
            for dr, dc in MOVES:
                nr, nc = r + dr, c + dc
                if 0 <= nr < n and 0 <= nc < n and not seen[nr, nc] and self.terrain[nr, nc] in (FREE, GOAL):
                    seen[nr, nc] = True
                    queue.append((nr, nc))
        return False

    def cell(self, row: int, col: int) -> int:
        """Terrain at (row, col), OFF_GRID outside the map."""
        n = self.size
        return int(self.terrain[row, col]) if 0 <= row < n and 0 <= col < n else OFF_GRID


class GridWorld(gym.Env):
    """An N x N grid world with a discrete state (row * N + column) and 4 actions.

    :param layout: the map; if None, ``GridLayout.random(size, layout_seed, lava_density, wall_density)``.
    :param size: side of a random layout.
    :param layout_seed: seed of a random layout.
    :param lava_density: share of lava cells in a random layout.
    :param wall_density: share of wall cells in a random layout.
    :param step_cost: reward of an ordinary step.
    :param lava_penalty: reward of a step into lava (which returns to the start).
    :param goal_reward: reward of the step into the goal (which ends the episode).
    :param exploring_starts: start each episode on a uniformly drawn free cell (from ``np_random``)
        rather than the map's start; lava still returns to the map's start, and
        ``initial_state_distrib`` (what :class:`~dospcot.envs.TabularMDP` and the metrics evaluate
        from) stays the map's start.
    :param render_mode: None or ``"ansi"``.
    """

    metadata = {"render_modes": ["ansi"]}  # noqa: RUF012

    def __init__(
        self,
        layout: GridLayout | str | None = None,
        size: int = 16,
        layout_seed: int = 0,
        lava_density: float = 0.1,
        wall_density: float = 0.1,
        step_cost: float = -1.0,
        lava_penalty: float = -100.0,
        goal_reward: float = 0.0,
        exploring_starts: bool = False,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(layout, str):
            layout = GridLayout.from_text(layout)
        self.layout = layout or GridLayout.random(size, layout_seed, lava_density, wall_density)
        if render_mode not in (None, "ansi"):
            raise ValueError(f"render_mode must be None or 'ansi', got {render_mode!r}")
        self.render_mode = render_mode
        n = self.layout.size
        self.observation_space = gym.spaces.Discrete(n * n)
        self.action_space = gym.spaces.Discrete(4)
        self.start_state = self.layout.start[0] * n + self.layout.start[1]
        self.next_state, self.reward, self.terminal = self._tables(step_cost, lava_penalty, goal_reward)
        # The toy-text interface, so TabularMDP.from_env and value iteration work unchanged.
        self.P = {
            s: {
                a: [(1.0, int(self.next_state[s, a]), float(self.reward[s, a]), bool(self.terminal[s, a]))]
                for a in range(4)
            }
            for s in range(n * n)
        }
        self.initial_state_distrib = np.zeros(n * n)
        self.initial_state_distrib[self.start_state] = 1.0
        self.s = self.start_state
        self.exploring_starts = exploring_starts
        self._free_states = np.flatnonzero(self.layout.terrain.reshape(-1) == FREE)

    def _tables(self, step_cost: float, lava_penalty: float, goal_reward: float):
        n, terrain = self.layout.size, self.layout.terrain
        rows, cols = np.divmod(np.arange(n * n), n)
        target_r = np.clip(rows[:, None] + MOVES[None, :, 0], 0, n - 1)
        target_c = np.clip(cols[:, None] + MOVES[None, :, 1], 0, n - 1)
        blocked = terrain[target_r, target_c] == WALL
        target_r = np.where(blocked, rows[:, None], target_r)
        target_c = np.where(blocked, cols[:, None], target_c)
        kind = terrain[target_r, target_c]
        next_state = np.where(kind == LAVA, self.start_state, target_r * n + target_c)
        reward = np.select([kind == LAVA, kind == GOAL], [lava_penalty, goal_reward], default=step_cost)
        terminal = kind == GOAL
        # Rows of wall, lava and goal cells are never used from the start; they stay for the P table.
        return next_state.astype(np.int64), reward.astype(np.float64), terminal

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if self.exploring_starts:
            self.s = int(self._free_states[self.np_random.integers(self._free_states.size)])
        else:
            self.s = self.start_state
        return self.s, {}

    def step(self, action: int):
        a = int(action)
        s = self.s
        self.s = int(self.next_state[s, a])
        return self.s, float(self.reward[s, a]), bool(self.terminal[s, a]), False, {}

    def render(self) -> str | None:
        if self.render_mode != "ansi":
            return None
        n = self.layout.size
        rows = [list(line) for line in self.layout.to_text().replace("S", ".").splitlines()]
        r, c = divmod(self.s, n)
        rows[r][c] = "A"
        return "\n".join("".join(row) for row in rows)


TERRAIN_VIEWS: tuple[str, ...] = ("patch", "rays")
"""The views that read the terrain, and so can have a blind spot."""


def lava_blind_spots(layout: GridLayout, rate: float, seed: int | Sequence[int]) -> np.ndarray:
    """A sensor's blind spot: ``round(rate * n_lava)`` of the layout's lava cells, drawn from ``seed``.

    :param layout: the map.
    :param rate: the share of lava cells the sensor misreads, in [0, 1].
    :param seed: the sensor's seed (an int or a sequence of ints, as numpy's ``default_rng`` takes);
        the same seed always gives the same cells.
    :return: bool (N, N), True on the misread lava cells.
    """
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"a blind-spot rate must lie in [0, 1], got {rate}")
    lava = np.flatnonzero(layout.terrain.reshape(-1) == LAVA)
    chosen = np.random.default_rng(seed).permutation(lava)[: round(rate * lava.size)]
    blind = np.zeros(layout.size * layout.size, dtype=bool)
    blind[chosen] = True
    return blind.reshape(layout.size, layout.size)


def view_blind_spots(
    layout: GridLayout, rate: float, seed: int, identical: bool = False
) -> dict[str, np.ndarray]:
    """The blind spot of every terrain view of a run: view j of :data:`TERRAIN_VIEWS` draws from the
    seed ``[seed, j]``, or with ``identical`` every view from ``[seed, 0]`` (the control in which no
    view can correct another)."""
    return {
        name: lava_blind_spots(layout, rate, [seed, 0 if identical else j])
        for j, name in enumerate(TERRAIN_VIEWS)
    }


def misread(layout: GridLayout, blind: np.ndarray) -> GridLayout:
    """The map as a sensor with blind spot ``blind`` (bool (N, N), lava cells only) perceives it."""
    if blind.shape != layout.terrain.shape:
        raise ValueError(f"a blind spot must have the map's shape {layout.terrain.shape}, got {blind.shape}")
    if np.any(blind & (layout.terrain != LAVA)):
        raise ValueError("a blind spot may hold lava cells only")
    return GridLayout(np.where(blind, FREE, layout.terrain), layout.start)


def grid_views(
    layout: GridLayout,
    patch_size: int = 5,
    compass: str = "none",
    blind_spots: Mapping[str, np.ndarray] | None = None,
    ray_encoding: str = "distance",
) -> dict[str, View]:
    """The ``coords``, ``patch`` and ``rays`` views of a layout, by name; ``compass`` (one of
    :data:`COMPASSES`) appends the goal's offset to every view, and ``ray_encoding`` (one of
    :data:`RAY_ENCODINGS`) sets how ``rays`` reads a distance (see the module docstring).

    :param blind_spots: view name (of :data:`TERRAIN_VIEWS`) -> bool (N, N), the lava cells that view
        reads as free (see :func:`lava_blind_spots`).
    """
    if patch_size < 1 or patch_size % 2 == 0:
        raise ValueError(f"patch_size must be odd and positive, got {patch_size}")
    if compass not in COMPASSES:
        raise ValueError(f"compass must be one of {COMPASSES}, got {compass!r}")
    if ray_encoding not in RAY_ENCODINGS:
        raise ValueError(f"ray_encoding must be one of {RAY_ENCODINGS}, got {ray_encoding!r}")
    blind_spots = dict(blind_spots or {})
    unknown = sorted(set(blind_spots) - set(TERRAIN_VIEWS))
    if unknown:
        raise ValueError(f"blind spots for view(s) {unknown}; only {list(TERRAIN_VIEWS)} read the terrain")
    perceived = {name: misread(layout, blind) for name, blind in blind_spots.items()}
    n = layout.size
    goal_r, goal_c = layout.goal
    scale = max(n - 1, 1)
    rows, cols = np.divmod(np.arange(n * n), n)
    coords_table = np.stack([rows, cols, goal_r - rows, goal_c - cols], axis=1).astype(np.float32) / scale
    tables = {
        "coords": coords_table,
        "patch": _patch_table(perceived.get("patch", layout), patch_size),
        "rays": _ray_table(perceived.get("rays", layout), ray_encoding),
    }
    if compass == "axes":
        offsets = np.eye(2 * n - 1, dtype=np.float32)
        heading = np.concatenate([offsets[goal_r - rows + n - 1], offsets[goal_c - cols + n - 1]], axis=1)
    elif compass == "cell":  # with the goal fixed, each cell has its own offset pair: one input per cell
        heading = np.eye(n * n, dtype=np.float32)
    if compass != "none":
        tables = {name: np.concatenate([table, heading], axis=1) for name, table in tables.items()}

    def view(name: str, table: np.ndarray, low: float) -> View:
        space = gym.spaces.Box(low, 1.0, (table.shape[1],), np.float32)
        return View(name, space, lambda state: table[int(state)])

    return {name: view(name, table, -1.0 if name == "coords" else 0.0) for name, table in tables.items()}


def _patch_table(layout: GridLayout, patch_size: int) -> np.ndarray:
    """(N*N, k*k*5) the one-hot terrain of the k x k window around every cell."""
    n, half = layout.size, patch_size // 2
    padded = np.pad(layout.terrain, half, constant_values=OFF_GRID)
    rows, cols = np.divmod(np.arange(n * n), n)
    windows = np.stack(
        [padded[r : r + patch_size, c : c + patch_size] for r, c in zip(rows, cols, strict=True)]
    )
    return np.eye(N_TERRAIN, dtype=np.float32)[windows].reshape(n * n, -1)


def _ray_table(layout: GridLayout, encoding: str = "distance") -> np.ndarray:
    """(N*N, 24) the nearest lava, wall-or-edge and goal along 8 directions, as d / N or 1 / d."""
    n = layout.size
    steps = np.zeros((n * n, 8, 3), dtype=np.float32)  # distance in cells, 0 where there is none
    for state in range(n * n):
        r, c = divmod(state, n)
        for d, (dr, dc) in enumerate(DIRECTIONS_8):
            for step in range(1, n + 1):
                kind = layout.cell(r + dr * step, c + dc * step)
                for i, wanted in enumerate((LAVA, WALL, GOAL)):
                    hit = kind == wanted or (wanted == WALL and kind == OFF_GRID)
                    if hit and not steps[state, d, i]:
                        steps[state, d, i] = step
                if kind == OFF_GRID:
                    break
    found = steps > 0
    if encoding == "inverse":
        table = np.divide(1.0, steps, out=np.zeros_like(steps), where=found)
    else:
        table = np.where(found, steps / n, 1.0).astype(np.float32)
    return table.reshape(n * n, 24)


def make_masked_gridworld(
    label_fraction: float = 0.05,
    views: Sequence[str] = ("coords", "patch"),
    mask_seed: int = 0,
    max_episode_steps: int | None = None,
    patch_size: int = 5,
    compass: str = "none",
    blind_spots: Mapping[str, np.ndarray] | None = None,
    monitored_columns: int = 0,
    ray_encoding: str = "distance",
    **grid_kwargs: Any,
) -> gym.Env:
    """A :class:`GridWorld` with a step limit (default 4 N), state-action masking and views in ``info``.

    ``compass``, ``blind_spots`` and ``ray_encoding`` go to :func:`grid_views`; with
    ``monitored_columns`` every reward of a state in the first that many columns is revealed
    (:func:`monitored_states`)."""
    base = GridWorld(**grid_kwargs)
    selected = select_views(grid_views(base.layout, patch_size, compass, blind_spots, ray_encoding), views)
    env = gym.wrappers.TimeLimit(base, max_episode_steps or 4 * base.layout.size)
    monitored = monitored_states(base.layout.size, monitored_columns) if monitored_columns else None
    env = RewardMaskWrapper(
        env, label_fraction, mode="state-action", mask_seed=mask_seed, monitored_states=monitored
    )
    return MultiViewWrapper(env, selected)


def monitored_states(size: int, columns: int) -> np.ndarray:
    """bool (N * N,): the states of the map's first ``columns`` columns, which a reward monitor sees."""
    if not 0 <= columns <= size:
        raise ValueError(f"monitored columns must lie in [0, {size}], got {columns}")
    return np.tile(np.arange(size) < columns, size)
