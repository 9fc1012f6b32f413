"""A sparse first layer for views of 0s and 1s: the dense layer's values and gradients from the inputs
that are on, Adam's steps as under ``nn.Linear``, and agents that stock SB3 loads without dospcot."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN
from torch import nn

from dospcot.config.learning_sections import ClassifierConfig, CoTrainingConfig
from dospcot.core.classifier import BatchedRewardClassifier
from dospcot.core.reward_model import RewardModelTrainer
from dospcot.core.self_paced import SelfPacedCoTrainer
from dospcot.policies import ExpectedSarsaDQN
from dospcot.policies.esarsa_dqn.sparse_inputs import SparseInputLinear, sparsify_first_layer
from dospcot.policies.stacked_esarsa.stacked_q_network import StackedQNetwork

REPO = Path(__file__).resolve().parents[1]


def _inputs(rows: int, width: int, seed: int, binary: bool = True) -> th.Tensor:
    """(rows, width) float64, about a tenth of it nonzero, one row and the last third of the inputs
    all 0 (as the inputs off the map in an egocentric view)."""
    gen = th.Generator().manual_seed(seed)
    on = th.rand(rows, width, generator=gen) < 0.1
    values = th.ones(rows, width) if binary else th.randn(rows, width, generator=gen)
    x = (on * values).double()
    x[1] = 0.0
    x[:, width - width // 3 :] = 0.0
    return x


@pytest.mark.parametrize("binary", [True, False])
def test_the_sparse_layer_gives_the_dense_layers_values_and_gradients_in_float64(binary: bool) -> None:
    th.manual_seed(0)
    dense = nn.Linear(50, 7).double()
    sparse = SparseInputLinear(dense)
    x = _inputs(9, 50, seed=1, binary=binary)
    upstream = th.randn(9, 7, dtype=th.float64)
    a, b = dense(x), sparse(x)
    (a * upstream).sum().backward()
    (b * upstream).sum().backward()
    assert th.allclose(a, b, rtol=0, atol=1e-13)
    assert sparse.weight_t.grad.shape == (50, 7)  # dense: every row, zero where no input was on
    assert th.allclose(dense.weight.grad, sparse.weight_t.grad.t(), rtol=0, atol=1e-13)
    assert th.allclose(dense.bias.grad, sparse.bias.grad, rtol=0, atol=1e-13)
    assert sparse.bias is dense.bias
    nothing = th.zeros(3, 50, dtype=th.float64)
    assert th.equal(sparse(nothing), dense.bias.detach().expand(3, 7))


def test_adam_takes_the_same_steps_on_the_sparse_layer_as_on_the_dense_one() -> None:
    th.manual_seed(0)
    dense = nn.Sequential(nn.Linear(40, 16), nn.ReLU(), nn.Linear(16, 3)).double()
    sparse = nn.Sequential(nn.Linear(40, 16), nn.ReLU(), nn.Linear(16, 3)).double()
    sparse.load_state_dict(dense.state_dict())
    assert isinstance(sparsify_first_layer(sparse), SparseInputLinear)
    optimisers = [th.optim.Adam(net.parameters(), lr=1e-2) for net in (dense, sparse)]
    for step in range(20):
        x, y = _inputs(8, 40, seed=step), th.randn(8, 3, dtype=th.float64)
        for net, optimiser in zip((dense, sparse), optimisers, strict=True):
            optimiser.zero_grad()
            ((net(x) - y) ** 2).mean().backward()
            optimiser.step()
    for name, value in dense.state_dict().items():
        assert th.allclose(value, sparse.state_dict()[name], rtol=0, atol=1e-12), name


def test_the_sparse_layer_saves_and_loads_nn_linears_state_dict() -> None:
    dense = nn.Linear(6, 4)
    sparse = SparseInputLinear(nn.Linear(6, 4))
    sparse.load_state_dict(dense.state_dict())
    assert {k: v.shape for k, v in sparse.state_dict().items()} == {"weight": (4, 6), "bias": (4,)}
    again = nn.Linear(6, 4)
    again.load_state_dict(sparse.state_dict())
    assert th.equal(again.weight, dense.weight) and th.equal(again.bias, dense.bias)
    with pytest.raises(RuntimeError, match="size mismatch"):
        sparse.load_state_dict(nn.Linear(4, 6).state_dict())
    with pytest.raises(RuntimeError, match="Missing key"):
        sparse.load_state_dict({"weight": dense.weight.detach()})


class OneHotBits(gym.ObservationWrapper):
    """CliffWalking's state as 48 indicators in a ``Box(0, 1)`` of uint8 (a view of 0s and 1s)."""

    def __init__(self) -> None:
        super().__init__(gym.make("CliffWalking-v1", max_episode_steps=100))
        self.observation_space = gym.spaces.Box(0, 1, (48,), np.uint8)

    def observation(self, observation: int) -> np.ndarray:
        return np.eye(48, dtype=np.uint8)[observation]


def _agent(**kwargs) -> ExpectedSarsaDQN:
    return ExpectedSarsaDQN(
        "MlpPolicy",
        OneHotBits(),
        learning_starts=20,
        policy_kwargs={"net_arch": [16]},
        seed=3,
        sparse_inputs=True,
        fused_adam=True,
        **kwargs,
    )


