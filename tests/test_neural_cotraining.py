"""Neural co-training on a small masked grid world: rounds, views, counters, leakage (also under
sensor blind spots and a reward monitor)."""

import json
import pickle
from functools import partial

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from small_runs import PINNED, grid_config, grid_run

from dospcot.config.errors import ConfigError
from dospcot.core.round_records import round_stats
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.core.self_paced import RunRound
from dospcot.envs import (
    FiniteCheckWrapper,
    GridWorld,
    NonFiniteError,
    StateActionMask,
    grid_views,
    monitored_states,
    view_blind_spots,
)
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

LAYOUT = GridWorld(size=6, layout_seed=0).layout

VIEWS = grid_views(LAYOUT, patch_size=3)
LABEL_FRACTION = 0.2
SECTIONS = {
    "training": {"rounds": 2, "steps_per_round": 300, "label_fraction": LABEL_FRACTION},
    "env": {"max_episode_steps": 36},
    "dqn": {"learning_starts": 50, "buffer_size": 5_000, "net_arch": [32]},
}


def config(method="dospcot", agents=("esarsa_dqn",), views=("coords",), seed=0, **changes):
    """The tests' small grid run; ``changes`` update keys of a section (``training={"rounds": 1}``)."""
    sections = {
        name: {**SECTIONS.get(name, {}), **values} for name, values in {**SECTIONS, **changes}.items()
    }
    return grid_config(method, agents, views, seed, **sections)


GRID = partial(GridWorld, LAYOUT)


def grid(cfg, make_env=GRID, views=VIEWS, monitored=None) -> CoTrainingRun:
    return grid_run(cfg, make_env, views, monitored)


@pytest.mark.parametrize("views", [("coords",), ("coords", "patch"), ("coords", "patch", "rays")])
def test_cotraining_runs_two_rounds_with_one_two_and_three_views(views):
    run = grid(config("dospcot", ("esarsa_dqn",) * len(views), views, seed=1))
    records = run.run()
    assert len(records) == 2 * len(views)
    last = [r for r in records if r["round"] == 2]
    # One learn() per agent per round: the step counters and the pace-driven eps carry on.
    assert all(r["env_steps"] == 600 for r in last)
    assert all(r["eps"] == pytest.approx(1.0 + (0.05 - 1.0) * r["pace"]) for r in last)
    assert 0 < last[0]["coverage"] <= 1 and 0 <= last[0]["pseudo_accuracy"] <= 1
    # The table is indexed by (s, a) key: every seen key has its entry.
    assert len(run.table) == run.task.mdp.n_states * run.task.mdp.n_actions == run.store.visited.size


def test_baselines_follow_a_linear_schedule():
    run = grid(config("labels-only", ("dqn",)))
    records = run.run()
    assert [r["eps"] for r in records] == pytest.approx([1.0 + (0.05 - 1.0) * 0.5, 0.05])
    # A baseline records its effort as co-training does: the (s, a) keys whose labels it saw.
    assert records[-1]["labelled_steps"] == (run.store.visited & run.store.labelled).sum() > 0


def test_with_every_reward_revealed_the_pace_is_full_and_exploration_decays():
    # No unlabelled key is left to admit: the self-paced schedule is done, not stuck at its start.
    run = grid(config(training={"label_fraction": 1.0}))
    records = run.run()
    assert [r["pace"] for r in records] == [1.0, 1.0] and [r["coverage"] for r in records] == [0.0, 0.0]
    assert [r["eps"] for r in records] == pytest.approx([0.05, 0.05])


def test_exploration_by_rounds_ignores_the_pace():
    # Every reward revealed: the pace is full after round 1, yet eps follows the rounds as a baseline's.
    records = grid(config(training={"label_fraction": 1.0, "exploration": "rounds"})).run()
    assert [r["pace"] for r in records] == [1.0, 1.0]
    assert [r["eps"] for r in records] == pytest.approx([1.0 + (0.05 - 1.0) * 0.5, 0.05])
    with pytest.raises(ValueError, match="exploration must be 'pace' or 'rounds', got 'steps'"):
        config(training={"exploration": "steps"})


def _permuted_grid(seed: int, monitored_states: np.ndarray | None = None) -> GridWorld:
    env = GridWorld(LAYOUT)
    masked = ~StateActionMask(env.observation_space.n, 4, LABEL_FRACTION, seed, monitored_states).labelled
    env.reward[masked] = np.random.default_rng(0).permutation(env.reward[masked])
    return env


def assert_same_learners(a: CoTrainingRun, b: CoTrainingRun) -> None:
    """Two runs' agents hold bit-identical parameters, and their reward tables the same rewards and
    weights: what the leakage tests ask of runs whose hidden rewards differ."""
    for agent_a, agent_b in zip(a.agents, b.agents, strict=True):
        for p, q in zip(agent_a.policy.parameters(), agent_b.policy.parameters(), strict=True):
            assert th.equal(p, q)
    assert np.array_equal(a.table.reward, b.table.reward) and np.array_equal(a.table.weight, b.table.weight)


