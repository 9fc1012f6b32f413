"""Tasks with mostly hidden rewards, reward masking and multi-view wrappers (``dospcot.envs``)."""

from gymnasium.envs.registration import register

from dospcot.envs.cliffwalking import CLIFF_VIEWS, make_masked_cliffwalking
from dospcot.envs.fast_highway import FastHighwayConfig, FastHighwayEnv, FastHighwayVec
from dospcot.envs.finite_check import EnvRaisedError, FiniteCheckWrapper, NonFiniteError
from dospcot.envs.gridworld import (
    GridLayout,
    GridWorld,
    grid_views,
    lava_blind_spots,
    make_masked_gridworld,
    monitored_states,
    view_blind_spots,
)
from dospcot.envs.gym_sensors import ObservationSensors, make_gym_env, make_masked_gym
from dospcot.envs.masked_highway import make_highway, make_masked_highway
from dospcot.envs.masking import RewardMaskWrapper, StateActionMask, check_label_fraction
from dospcot.envs.sensors import SensorViewWrapper
from dospcot.envs.tabular import TabularMDP
from dospcot.envs.views import MultiViewWrapper, View, ViewObservationWrapper, select_views

register(id="dospcot/MaskedCliffWalking-v1", entry_point="dospcot.envs.cliffwalking:make_masked_cliffwalking")
register(id="dospcot/GridWorld-v0", entry_point="dospcot.envs.gridworld:GridWorld", max_episode_steps=64)
register(id="dospcot/MaskedGridWorld-v0", entry_point="dospcot.envs.gridworld:make_masked_gridworld")
# Highway driving: our fast env, and every task masked per transition with sensor views (highway-env's
# need the `highway` extra; it is imported only when one is made).
register(id="dospcot/FastHighway-v0", entry_point="dospcot.envs.fast_highway:FastHighwayEnv")
register(
    id="dospcot/MaskedFastHighway-v0",
    entry_point="dospcot.envs.masked_highway:make_masked_highway",
    kwargs={"env_id": "dospcot/FastHighway-v0"},
)
for _env_id in ("highway-fast-v0", "merge-v0", "roundabout-v0"):
    _name = "".join(part.capitalize() for part in _env_id[:-3].split("-"))
    register(
        id=f"dospcot/Masked{_name}-v0",
        entry_point="dospcot.envs.masked_highway:make_masked_highway",
        kwargs={"env_id": _env_id},
    )

__all__ = [
    "CLIFF_VIEWS",
    "EnvRaisedError",
    "FastHighwayConfig",
    "FastHighwayEnv",
    "FastHighwayVec",
    "FiniteCheckWrapper",
    "GridLayout",
    "GridWorld",
    "MultiViewWrapper",
    "NonFiniteError",
    "ObservationSensors",
    "RewardMaskWrapper",
    "SensorViewWrapper",
    "StateActionMask",
    "TabularMDP",
    "View",
    "ViewObservationWrapper",
    "check_label_fraction",
    "grid_views",
    "lava_blind_spots",
    "make_gym_env",
    "make_highway",
    "make_masked_cliffwalking",
    "make_masked_gridworld",
    "make_masked_gym",
    "make_masked_highway",
    "monitored_states",
    "select_views",
    "view_blind_spots",
]
