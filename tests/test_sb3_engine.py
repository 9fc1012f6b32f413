"""SB3 behind its door: every private stable-baselines3 member the project touches is listed in
``policies/sb3_private.py`` and exists on the installed SB3, and a step the batched engine
(:mod:`dospcot.core.sb3_engine`) books is the step SB3's own ``learn()`` books."""

from __future__ import annotations

import ast
import importlib
from collections.abc import Iterable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import stable_baselines3
from stable_baselines3 import DQN
from stable_baselines3.common.buffers import ReplayBuffer

from dospcot.core import sb3_engine
from dospcot.policies.sb3_private import SB3_PRIVATE_MEMBERS

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def agent() -> DQN:
    model = DQN(
        "MlpPolicy", gym.make("CartPole-v1"), learning_starts=0, buffer_size=100, seed=0, device="cpu"
    )
    model.learn(8)
    return model


def _holder(path: str, agent: DQN) -> object:
    """An object of the SB3 class at ``path`` that holds its instance attributes: the learnt agent, its
    replay buffer, or the callback class itself."""
    module, _, name = path.rpartition(".")
    cls = getattr(importlib.import_module(module), name)
    for candidate in (agent, agent.replay_buffer):
        if isinstance(candidate, cls):
            return candidate
    return cls


@pytest.mark.parametrize(
    ("owner", "name"),
    [(owner, name) for owner, names in SB3_PRIVATE_MEMBERS.items() for name in names],
)
def test_every_private_sb3_member_the_project_touches_is_there(agent, owner, name):
    assert isinstance(agent.replay_buffer, ReplayBuffer)
    assert hasattr(_holder(owner, agent), name), (
        f"stable-baselines3 {stable_baselines3.__version__} has no {owner}.{name}, which dospcot uses "
        "(policies/sb3_private.py): adapt the code that uses it or pin SB3 to the tested range"
    )


def _private_names(files: Iterable[Path], defined: set[str] | None = None) -> dict[str, set[str]]:
    """Private, non-dunder names in ``files``: those they define (methods, ``self._x = ...``) where
    ``defined`` is None, else every use (attribute or method definition) of a name in ``defined``."""
    found: dict[str, set[str]] = {}
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            name = None
            if isinstance(node, ast.FunctionDef):
                name = node.name
            elif isinstance(node, ast.Attribute) and (
                defined is not None
                or (isinstance(node.ctx, ast.Store) and getattr(node.value, "id", "") == "self")
            ):
                name = node.attr
            if name and name.startswith("_") and not name.startswith("__"):
                if defined is None or name in defined:
                    found.setdefault(name, set()).add(str(path))
    return found


OWN_NAMES = {"_seeds"}
"""Private names the project defines for itself that SB3 happens to use too (nothing of SB3's)."""


def test_the_project_touches_no_private_sb3_member_the_list_lacks():
    sb3 = set(_private_names(Path(stable_baselines3.__file__).parent.rglob("*.py")))
    project = [
        path for folder in ("dospcot", "policies", "envs", "lab") for path in (ROOT / folder).rglob("*.py")
    ]
    touched = set(_private_names(project, sb3)) - OWN_NAMES
    listed = {name for names in SB3_PRIVATE_MEMBERS.values() for name in names}
    assert touched == listed, (
        f"touched, not listed: {sorted(touched - listed)}; listed, unused: {sorted(listed - touched)}"
    )


def test_a_booked_step_counts_and_stores_as_sb3_does():
    model = DQN(
        "MlpPolicy", gym.make("CartPole-v1"), learning_starts=0, buffer_size=100, seed=0, device="cpu"
    )
    sb3_engine.start_collection(model, 5)
    env = model.get_env()
    before = (model.num_timesteps, sb3_engine.calls(model), model.replay_buffer.pos)
    obs = sb3_engine.last_observation(model)
    assert obs.shape == (1, 4)
    action = np.array([1])
    new_obs, rewards, dones, infos = env.step(action)
    sb3_engine.record_step(model, action, new_obs, rewards, dones, infos)
    assert (model.num_timesteps, sb3_engine.calls(model), model.replay_buffer.pos) == tuple(
        b + 1 for b in before
    )
    stored = sb3_engine.samples_at(model.replay_buffer, np.array([0]))
    np.testing.assert_array_equal(stored.observations.numpy(), obs)
    assert int(stored.actions.item()) == 1
