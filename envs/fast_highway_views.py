"""The fast highway's two sensor views, computed as highway-env computes its default
``KinematicObservation`` (``"kinematics"``) and ``OccupancyGridObservation`` (``"occupancy"``) for the
same vehicles (:mod:`dospcot.envs.fast_highway`)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from dospcot.config.task_sections import FAST_HIGHWAY_VIEWS
from dospcot.envs.highway_constants import (
    GRID_CELLS,
    GRID_FEATURES,
    GRID_LOW,
    GRID_STEP,
    KIN_FEATURES,
    KIN_VEHICLES,
    LANE_WIDTH,
    LENGTH,
    MAX_SPEED,
    PERCEPTION_DISTANCE,
    ROAD_PERCEPTION,
    lmap,
)

VIEW_NAMES: tuple[str, ...] = FAST_HIGHWAY_VIEWS

VIEW_SHAPES: dict[str, tuple[int, ...]] = {
    "kinematics": (KIN_VEHICLES, KIN_FEATURES),
    "occupancy": (GRID_FEATURES, GRID_CELLS, GRID_CELLS),
}


def view_space(name: str) -> gym.spaces.Box:
    """The ``Box(-inf, inf, shape, float32)`` of a view: (5, 5) kinematics, (4, 11, 11) occupancy."""
    if name not in VIEW_SHAPES:
        raise ValueError(f"unknown view {name!r}; allowed: {list(VIEW_NAMES)}")
    return gym.spaces.Box(-np.inf, np.inf, shape=VIEW_SHAPES[name], dtype=np.float32)


def kinematics_view(
    x: np.ndarray, y: np.ndarray, speed: np.ndarray, heading: np.ndarray, lanes_count: int
) -> np.ndarray:
    """highway-env's default ``KinematicObservation`` of the ego (column 0) in each env.

    :param x, y: positions [m], shape (n, V), ego in column 0.
    :param speed: [m/s], shape (n, V).
    :param heading: [rad], shape (n, V).
    :param lanes_count: number of lanes; sets the y normalisation range ``±4 * lanes_count`` m.
    :return: (n, 5, 5) float32 rows (presence, x, y, vx, vy): the ego absolute, then up to 4 vehicles
        relative to it, nearest first; everything normalised and clipped to [-1, 1], missing rows 0.
    """
    n, n_vehicles = x.shape
    vx = speed * np.cos(heading)
    vy = speed * np.sin(heading)
    y_max = LANE_WIDTH * lanes_count
    ranges = ((-PERCEPTION_DISTANCE, PERCEPTION_DISTANCE), (-y_max, y_max), (-2 * MAX_SPEED, 2 * MAX_SPEED))
    obs = np.zeros((n, KIN_VEHICLES, KIN_FEATURES))
    obs[:, 0, 0] = 1.0
    for k, (values, (lo, hi)) in enumerate(zip((x, y, vx, vy), ranges + ranges[-1:], strict=True)):
        obs[:, 0, 1 + k] = lmap(values[:, 0], lo, hi, -1.0, 1.0)
    n_rows = min(KIN_VEHICLES - 1, n_vehicles - 1)
    if n_rows > 0:
        dx = x[:, 1:] - x[:, :1]
        dy = y[:, 1:] - y[:, :1]
        # Road.close_objects_to(see_behind=False): nearer than PERCEPTION_DISTANCE and less than two
        # lengths behind, sorted (stably, in road order) by the longitudinal distance.
        visible = (np.sqrt(dx * dx + dy * dy) < PERCEPTION_DISTANCE) & (dx > -2 * LENGTH)
        key = np.where(visible, np.abs(dx), np.inf)
        order = np.argsort(key, axis=1, kind="stable")[:, :n_rows]
        shown = np.take_along_axis(visible, order, axis=1)
        rel = (dx, dy, vx[:, 1:] - vx[:, :1], vy[:, 1:] - vy[:, :1])
        obs[:, 1 : 1 + n_rows, 0] = shown
        for k, (values, (lo, hi)) in enumerate(zip(rel, ranges + ranges[-1:], strict=True)):
            picked = lmap(np.take_along_axis(values, order, axis=1), lo, hi, -1.0, 1.0)
            obs[:, 1 : 1 + n_rows, 1 + k] = np.where(shown, picked, 0.0)
    return np.clip(obs, -1.0, 1.0).astype(np.float32)


def occupancy_view(
    x: np.ndarray, y: np.ndarray, speed: np.ndarray, heading: np.ndarray, lanes_count: int
) -> np.ndarray:
    """highway-env's default ``OccupancyGridObservation`` around the ego (column 0) in each env.

    :param x, y: positions [m], shape (n, V), ego in column 0.
    :param speed: [m/s], shape (n, V).
    :param heading: [rad], shape (n, V).
    :param lanes_count: number of lanes (centres at y = 0, 4, ...), for the on-road layer.
    :return: (n, 4, 11, 11) float32 layers (presence, vx, vy, on_road) over 5 m cells from -27.5 m to
        27.5 m around the ego, world-aligned, indexed ``[layer, x cell, y cell]``; velocities relative
        to the ego with ±80 m/s mapped to ±1 and clipped. The ego itself occupies the centre cell.
    """
    n, n_vehicles = x.shape
    vx = speed * np.cos(heading)
    vy = speed * np.sin(heading)
    ix = np.floor((x - x[:, :1] - GRID_LOW) / GRID_STEP)
    iy = np.floor((y - y[:, :1] - GRID_LOW) / GRID_STEP)
    inside = (ix >= 0) & (ix < GRID_CELLS) & (iy >= 0) & (iy < GRID_CELLS)
    n_cells = GRID_CELLS * GRID_CELLS
    cell = (np.arange(n)[:, None] * n_cells + ix * GRID_CELLS + iy).astype(np.intp)
    # highway-env writes the vehicles in reverse road order, so the earliest vehicle of a shared
    # cell (the ego first) is the one left in it: keep the smallest vehicle index per cell.
    winner = np.full(n * n_cells, n_vehicles, dtype=np.intp)
    vehicle_index = np.broadcast_to(np.arange(n_vehicles), (n, n_vehicles))
    np.minimum.at(winner, cell[inside], vehicle_index[inside])
    winner = winner.reshape(n, n_cells)
    occupied = winner < n_vehicles
    source = np.where(occupied, winner, 0)

    grid = np.zeros((n, GRID_FEATURES, n_cells))
    grid[:, 0] = occupied
    for layer, v in ((1, vx), (2, vy)):
        normalised = lmap(v - v[:, :1], -2 * MAX_SPEED, 2 * MAX_SPEED, -1.0, 1.0)
        grid[:, layer] = np.where(occupied, np.take_along_axis(normalised, source, axis=1), 0.0)
    grid = grid.reshape(n, GRID_FEATURES, GRID_CELLS, GRID_CELLS)

    # fill_road_layer_by_lanes: waypoints every 5 m within ±100 m of the ego along each lane,
    # generated exactly as np.arange does (start, start + step, then start + i * delta).
    start = x[:, 0] - ROAD_PERCEPTION
    stop = x[:, 0] + ROAD_PERCEPTION
    n_waypoints = np.ceil((stop - start) / GRID_STEP).astype(np.intp)
    steps = np.arange(int(n_waypoints.max()) if n else 0)
    delta = (start + GRID_STEP) - start
    waypoints = start[:, None] + steps * delta[:, None]
    waypoints = np.clip(waypoints, 0.0, None)  # lanes start at x = 0 (their 10 km end is never in range)
    wx = np.floor((waypoints - x[:, :1] - GRID_LOW) / GRID_STEP)
    lane_y = LANE_WIDTH * np.arange(lanes_count)
    wy = np.floor((lane_y[None, :] - y[:, :1] - GRID_LOW) / GRID_STEP)  # (n, lanes)
    wx_all = np.broadcast_to(wx[:, None, :], (n, lanes_count, steps.size))
    wy_all = np.broadcast_to(wy[:, :, None], (n, lanes_count, steps.size))
    valid = (
        (steps[None, None, :] < n_waypoints[:, None, None])
        & (wx_all >= 0)
        & (wx_all < GRID_CELLS)
        & (wy_all >= 0)
        & (wy_all < GRID_CELLS)
    )
    env_index = np.broadcast_to(np.arange(n)[:, None, None], valid.shape)
    grid[env_index[valid], 3, wx_all[valid].astype(np.intp), wy_all[valid].astype(np.intp)] = 1.0
    return np.clip(grid, -1.0, 1.0).astype(np.float32)


VIEW_FUNCTIONS = {"kinematics": kinematics_view, "occupancy": occupancy_view}