def test_an_agent_on_a_binary_view_gets_the_sparse_layer_and_a_fused_adam() -> None:
    agent = _agent()
    for net in (agent.q_net, agent.q_net_target):
        assert isinstance(net.q_net[0], SparseInputLinear)
    assert agent.policy.optimizer.defaults["fused"] is True
    ids = {id(p) for group in agent.policy.optimizer.param_groups for p in group["params"]}
    assert ids == {id(p) for p in agent.q_net.parameters()}
    agent.learn(120)
    assert agent.q_net.q_net[0].weight_t.grad is not None
    # A view of other values keeps the stock layer.
    plain = ExpectedSarsaDQN("MlpPolicy", gym.make("CartPole-v1"), sparse_inputs=True, seed=0)
    assert type(plain.q_net.q_net[0]) is nn.Linear


def test_the_saved_agent_loads_back_and_into_stock_dqn_which_can_train_on(tmp_path: Path) -> None:
    agent = _agent()
    agent.learn(150)
    agent.save(tmp_path / "agent.zip")
    loaded = ExpectedSarsaDQN.load(tmp_path / "agent.zip", env=OneHotBits())
    assert isinstance(loaded.q_net.q_net[0], SparseInputLinear)
    for p, q in zip(agent.policy.parameters(), loaded.policy.parameters(), strict=True):
        assert th.equal(p, q)
    ours, theirs = agent.policy.optimizer.state, loaded.policy.optimizer.state
    for p, q in zip(agent.q_net.parameters(), loaded.q_net.parameters(), strict=True):
        assert all(th.equal(ours[p][k], theirs[q][k]) for k in ("exp_avg", "exp_avg_sq"))
    loaded.learn(40)
    with pytest.raises(ValueError, match="sparse first layer"):
        StackedQNetwork.from_q_networks([agent.q_net])
    stock = DQN.load(tmp_path / "agent.zip", env=OneHotBits())
    first = stock.q_net.q_net[0]
    assert type(first) is nn.Linear and th.equal(first.weight, agent.q_net.q_net[0].weight)
    assert stock.policy.optimizer.state[first.weight]["exp_avg"].shape == first.weight.shape
    stock.learn(40)  # its Adam reads the moments in its own layout


def test_stock_sb3_loads_the_agent_where_dospcot_cannot_be_imported(tmp_path: Path) -> None:
    agent = _agent()
    agent.learn(150)
    agent.save(tmp_path / "agent.zip")
    obs = np.eye(48, dtype=np.uint8)
    with th.no_grad():
        q = agent.q_net(th.as_tensor(obs)).numpy()
    np.save(tmp_path / "obs.npy", obs)
    np.save(tmp_path / "q.npy", q)
    script = textwrap.dedent(f"""
        import importlib.util, sys
        sys.meta_path = [f for f in sys.meta_path if "__editable__" not in repr(f)]
        sys.path = [p for p in sys.path if "site-packages" in p or not p.startswith({str(REPO)!r})]
        assert importlib.util.find_spec("dospcot") is None, "dospcot is importable"
        import numpy as np, torch
        from stable_baselines3 import DQN
        model = DQN.load("agent.zip")
        assert not any(m.startswith("dospcot") for m in sys.modules), "dospcot was imported"
        with torch.no_grad():
            q = model.q_net(torch.as_tensor(np.load("obs.npy"))).numpy()
        np.testing.assert_allclose(q, np.load("q.npy"), rtol=0, atol=1e-5)
        print("ok")
    """)
    out = subprocess.run(
        [sys.executable, "-I", "-c", script], cwd=tmp_path, capture_output=True, text=True, check=False
    )
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


@pytest.mark.parametrize("model", ["mlp", "linear"])
def test_a_classifier_with_sparse_inputs_and_fused_adam_fits_as_the_dense_one_in_float64(model: str) -> None:
    config = ClassifierConfig(model=model, loss="cross_entropy" if model == "mlp" else "hinge", hidden=8)
    gen = th.Generator().manual_seed(0)
    x = _inputs(2 * 30, 40, seed=5).view(2, 30, 40)
    y = th.randint(0, 3, (2, 30), generator=gen)
    weight = th.rand(2, 30, generator=gen, dtype=th.float64)
    mask = th.ones(2, 3, dtype=th.bool)
    dense = BatchedRewardClassifier(2, 40, 3, config, seeds=[1, 2]).double()
    sparse = BatchedRewardClassifier(2, 40, 3, config, [1, 2], sparse_inputs=True, fused_adam=True).double()
    assert th.allclose(dense(x, mask), sparse(x, mask), rtol=0, atol=1e-13)
    losses = dense.fit(x, y, weight, mask), sparse.fit(x, y, weight, mask)
    assert th.allclose(*losses, rtol=0, atol=1e-10)
    for a, b in zip(dense.parameters(), sparse.parameters(), strict=True):
        assert th.allclose(a, b, rtol=0, atol=1e-10)


def test_numerics_3_gives_the_classifiers_and_agents_the_sparse_layer_and_fused_adam() -> None:
    config = CoTrainingConfig(numerics=3)
    trainer = SelfPacedCoTrainer([12, 5], 1, config, [0], 2)
    assert all(clf.sparse_inputs and clf.fused_adam for clf in trainer.classifiers)
    assert all(p.dtype == th.float32 for clf in trainer.classifiers for p in clf.parameters())
    models = RewardModelTrainer([12], config, 0, 2)
    assert all(clf.sparse_inputs and clf.fused_adam for clf in models.classifiers)
    for numerics in (1, 2):
        plain = SelfPacedCoTrainer([12], 1, CoTrainingConfig(numerics=numerics), [0], 2)
        assert not plain.classifiers[0].sparse_inputs and not plain.classifiers[0].fused_adam
