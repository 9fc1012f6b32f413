"""Sensors with errors (blind spots) and reward monitors: the settings of docs/preregistration.md.
Their leakage test sits with the other grid one, in test_neural_cotraining.py."""

import gymnasium as gym
import numpy as np
import pytest

from dospcot.envs import (
    GridLayout,
    GridWorld,
    RewardMaskWrapper,
    StateActionMask,
    grid_views,
    lava_blind_spots,
    make_masked_gridworld,
    monitored_states,
    view_blind_spots,
)
from dospcot.envs.gridworld import FREE, LAVA, N_TERRAIN, misread
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config
from dospcot.tasks.grid import grid_world

# Lava at (0, 2), (1, 1), (2, 0) and (3, 3); start (3, 0), goal (1, 3).
MAP = """
..L.
.L.G
L...
S..L
"""
LAYOUT = GridLayout.from_text(MAP)
BIG = GridWorld(size=16, layout_seed=0).layout


def test_a_blind_spot_holds_its_share_of_lava_cells_and_is_fixed_by_its_seed():
    n_lava = int((BIG.terrain == LAVA).sum())
    blind = lava_blind_spots(BIG, 0.5, [3, 1])
    assert blind.sum() == round(0.5 * n_lava) and np.all(BIG.terrain[blind] == LAVA)
    assert np.array_equal(blind, lava_blind_spots(BIG, 0.5, [3, 1]))  # fixed per cell for a seed
    assert not lava_blind_spots(BIG, 0.0, 3).any() and lava_blind_spots(BIG, 1.0, 3).sum() == n_lava


@pytest.mark.parametrize("seed", range(5))
def test_two_views_miss_different_cells_unless_their_errors_are_identical(seed):
    independent = view_blind_spots(BIG, 0.5, seed)
    assert set(independent) == {"patch", "rays"}
    assert not np.array_equal(independent["patch"], independent["rays"])
    identical = view_blind_spots(BIG, 0.5, seed, identical=True)
    assert np.array_equal(identical["patch"], identical["rays"])
    assert np.array_equal(identical["patch"], independent["patch"])  # the control shares the patch's draw
    assert not np.array_equal(view_blind_spots(BIG, 0.5, seed + 1)["patch"], independent["patch"])


def test_a_view_with_a_blind_spot_reads_that_lava_as_free_and_nothing_else_changes():
    blind = np.zeros((4, 4), dtype=bool)
    blind[1, 1] = True
    plain = grid_views(LAYOUT, patch_size=3)
    seen = grid_views(LAYOUT, patch_size=3, blind_spots={"patch": blind, "rays": blind})
    below = 2 * 4 + 1  # the cell (2, 1), just below the blind lava cell
    # The 3 x 3 patch around (2, 1): its top-middle cell (window index 1) is (1, 1).
    assert np.argmax(plain["patch"].fn(below).reshape(9, N_TERRAIN)[1]) == LAVA
    assert np.argmax(seen["patch"].fn(below).reshape(9, N_TERRAIN)[1]) == FREE
    # The ray going up from (2, 1) meets lava at distance 1 (1 / N); through the blind spot it meets none.
    lava_up = 0 * 3 + 0  # direction 0 (up), channel 0 (lava)
    assert plain["rays"].fn(below)[lava_up] == pytest.approx(1 / 4)
    assert seen["rays"].fn(below)[lava_up] == 1.0
    # Elsewhere the views agree: the cells whose patch does not hold (1, 1) and every coords row.
    far = 3 * 4 + 3
    assert np.array_equal(plain["patch"].fn(far), seen["patch"].fn(far))
    assert all(np.array_equal(plain["coords"].fn(s), seen["coords"].fn(s)) for s in range(16))
    # What the world does is unchanged: the step up from (2, 1) is still a lava step.
    env = GridWorld(LAYOUT)
    assert env.reward[below, 0] == -100.0 and env.next_state[below, 0] == env.start_state


def test_a_blind_spot_must_hold_lava_cells_of_the_map_only():
    not_lava = np.zeros((4, 4), dtype=bool)
    not_lava[0, 0] = True
    with pytest.raises(ValueError, match="a blind spot may hold lava cells only"):
        misread(LAYOUT, not_lava)
    with pytest.raises(ValueError, match="only \\['patch', 'rays'\\] read the terrain"):
        grid_views(LAYOUT, 3, blind_spots={"coords": np.zeros((4, 4), dtype=bool)})
    with pytest.raises(ValueError, match="a blind-spot rate must lie in \\[0, 1\\]"):
        lava_blind_spots(LAYOUT, 1.5, 0)


