"""highway-env's constants and helpers as the fast highway (:mod:`dospcot.envs.fast_highway`) copies
them: its vehicles, controllers and observation defaults, and its ``utils.lmap`` and ``utils.not_zero``
with the same operation order, so that results match highway-env's to the bit."""

from __future__ import annotations

import numpy as np

# highway-env's constants (vehicle/kinematics.py, vehicle/controller.py, vehicle/behavior.py, road/lane.py).
LANE_WIDTH = 4.0  # [m]
LENGTH = 5.0  # [m]
WIDTH = 2.0  # [m]
MAX_SPEED = 40.0  # [m/s]
MIN_SPEED = -40.0  # [m/s]
SPEED_LIMIT = 30.0  # [m/s], of every lane of the straight road
TARGET_SPEEDS = np.array([20.0, 25.0, 30.0])  # [m/s], MDPVehicle.DEFAULT_TARGET_SPEEDS
EGO_INITIAL_SPEED = 25.0  # [m/s]
KP_A = 1 / 0.6  # [1/s]
KP_HEADING = 1 / 0.2  # [1/s]
KP_LATERAL = 1 / 0.6  # [1/s]
MAX_STEERING_ANGLE = np.pi / 3  # [rad]
IDM_ACC_MAX = 6.0  # [m/s2]
IDM_COMFORT_ACC_MAX = 3.0  # [m/s2]
IDM_COMFORT_ACC_MIN = -5.0  # [m/s2]
IDM_DISTANCE_WANTED = 5.0 + LENGTH  # [m]
IDM_TIME_WANTED = 1.5  # [s]
IDM_DELTA_RANGE = (3.5, 4.5)
PERCEPTION_DISTANCE = 5.0 * MAX_SPEED  # [m]

# Observation defaults (envs/common/observation.py).
KIN_VEHICLES = 5
KIN_FEATURES = 5  # presence, x, y, vx, vy
GRID_LOW = -27.5  # [m], both axes
GRID_STEP = 5.0  # [m]
GRID_CELLS = 11
GRID_FEATURES = 4  # presence, vx, vy, on_road
ROAD_PERCEPTION = 100.0  # [m], fill_road_layer_by_lanes' lane_perception_distance


def lmap(v: np.ndarray, x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """highway-env's ``utils.lmap``, with the same operation order so that results match to the bit."""
    return y0 + (v - x0) * (y1 - y0) / (x1 - x0)


def not_zero(x: np.ndarray, eps: float = 1e-2) -> np.ndarray:
    """highway-env's ``utils.not_zero``: values within ``eps`` of 0 become ``±eps``."""
    return np.where(np.abs(x) > eps, x, np.where(x >= 0, eps, -eps))
