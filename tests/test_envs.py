"""Masking, views and the tabular form of CliffWalking."""

import gymnasium as gym
import numpy as np
import pytest

from dospcot.envs import (
    CLIFF_VIEWS,
    RewardMaskWrapper,
    StateActionMask,
    TabularMDP,
    make_masked_cliffwalking,
)
from dospcot.envs.cliffwalking import patch_view


@pytest.mark.parametrize("fraction", [0.01, 0.1, 0.25, 0.5, 1.0])
def test_mask_reveals_exactly_round_fraction_of_keys(fraction):
    mask = StateActionMask(48, 4, fraction, seed=3)
    assert mask.labelled.sum() == max(1, round(fraction * 192))


def test_mask_same_across_resets_and_differs_across_seeds():
    env = make_masked_cliffwalking(0.1, mask_seed=7)
    first = _mask_of(env).copy()
    for reset_seed in range(3):
        env.reset(seed=reset_seed)
        assert np.array_equal(_mask_of(env), first)
    other = _mask_of(make_masked_cliffwalking(0.1, mask_seed=8))
    assert not np.array_equal(first, other)
    assert np.array_equal(first, _mask_of(make_masked_cliffwalking(0.1, mask_seed=7)))


def _mask_of(env):
    wrapper = env
    while not isinstance(wrapper, RewardMaskWrapper):
        wrapper = wrapper.env
    return wrapper.mask.labelled


def test_masked_step_hides_reward_and_keeps_truth_in_info():
    env = make_masked_cliffwalking(0.5, mask_seed=0)
    labelled = _mask_of(env)
    obs, info = env.reset(seed=0)
    assert set(info["views"]) == {"coords", "patch"}
    seen = {True: 0, False: 0}
    for action in [0, 1, 1, 2, 1, 3, 0, 0, 1, 2] * 5:
        nxt, reward, terminated, truncated, info = env.step(action)
        observed = bool(labelled[obs, action])
        assert info["reward_observed"] == observed
        assert reward == (info["hidden_reward"] if observed else 0.0)
        seen[observed] += 1
        obs = nxt
        if terminated or truncated:
            obs, _ = env.reset()
    assert seen[True] and seen[False]


def test_transition_mode_reveals_about_fraction_of_steps():
    env = RewardMaskWrapper(gym.make("CliffWalking-v1"), 0.3, mode="transition", mask_seed=1)
    env.reset(seed=0)
    observed = [env.step(0)[4]["reward_observed"] for _ in range(4000)]
    assert abs(np.mean(observed) - 0.3) < 0.03


@pytest.mark.parametrize("fraction", [0.0, -0.1, 1.5, float("nan")])
def test_bad_label_fraction_raises_naming_argument(fraction):
    with pytest.raises(ValueError, match="label_fraction"):
        make_masked_cliffwalking(fraction)


def test_unknown_view_raises_naming_allowed_views():
    with pytest.raises(ValueError, match=r"unknown view.*allowed: \['coords', 'onehot', 'patch'\]"):
        make_masked_cliffwalking(0.1, views=("coords", "lidar"))


def test_state_action_mode_needs_discrete_spaces():
    with pytest.raises(ValueError, match="Discrete observation_space"):
        RewardMaskWrapper(gym.make("CartPole-v1"), 0.1, mode="state-action")
    with pytest.raises(ValueError, match="mode must be one of"):
        RewardMaskWrapper(gym.make("CliffWalking-v1"), 0.1, mode="episode")


def test_patch_view_of_start_state_by_hand():
    # Start (3, 0): above row is free, left column and bottom row are off-grid, right is cliff.
    patch = patch_view(36).reshape(3, 3, 4).argmax(-1)
    free, cliff, off = 0, 1, 3
    assert patch.tolist() == [[off, free, free], [off, free, cliff], [off, off, off]]
    # (2, 10): the cell below is cliff, below-right is the goal.
    assert patch_view(34).reshape(3, 3, 4).argmax(-1)[2].tolist() == [cliff, cliff, 2]


def test_tabular_mdp_steps_like_the_gymnasium_env():
    env = make_masked_cliffwalking(0.2, views=tuple(CLIFF_VIEWS), mask_seed=4)
    mdp = TabularMDP.from_env(env, CLIFF_VIEWS, max_episode_steps=100)
    rng = np.random.default_rng(0)
    state, info = env.reset(seed=0)
    assert state == mdp.start_state
    for _ in range(300):
        action = int(rng.integers(4))
        nxt, _, terminated, truncated, info = env.step(action)
        assert nxt == mdp.next_state[state, action]
        assert info["hidden_reward"] == mdp.reward[state, action]
        assert terminated == mdp.terminal[state, action]
        for name, features in info["views"].items():
            assert np.array_equal(features, mdp.views[name][nxt])
        state = nxt
        if terminated or truncated:
            state, _ = env.reset()


def test_value_iteration_gives_the_cliff_edge_path():
    mdp = TabularMDP.from_env(make_masked_cliffwalking(), CLIFF_VIEWS, 100)
    q = mdp.value_iteration(discount=1.0)
    assert q[36].max() == pytest.approx(-13.0)  # up, 11 steps right, down
    optimal = mdp.optimal_actions(discount=1.0)
    assert optimal[36, 0] and not optimal[36, 1]
    assert all(optimal[24 + col, 1] for col in range(11))  # row 2 walks right along the cliff edge
    reachable = mdp.reachable_nonterminal()
    assert reachable.sum() == 37 and not reachable[37:].any()
