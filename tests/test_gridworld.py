"""Grid worlds: layouts, dynamics, value iteration, views, env checkers."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from dospcot.envs import (
    GridLayout,
    GridWorld,
    TabularMDP,
    ViewObservationWrapper,
    grid_views,
    make_masked_gridworld,
)

MAP_4X4 = """
...G
.#L.
....
S...
"""


def test_layout_text_round_trip_and_bad_maps():
    layout = GridLayout.from_text(MAP_4X4)
    assert layout.size == 4 and layout.start == (3, 0) and layout.goal == (0, 3)
    assert layout.to_text() == MAP_4X4.strip()
    with pytest.raises(ValueError, match=r"unknown map character\(s\) \['x'\]"):
        GridLayout.from_text("S.x\n..G\n...")
    with pytest.raises(ValueError, match="exactly one start"):
        GridLayout.from_text("...\n..G\n...")
    with pytest.raises(ValueError, match="exactly one goal"):
        GridLayout.from_text("S..\n...\n...")


def test_dynamics_by_hand():
    env = GridWorld(MAP_4X4)
    env.reset(seed=0)
    assert env.step(3)[:3] == (12, -1.0, False)  # left edge: stays put
    assert env.step(0)[:3] == (8, -1.0, False)
    assert env.step(0)[:3] == (4, -1.0, False)
    assert env.step(1)[:3] == (4, -1.0, False)  # the wall at (1, 1) blocks
    env.s = 10  # (2, 2): up is lava
    assert env.step(0)[:3] == (12, -100.0, False)  # lava: penalty, back to the start
    env.s = 7  # (1, 3): up is the goal
    assert env.step(0)[:3] == (3, 0.0, True)


def test_value_iteration_matches_the_hand_solved_4x4_map():
    env = GridWorld(MAP_4X4)
    mdp = TabularMDP.from_env(env, grid_views(env.layout), max_episode_steps=16)
    q = mdp.value_iteration(discount=1.0)
    # From the start (3, 0) the goal (0, 3) is 6 moves away: five steps of -1, then the goal's 0.
    assert q[12].max() == pytest.approx(-5.0)
    optimal = mdp.optimal_actions(discount=1.0)
    assert optimal[12].tolist() == [True, True, False, False]  # up or right, both shortest
    assert optimal[7].tolist() == [True, False, False, False]  # (1, 3): straight up into the goal
    # (2, 2): right or... up is lava; the shortest paths go right then up, or up is penalised.
    assert not optimal[10, 0]
    assert q[10].max() == pytest.approx(-2.0)


@pytest.mark.parametrize("size", [8, 16, 32, 64])
def test_random_layouts_are_solvable_and_seeded(size):
    for seed in range(5):
        layout = GridLayout.random(size, seed, lava_density=0.15, wall_density=0.15)
        assert layout.solvable()
        assert np.array_equal(layout.terrain, GridLayout.random(size, seed, 0.15, 0.15).terrain)
    assert not np.array_equal(GridLayout.random(size, 0).terrain, GridLayout.random(size, 1).terrain)
    env = GridWorld(size=size, layout_seed=3)
    mdp = TabularMDP.from_env(env, {}, max_episode_steps=4 * size)
    assert np.isfinite(mdp.value_iteration(discount=1.0)[env.start_state].max())


def test_env_checkers_pass():
    gym_check_env(GridWorld(size=8), skip_render_check=True)
    sb3_check_env(GridWorld(size=8))
    env = GridWorld(size=8)
    sb3_check_env(ViewObservationWrapper(env, grid_views(env.layout)["rays"]))
    assert gym.make("dospcot/GridWorld-v0", size=8).spec.max_episode_steps == 64


def test_views_by_hand():
    layout = GridLayout.from_text(MAP_4X4)
    views = grid_views(layout, patch_size=3)
    assert views["coords"].fn(12).tolist() == pytest.approx([1.0, 0.0, -1.0, 1.0])
    patch = views["patch"].fn(12).reshape(3, 3, 5).argmax(-1)
    free, off = 0, 4
    assert patch.tolist() == [[off, free, free], [off, free, free], [off, off, off]]
    rays = views["rays"].fn(12).reshape(8, 3)  # (lava, wall-or-edge, goal) per direction
    assert rays[0].tolist() == pytest.approx([1.0, 1.0, 1.0])  # up: no lava, edge after 4 cells -> 4/4
    assert rays[1].tolist() == pytest.approx([0.5, 1.0, 0.75])  # up-right: lava at 2, goal at 3, edge at 4
    assert rays[4][1] == pytest.approx(0.25)  # down: the edge right below
    # Inverse distances: 1 / d, and 0 where the ray finds nothing.
    inverse = grid_views(layout, patch_size=3, ray_encoding="inverse")["rays"].fn(12).reshape(8, 3)
    assert inverse[0].tolist() == pytest.approx([0.0, 0.25, 0.0])  # up: the edge after 4 cells
    assert inverse[1].tolist() == pytest.approx([0.5, 0.25, 1 / 3])  # up-right: lava 2, goal 3, edge 4
    assert inverse[4][1] == pytest.approx(1.0)  # down: the edge right below
    with pytest.raises(ValueError, match="ray_encoding must be one of"):
        grid_views(layout, ray_encoding="log")
    # The compass "axes": the goal's offset (d_row, d_column), each one-hot over its 2N - 1 = 7 values.
    compass = grid_views(layout, patch_size=3, compass="axes")
    heading = np.zeros(14)
    heading[[-3 + 3, 7 + 3 + 3]] = 1.0  # from (3, 0) the goal (0, 3) is 3 rows up, 3 columns right
    for name in ("coords", "patch", "rays"):
        assert compass[name].fn(12).tolist() == pytest.approx([*views[name].fn(12), *heading])
    assert compass["patch"].space.shape == (45 + 14,) and compass["rays"].space.shape == (24 + 14,)
    # The compass "cell": one input per cell of the 4 x 4 map, cell 12 = (3, 0) here.
    cell = grid_views(layout, patch_size=3, compass="cell")
    assert cell["rays"].fn(12).tolist() == pytest.approx([*views["rays"].fn(12), *np.eye(16)[12]])
    assert cell["patch"].space.shape == (45 + 16,) and cell["coords"].space.shape == (4 + 16,)
    assert cell["coords"].space.low.min() == -1.0 and cell["patch"].space.low.min() == 0.0
    with pytest.raises(ValueError, match="compass must be one of"):
        grid_views(layout, compass="north")


def test_masked_gridworld_has_views_and_hides_rewards():
    env = make_masked_gridworld(0.5, views=("coords", "patch", "rays"), size=8, layout_seed=0)
    _, info = env.reset(seed=0)
    assert set(info["views"]) == {"coords", "patch", "rays"}
    observed = []
    for t in range(40):
        _, reward, terminated, truncated, info = env.step(t % 4)
        observed.append(info["reward_observed"])
        if not info["reward_observed"]:
            assert reward == 0.0
        if terminated or truncated:
            env.reset()
    assert any(observed) and not all(observed)


def test_tabular_cotraining_learns_a_masked_grid_with_two_and_three_views():
    from dospcot.core.tabular_runs import TabularConfig, TabularCoTraining, TabularRunSpec

    env = GridWorld(size=8, layout_seed=0)
    mdp = TabularMDP.from_env(env, grid_views(env.layout, patch_size=3), max_episode_steps=64)
    specs = []
    for seed in range(3):
        specs += [
            TabularRunSpec("dospcot", ("esarsa", "esarsa"), ("coords", "patch"), seed=seed),
            TabularRunSpec("dospcot", ("esarsa",) * 3, ("coords", "patch", "rays"), seed=seed),
            TabularRunSpec("masked-zero", ("esarsa",), ("coords",), seed=seed),
            TabularRunSpec("labels-only", ("esarsa",), ("coords",), seed=seed),
        ]
    config = TabularConfig(rounds=4, episodes_per_round=150, label_fraction=0.1)
    last = [r for r in TabularCoTraining(mdp, specs, config).run().records if r["round"] == 4]

    def mean(metric, method, m):
        return np.mean([r[metric] for r in last if r["method"] == method and r["m"] == m])

    for m in (2, 3):
        # The normalised score is no use here: a random walk meets so much lava that merely
        # avoiding it scores near 1. Agreement with the optimal actions and returns tell.
        assert mean("agreement", "dospcot", m) > mean("agreement", "masked-zero", 1) + 0.2
        assert mean("agreement", "dospcot", m) > mean("agreement", "labels-only", 1) + 0.2
        assert mean("success", "dospcot", m) > mean("success", "masked-zero", 1)
        assert mean("greedy_return", "dospcot", m) > mean("greedy_return", "labels-only", 1)