def test_a_monitor_reveals_every_key_of_its_columns_and_the_label_share_of_the_rest():
    monitored = monitored_states(4, 2)
    assert monitored.tolist() == [True, True, False, False] * 4
    mask = StateActionMask(16, 4, 0.25, seed=5, monitored_states=monitored).labelled
    assert mask[monitored].all()
    assert mask[~monitored].sum() == round(0.25 * 8 * 4)  # 8 unmonitored states x 4 actions
    # Without a monitor the draw is the one every earlier run made: the first 16 of a permutation.
    plain = StateActionMask(16, 4, 0.25, seed=5).labelled.reshape(-1)
    assert np.flatnonzero(plain).tolist() == sorted(np.random.default_rng(5).permutation(64)[:16].tolist())


def test_a_monitored_grid_reveals_every_step_from_its_columns():
    env = make_masked_gridworld(
        label_fraction=0.01, views=("coords",), layout=MAP, monitored_columns=1, exploring_starts=True
    )
    mask = StateActionMask(16, 4, 0.01, seed=0, monitored_states=monitored_states(4, 1)).labelled
    assert mask[~monitored_states(4, 1)].sum() == 1  # round(0.01 * 48) keys, at least one
    rng = np.random.default_rng(0)
    from_column_0 = 0
    for seed in range(10):
        env.reset(seed=seed)
        for _ in range(6):
            state, action = env.unwrapped.s, int(rng.integers(4))
            observed = env.step(action)[4]["reward_observed"]
            assert observed == mask[state, action]
            from_column_0 += state % 4 == 0
            assert observed or state % 4 != 0
    assert from_column_0 > 5


class _Counter(gym.Env):
    observation_space = gym.spaces.Discrete(100)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return 0, {}

    def step(self, action):
        self.t += 1
        return self.t, 1.0, False, self.t >= 8, {}


def test_a_transition_monitor_reveals_the_first_steps_of_every_episode():
    env = RewardMaskWrapper(_Counter(), 0.01, mode="transition", mask_seed=0, reveal_first_steps=3)
    plain = RewardMaskWrapper(_Counter(), 0.01, mode="transition", mask_seed=0)
    for episode in range(3):
        env.reset(seed=episode)
        plain.reset(seed=episode)
        seen = [env.step(0)[4]["reward_observed"] for _ in range(8)]
        draws = [plain.step(0)[4]["reward_observed"] for _ in range(8)]
        assert seen[:3] == [True] * 3
        assert seen[3:] == draws[:5]  # the monitored steps draw nothing: later ones draw as before
    with pytest.raises(ValueError, match="reveal_first_steps needs mode='transition'"):
        RewardMaskWrapper(GridWorld(LAYOUT), 0.5, reveal_first_steps=2)
    with pytest.raises(ValueError, match="monitored_states needs mode='state-action'"):
        RewardMaskWrapper(_Counter(), 0.5, mode="transition", monitored_states=np.ones(100, dtype=bool))


def test_the_config_keys_reach_the_views_and_the_mask():
    cfg = load_config("tiny", ["env.blind_spot_rate=0.5", "env.monitored_columns=2"])
    _, views, layout = grid_world(cfg)
    blind = view_blind_spots(layout, 0.5, cfg.seed)
    expected = grid_views(layout, 3, cfg.env.compass, blind, ray_encoding=cfg.env.ray_encoding)
    assert all(np.array_equal(views[v].fn(s), expected[v].fn(s)) for v in views for s in range(36))
    run = build_run(cfg)
    assert np.array_equal(run.task.monitored_states, monitored_states(6, 2))
    identical = load_config("tiny", ["env.blind_spot_rate=0.5", 'env.blind_spots="identical"'])
    _, views, _ = grid_world(identical)
    blind = view_blind_spots(layout, 0.5, cfg.seed, identical=True)
    expected = grid_views(layout, 3, cfg.env.compass, blind, ray_encoding=identical.env.ray_encoding)
    assert all(np.array_equal(views["rays"].fn(s), expected["rays"].fn(s)) for s in range(36))