@pytest.mark.parametrize("kinds", [("esarsa_dqn", "dqn"), ("tabular", "tabular")])
def test_leakage_permuting_hidden_rewards_leaves_agents_bit_identical(kinds):
    assert not np.array_equal(_permuted_grid(3).reward, GridWorld(LAYOUT).reward)
    cfg = config("dospcot", kinds, ("coords", "patch"), seed=3)
    # SB3 seeds the global generators when an agent is built: build and run one run at a time.
    a = grid(cfg)
    a.run()
    b = grid(cfg, partial(_permuted_grid, 3))
    b.run()
    assert_same_learners(a, b)


def test_leakage_under_blind_spots_and_a_monitor_agents_stay_bit_identical():
    monitor = monitored_states(6, 2)
    assert not np.array_equal(_permuted_grid(3, monitor).reward, GridWorld(LAYOUT).reward)
    views = grid_views(LAYOUT, 3, blind_spots=view_blind_spots(LAYOUT, 0.5, 3))
    cfg = config("dospcot", ("dqn", "dqn"), ("patch", "rays"), seed=3)
    # SB3 seeds the global generators when an agent is built: build and run one run at a time.
    a = grid(cfg, views=views, monitored=monitor)
    a.run()
    b = grid(cfg, partial(_permuted_grid, 3, monitor), views, monitor)
    b.run()
    assert a.store.labelled[a.store.visited].mean() > 0.2  # the monitor revealed more than the share
    assert_same_learners(a, b)


def test_episode_end_classes_keep_the_goal_off_keys_that_go_on():
    """Only the keys into the goal end an episode, and the goal's class is labelled only there: with
    ``env.episode_end_classes`` every other key may not take it, in the pool's mask and in the round's
    pseudo-rewards; without it the mask is the run's classes alone."""
    run = build_run(load_config("tiny", [*PINNED, "seed=5", "env.episode_end_classes=true"]))
    run.run()
    store, pool = run.store, run.task.pool()
    ends = store.visited & store.terminated
    assert (store.labelled & ends).any()  # seed 5 labels the key into the goal
    assert (run.task.mdp.reward.ravel()[ends] == 0.0).all()
    goal = int(run.task.classes.encode(np.array([0.0]))[0])
    assert pool.class_mask.shape == (store.visited.size, run.task.n_classes)
    np.testing.assert_array_equal(pool.class_mask[:, goal], store.terminated)
    result = run.trainer.step(pool)
    goes_on = ~store.terminated & pool.unlabelled
    assert goes_on.any() and (result.pseudo_class[goes_on] != goal).all()
    plain = build_run(load_config("tiny", [*PINNED, "seed=5"]))
    plain.run()
    assert plain.task.pool().class_mask.shape == (plain.task.n_classes,)


def test_a_mix_of_tabular_and_neural_agents_cotrains_and_resumes_from_its_state():
    build = partial(
        grid, config("dospcot", ("tabular", "esarsa_dqn", "dqn"), ("coords", "patch", "rays"), seed=2)
    )
    full = build()
    records = full.run()
    assert [r["env_steps"] for r in records] == [300] * 3 + [600] * 3
    assert all(r["eps"] == pytest.approx(1.0 + (0.05 - 1.0) * r["pace"]) for r in records)
    assert full.agents[0].q_table.shape == (4, 36)  # one row per cell: coords tell every cell apart
    first = build()
    first.run_round()
    state = pickle.dumps(first.state_dict())
    resumed = build()
    resumed.load_state_dict(pickle.loads(state))
    assert json.dumps(resumed.run_round()) == json.dumps(records[3:])
    for agent_full, agent_resumed in zip(full.agents, resumed.agents, strict=True):
        assert type(agent_resumed) is type(agent_full)
        for p, q in zip(agent_full.policy.parameters(), agent_resumed.policy.parameters(), strict=True):
            assert th.equal(p, q)


def test_bad_configs_raise():
    with pytest.raises(ConfigError, match="agents: unknown agent kind 'ppo'"):
        config("dospcot", ("ppo",))
    with pytest.raises(ConfigError, match="views: the grid world has no view 'lidar'"):
        config("dospcot", ("dqn",), ("lidar",))
    with pytest.raises(ValueError, match=r"unknown view\(s\) \['rays'\]"):  # a task of the test's own
        grid(config("dospcot", ("dqn",), ("rays",)), views={"coords": VIEWS["coords"]})
    with pytest.raises(ValueError, match="label_fraction"):
        config(training={"label_fraction": 0.0})


