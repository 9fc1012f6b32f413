"""The stacked learner: S members' gradient steps at once, each what ExpectedSarsaDQN.train makes."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch as th

from dospcot.policies.esarsa_dqn import ExpectedSarsaDQN, WeightedReplayBufferSamples
from dospcot.policies.stacked_esarsa import StackedExpectedSarsa, stack_samples
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

UPDATES = 100


def _trained_agent(n_steps: int, seed: int = 0) -> ExpectedSarsaDQN:
    """A tiny grid run's first agent after one round: a filled relabelling buffer, an Adam with state."""
    run = build_run(load_config("tiny", [f"dqn.n_steps={n_steps}", "training.rounds=1", f"seed={seed}"]))
    run.run()
    return run.agents[0]


@pytest.fixture(scope="module")
def trained_agent():
    """``trained_agent(n_steps, seed=0)``: a deep copy of :func:`_trained_agent`'s agent, which is trained
    once per module for each (n_steps, seed); the test may train and change its copy."""
    agents: dict[tuple[int, int], ExpectedSarsaDQN] = {}

    def get(n_steps: int, seed: int = 0) -> ExpectedSarsaDQN:
        if (n_steps, seed) not in agents:
            agents[n_steps, seed] = _trained_agent(n_steps, seed)
        return copy.deepcopy(agents[n_steps, seed])

    return get


def _batches(agent: ExpectedSarsaDQN, count: int, seed: int) -> list[WeightedReplayBufferSamples]:
    np.random.seed(seed)  # noqa: NPY002  (the buffer samples from numpy's global stream, as SB3's)
    return [agent.replay_buffer.sample(agent.batch_size) for _ in range(count)]


def _member_parameters(learner: StackedExpectedSarsa, member: int) -> dict[str, th.Tensor]:
    return learner.q_net.member_state_dict(member)


@pytest.mark.parametrize("n_steps", [1, 3])
@pytest.mark.parametrize(
    ("target", "greedy"), [("expected_sarsa", "target"), ("expected_sarsa", "online"), ("q", "target")]
)
def test_one_member_makes_the_first_100_updates_of_expected_sarsa_dqn_train(
    trained_agent, n_steps, target, greedy
):
    agent = trained_agent(n_steps)
    agent.target, agent.greedy = target, greedy
    batches = _batches(agent, UPDATES, seed=1)
    assert n_steps == 1 or any(float((b.discounts < agent.gamma * 0.999).any()) for b in batches)
    learner = StackedExpectedSarsa.from_agents([agent])
    queue = iter(batches)
    agent.replay_buffer.sample = lambda *args, **kwargs: next(queue)
    eps = th.tensor([agent.exploration_rate])
    updated = 0
    for data in batches:
        before = [p.detach().clone() for p in agent.q_net.parameters()]
        agent.train(1, agent.batch_size)
        _, active = learner.train_step(stack_samples([data]), eps, agent.gamma)
        moved = any(not th.equal(a, p) for a, p in zip(before, agent.q_net.parameters(), strict=True))
        assert bool(active[0]) == moved  # a batch with nothing labelled is skipped by both
        updated += moved
        for name, value in _member_parameters(learner, 0).items():
            np.testing.assert_allclose(value, agent.q_net.state_dict()[name], atol=1e-5, rtol=0)
    assert updated > UPDATES // 2


def test_one_member_makes_expected_sarsa_dqns_updates_with_the_large_margin_loss(trained_agent):
    agent = trained_agent(3)
    rng = np.random.default_rng(0)
    states = rng.random((40, *agent.observation_space.shape)).astype(np.float32)
    actions = rng.integers(agent.action_space.n, size=40)
    agent.set_demonstrations(states, actions)
    batches = _batches(agent, UPDATES, seed=1)
    learner = StackedExpectedSarsa.from_agents([agent])
    queue = iter(batches)
    agent.replay_buffer.sample = lambda *args, **kwargs: next(queue)
    eps = th.tensor([agent.exploration_rate])
    for step, data in enumerate(batches):
        np.random.seed(step)  # noqa: NPY002  (the margin loss's minibatch comes from numpy's global stream)
        agent.train(1, agent.batch_size)
        np.random.seed(step)  # noqa: NPY002
        index = np.random.randint(0, len(actions), size=agent.batch_size)  # noqa: NPY002
        demos = (th.as_tensor(states[index])[None], th.as_tensor(actions[index])[None])
        _, active = learner.train_step(stack_samples([data]), eps, agent.gamma, demos)
        assert bool(active[0])  # a demonstration always gives a gradient
    for name, value in _member_parameters(learner, 0).items():
        np.testing.assert_allclose(value, agent.q_net.state_dict()[name], atol=1e-5, rtol=0)


def test_members_are_independent_another_members_data_leaves_one_bit_identical(trained_agent):
    agents = [trained_agent(3, seed) for seed in (0, 1, 2)]
    other = trained_agent(3, seed=7)
    data = [_batches(agent, 30, seed=i) for i, agent in enumerate(agents)]

    def trajectory(members, batches):
        learner = StackedExpectedSarsa.from_agents(members)
        eps = th.tensor([0.3, 0.2, 0.1])
        for step in range(30):
            learner.train_step(stack_samples([b[step] for b in batches]), eps, members[0].gamma)
            if step % 10 == 9:
                learner.sync_target()
        return learner

    plain = trajectory(agents, data)
    changed = trajectory([*agents[:2], other], [*data[:2], _batches(other, 30, seed=9)])
    for member in (0, 1):
        for name, value in _member_parameters(plain, member).items():
            assert th.equal(value, _member_parameters(changed, member)[name]), name
    assert not th.equal(plain.q_net.weights[0][2], changed.q_net.weights[0][2])
