"""The ``[dqn]`` section's fields are written out, and they cover stable-baselines3's ``DQN``: every
keyword argument a TOML value can hold is a field with SB3's default (or dospcot's, listed in
``DQN_DEFAULTS``) or is set elsewhere (``DQN_SET_ELSEWHERE``), so a new SB3 argument fails here."""

from __future__ import annotations

import dataclasses
import inspect

from stable_baselines3 import DQN

from dospcot.config.agent_sections import DQN_DEFAULTS, DQN_SET_ELSEWHERE, DQNConfig
from dospcot.policies import ExpectedSarsaDQN

DOSPCOT_FIELDS = {"net_arch", "cut_windows"}
"""``[dqn]`` fields that are dospcot's own, not SB3 ``DQN`` arguments."""


def _sb3_arguments() -> dict[str, inspect.Parameter]:
    """SB3 ``DQN``'s keyword arguments but the env, the policy and its private ones."""
    return {
        name: param
        for name, param in inspect.signature(DQN.__init__).parameters.items()
        if name not in ("self", "policy", "env") and not name.startswith("_")
    }


def _holds_toml(param: inspect.Parameter) -> bool:
    """Whether a TOML value (a bool, a number or a string) can give the argument."""
    return isinstance(param.default, bool | int | float | str) and param.default is not None


def test_every_sb3_argument_a_toml_value_can_hold_is_a_field_or_set_elsewhere():
    fields = {f.name for f in dataclasses.fields(DQNConfig)}
    toml_arguments = {name for name, param in _sb3_arguments().items() if _holds_toml(param)}
    assert toml_arguments - set(DQN_SET_ELSEWHERE) == fields - DOSPCOT_FIELDS
    assert set(DQN_SET_ELSEWHERE) <= set(_sb3_arguments())


def test_every_default_is_sb3s_unless_dospcot_names_its_own():
    sb3 = _sb3_arguments()
    for field in dataclasses.fields(DQNConfig):
        if field.name in DOSPCOT_FIELDS:
            continue
        expected = DQN_DEFAULTS.get(field.name, sb3[field.name].default)
        assert field.default == expected, f"dqn.{field.name}: {field.default!r}, expected {expected!r}"
    for name in DQN_DEFAULTS:
        assert DQN_DEFAULTS[name] != sb3[name].default, f"DQN_DEFAULTS lists {name} at SB3's own default"


def test_cut_windows_defaults_as_the_agent_does():
    agent_default = inspect.signature(ExpectedSarsaDQN.__init__).parameters["cut_windows"].default
    assert DQNConfig().cut_windows == agent_default


def test_the_agents_keyword_arguments_are_the_fields():
    kwargs = DQNConfig(net_arch=(32,)).sb3_kwargs()
    assert kwargs["policy_kwargs"] == {"net_arch": [32]}
    assert set(kwargs) == {f.name for f in dataclasses.fields(DQNConfig)} - {"net_arch"} | {"policy_kwargs"}
