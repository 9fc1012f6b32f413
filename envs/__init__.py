"""Tasks with mostly hidden rewards, reward masking and multi-view wrappers (``dospcot.envs``)."""

from gymnasium.envs.registration import register

from dospcot.envs.cliffwalking import CLIFF_VIEWS, make_masked_cliffwalking
from dospcot.envs.masking import RewardMaskWrapper, StateActionMask, check_label_fraction
from dospcot.envs.tabular import TabularMDP
from dospcot.envs.views import MultiViewWrapper, View, ViewObservationWrapper, select_views

register(id="dospcot/MaskedCliffWalking-v1", entry_point="dospcot.envs.cliffwalking:make_masked_cliffwalking")

__all__ = [
    "CLIFF_VIEWS",
    "MultiViewWrapper",
    "RewardMaskWrapper",
    "StateActionMask",
    "TabularMDP",
    "View",
    "ViewObservationWrapper",
    "check_label_fraction",
    "make_masked_cliffwalking",
    "select_views",
]