def test_training_episodes_follow_their_own_limit_while_evaluation_keeps_the_horizon():
    cfg = config("oracle", training={"rounds": 1}, env={"train_episode_steps": 5})
    run = grid(cfg, partial(GridWorld, LAYOUT, exploring_starts=True))
    run.run()
    # 300 steps in episodes of at most 5 steps: at least 60 episodes (fewer steps end at the goal).
    assert run.agents[0]._episode_num >= 60
    assert run.task.mdp.max_episode_steps == SECTIONS["env"]["max_episode_steps"]


class _NaNRewardAt(GridWorld):
    """A grid world whose 57th step returns a NaN reward."""

    def __init__(self, layout, at: int = 57) -> None:
        super().__init__(layout)
        self.at, self.count = at, 0

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        self.count += 1
        return obs, float("nan") if self.count == self.at else reward, terminated, truncated, info


def test_a_nan_reward_stops_the_run_naming_the_env_and_the_step():
    run = grid(config("dospcot", ("esarsa_dqn", "dqn"), ("coords", "patch")), partial(_NaNRewardAt, LAYOUT))
    # The mask decides whether the agent sees the NaN as its reward or only as the hidden reward.
    with pytest.raises(
        NonFiniteError,
        match=r"^env _NaNRewardAt \(agent 0, view coords\) returned a "
        r"non-finite (hidden )?reward \(nan\) at env step 57 \(step \d+ of its episode",
    ):
        run.run()


