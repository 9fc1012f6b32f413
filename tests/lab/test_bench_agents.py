"""The agent ``dospcot-lab bench --only ego_gradient_step`` times: the preset's agent on MiniGrid's
egocentric map under numerics 3, whose replay stores bits and whose first layer reads them sparsely."""

import pytest
import torch as th
from torch import nn

from dospcot.policies.esarsa_dqn.sparse_inputs import SparseInputLinear
from dospcot_lab.bench_agents import ego_agent


def test_the_egocentric_maps_agent_under_numerics_3_stores_bits_and_reads_them_sparsely() -> None:
    pytest.importorskip("minigrid")
    agent = ego_agent(sparse_inputs=True, fused_adam=True, fill=300)
    buffer = agent.replay_buffer
    assert buffer.packed and agent.observation_space.shape == (2535,)
    # 2,535 inputs in 317 bytes a step: an eighth of the uint8 view's 2,535.
    assert buffer.observations.shape == buffer.next_observations.shape == (300, 1, 317)
    sample = buffer.sample(64).observations
    assert sample.shape == (64, 2535) and int(sample.max()) == 1
    for net in (agent.q_net, agent.q_net_target):
        assert isinstance(net.q_net[0], SparseInputLinear)
    with th.no_grad():
        q = agent.q_net(sample)
    dense = nn.Linear(2535, 128)
    dense.load_state_dict(agent.q_net.q_net[0].state_dict())
    with th.no_grad():
        hidden = agent.q_net.q_net[1:](dense(sample.float()))
    assert th.allclose(q, hidden, rtol=0, atol=1e-5)
