"""Tasks with mostly hidden rewards, reward masking and multi-view wrappers (``dospcot.envs``)."""

from gymnasium.envs.registration import register

from dospcot.envs.cliffwalking import CLIFF_VIEWS, make_masked_cliffwalking
from dospcot.envs.finite_check import FiniteCheckWrapper, NonFiniteError
from dospcot.envs.gridworld import GridLayout, GridWorld, grid_views, make_masked_gridworld
from dospcot.envs.masking import RewardMaskWrapper, StateActionMask, check_label_fraction
from dospcot.envs.tabular import TabularMDP
from dospcot.envs.views import MultiViewWrapper, View, ViewObservationWrapper, select_views

register(id="dospcot/MaskedCliffWalking-v1", entry_point="dospcot.envs.cliffwalking:make_masked_cliffwalking")
register(id="dospcot/GridWorld-v0", entry_point="dospcot.envs.gridworld:GridWorld", max_episode_steps=64)
register(id="dospcot/MaskedGridWorld-v0", entry_point="dospcot.envs.gridworld:make_masked_gridworld")

__all__ = [
    "CLIFF_VIEWS",
    "FiniteCheckWrapper",
    "GridLayout",
    "GridWorld",
    "MultiViewWrapper",
    "NonFiniteError",
    "RewardMaskWrapper",
    "StateActionMask",
    "TabularMDP",
    "View",
    "ViewObservationWrapper",
    "check_label_fraction",
    "grid_views",
    "make_masked_cliffwalking",
    "make_masked_gridworld",
    "select_views",
]