def test_finite_check_names_a_nan_observation_at_reset_and_at_a_step():
    class Broken(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, (3,))
        action_space = gym.spaces.Discrete(2)

        def reset(self, *, seed=None, options=None):
            return np.array([0.0, np.inf, 0.0], dtype=np.float32), {}

    with pytest.raises(
        NonFiniteError, match=r"env Broken returned a non-finite observation \(inf\) at reset"
    ):
        FiniteCheckWrapper(Broken()).reset()
    env = FiniteCheckWrapper(gym.make("CartPole-v1", disable_env_checker=True), name="cartpole")
    env.reset(seed=0)
    env.unwrapped.state = np.array([np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(
        NonFiniteError, match=r"env cartpole returned a non-finite observation \(nan\) at env step 1"
    ):
        env.step(0)


def _buffered_keys(run: CoTrainingRun) -> np.ndarray:
    """The (s, a) key of each step in agent 0's replay buffer (its view is ``coords``, one row per
    state)."""
    buffer = run.agents[0].replay_buffer
    obs, actions = buffer.observations[: buffer.size(), 0], buffer.actions[: buffer.size(), 0, 0]
    states = (obs[:, None, :] == run.task.mdp.views["coords"][None]).all(-1).argmax(1)
    return states * run.task.mdp.n_actions + actions


def _last_round_q(kind: str, update_steps: int, shift: float) -> tuple[float, int]:
    """Q(s, a) after one round of a run whose co-trainer's pseudo-reward for one admitted key
    is shifted by ``shift``; returns it and the key. The key is the admitted one the agent's replay
    buffer holds most often (the first such), so that the effect tested does not hinge on whether
    the seed's first admitted key happened to be visited once or often."""
    # A fast learner, so that the shifted key's few replayed samples move its value visibly.
    cfg = config(
        "dospcot", (kind,), training={"rounds": 1, "update_steps": update_steps}, dqn={"learning_rate": 0.01}
    )
    run = grid(cfg)
    table_set, picked = run.table.set, []

    def shifted_set(ids, reward, weight):
        keys = np.asarray(ids)
        admitted = keys[(np.asarray(weight) > 0) & ~run.store.labelled[keys]]
        buffered = np.bincount(_buffered_keys(run), minlength=run.store.labelled.size)
        picked.append(int(admitted[np.argmax(buffered[admitted])]))
        table_set(ids, np.where(keys == picked[0], np.asarray(reward) + shift, reward), weight)

    run.table.set = shifted_set
    run.run_round()
    state, action = divmod(picked[0], run.task.mdp.n_actions)
    with th.no_grad():
        q = run.agents[0].q_net(th.as_tensor(run.task.mdp.views["coords"][[state]]))
    return float(q[0, action]), picked[0]


@pytest.mark.parametrize("kind", ["tabular", "esarsa_dqn"])
def test_the_policy_update_learns_the_last_rounds_pseudo_rewards(kind):
    # Without the update phase the round's pseudo-rewards reach no agent before it is evaluated.
    assert _last_round_q(kind, 0, -50.0) == _last_round_q(kind, 0, 0.0)
    (moved, key), (plain, same_key) = _last_round_q(kind, 300, -50.0), _last_round_q(kind, 300, 0.0)
    assert key == same_key and moved < plain - 1.0


def test_round_stats_name_the_worst_class_the_mean_accuracy_hides():
    # Six admitted samples (the seventh is not admitted): hidden classes 0, 0, 0, 1, -1 (a value no
    # label showed, e.g. the goal) and 0; given classes 0, 0, 1, 1, 0 and 0.
    true_class = np.array([0, 0, 0, 1, -1, 0, 1])
    given = np.array([0, 0, 1, 1, 0, 0, -1])
    weight = (given >= 0).astype(float)
    result = RunRound(
        pseudo_class=given,
        pseudo_weight=weight,
        view_weight=weight[None],
        view_class=given[None],
        threshold=np.zeros((1, 2)),
        classifier_loss=np.zeros(1),
        pace=6 / 7,
        changed=0.0,
        stopped=False,
    )
    unlabelled = np.ones(7, dtype=bool)
    stats = round_stats(result, unlabelled, true_class)
    assert stats["pseudo_accuracy"] == pytest.approx(4 / 6)
    # Recall: class 0 gets 3 of its 4 right, class 1 its 1 of 1, the unseen value none of its 1.
    assert stats["worst_class_recall"] == 0.0
    # Precision: of the 4 given class 0, 3 are; of the 2 given class 1, 1 is.
    assert stats["worst_class_precision"] == pytest.approx(1 / 2)
    assert stats["coverage"] == pytest.approx(6 / 7)


def test_agents_take_their_first_gradient_step_in_learn_from_round():
    run = grid(
        config("dospcot", ("esarsa_dqn", "tabular"), ("coords", "patch"), training={"learn_from_round": 2})
    )
    assert [agent.learning_starts for agent in run.agents] == [300, 300]
    run.run_round()
    # Round 1 collects at random: every buffered step is a uniform draw, none trained the agents.
    assert [agent._n_updates for agent in run.agents] == [0, 0]
    assert all(agent.replay_buffer.size() == 300 for agent in run.agents)
    run.run_round()
    assert all(agent._n_updates > 0 for agent in run.agents)


def test_the_hidden_rewards_control_changes_only_the_rewards_of_the_admitted_samples():
    """``cotraining.pseudo_rewards = "hidden"``: round 1 admits the same samples with the same weights
    and fits the same classifiers as the method, but every admitted sample reads its true reward; the
    record's pseudo-reward accuracy is then 1, while each view's figures still score its classifier."""
    views = ("coords", "patch")
    runs, first = {}, {}
    for mode in ("classifiers", "hidden"):  # one run at a time: SB3 seeds the global generators
        runs[mode] = grid(
            config(agents=("dqn", "dqn"), views=views, seed=6, cotraining={"pseudo_rewards": mode})
        )
        first[mode] = runs[mode].run_round()
    method, control = runs["classifiers"], runs["hidden"]
    admitted = control.table.weight > 0
    assert admitted.sum() > 5 and np.array_equal(control.table.weight, method.table.weight)
    true = control.store.hidden_reward.astype(np.float32)
    assert np.array_equal(control.table.reward[admitted], true[admitted])
    assert not np.array_equal(method.table.reward[admitted], true[admitted])  # the classifiers erred
    assert np.array_equal(control.table.reward[~admitted], method.table.reward[~admitted])
    assert [r["pseudo_accuracy"] for r in first["hidden"]] == [1.0, 1.0]
    assert [r["worst_class_recall"] for r in first["hidden"]] == [1.0, 1.0]
    assert first["classifiers"][0]["pseudo_accuracy"] < 1.0
    for a, b in zip(first["classifiers"], first["hidden"], strict=True):
        for key in (
            "pace",
            "coverage",
            "eps",
            "view_coverage",
            "view_pseudo_accuracy",
            "lambda",
            "classifier_loss",
        ):
            assert a[key] == b[key], key
    # Round 2 admits from the control's own experience, and still gives every admitted sample its truth.
    second = control.run_round()
    admitted = control.table.weight > 0
    assert [r["pseudo_accuracy"] for r in second] == [1.0, 1.0]
    assert np.array_equal(
        control.table.reward[admitted], control.store.hidden_reward.astype(np.float32)[admitted]
    )


def test_the_hidden_rewards_control_is_read_by_reward_learners_only():
    assert load_config("tiny", ["cotraining.pseudo_rewards=hidden"]).cotraining.pseudo_rewards == "hidden"
    with pytest.raises(ConfigError, match='method = "oracle" never reads it'):
        load_config("grid16-oracle", ["cotraining.pseudo_rewards=hidden"])
    with pytest.raises(ConfigError, match="allowed: classifiers, hidden"):
        load_config("tiny", ["cotraining.pseudo_rewards=true"])
    with pytest.raises(ConfigError, match="the paper protocol's batched co-trainer gives the classifiers'"):
        load_config("paper-text", ["tabular.cotraining.pseudo_rewards=hidden"])
