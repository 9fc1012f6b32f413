"""Each agent's own draws (``training.agent_draws = "own"``): agent k of a co-trained run with every
reward labelled computes what agent k of a one-view run computes, bit for bit; a one-agent run is the
same under both settings; a run resumed from its checkpoint continues its agents' own draws."""

import pickle
from functools import cache

import pytest
import torch as th
from small_runs import PINNED

from dospcot.config.errors import ConfigError
from dospcot.config.learning_sections import TrainingConfig
from dospcot.config.loading import renamed_to_now
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

SHORT = [
    *PINNED,
    "training.rounds=2",
    "training.steps_per_round=150",
    "dqn.learning_starts=30",
    "training.update_steps=20",
]
"""grid16-dospcot, shortened, with every reward labelled: the views' co-training changes no reward."""


@cache
def _agent_params(views: str, draws: str, rounds: int = 1) -> list[th.Tensor]:
    """Agent 0's parameters after each of ``rounds`` rounds of a run on ``views`` (trained once per
    module: the tests only read them)."""
    overrides = [*SHORT, "training.label_fraction=1.0", f"views={views}", f'training.agent_draws="{draws}"']
    run = build_run(load_config("grid16-dospcot", overrides))
    params = []
    for _ in range(rounds):
        run.run_round()
        params.append(th.cat([p.detach().flatten() for p in run.agents[0].policy.parameters()]))
    return params


def test_with_own_draws_a_co_trained_agent_is_the_one_view_runs_agent_bit_for_bit():
    alone = _agent_params('["patch"]', "own")
    beside = _agent_params('["patch", "rays"]', "own")
    for round_alone, round_beside in zip(alone, beside, strict=True):
        assert th.equal(round_alone, round_beside)
    # Sharing the global generators, the second agent's draws move the first's (the control's confound).
    shared = _agent_params('["patch", "rays"]', "shared")
    assert not th.equal(shared[-1], alone[-1])


def test_a_one_agent_run_draws_the_same_under_both_settings():
    own, shared = _agent_params('["patch"]', "own"), _agent_params('["patch"]', "shared")
    assert all(th.equal(a, b) for a, b in zip(own, shared, strict=True))


def test_a_run_resumed_from_its_checkpoint_continues_its_agents_own_draws():
    overrides = [*SHORT, 'training.agent_draws="own"']
    cfg = load_config("grid16-dospcot", overrides)
    first = build_run(cfg)
    first.run_round()
    state = pickle.dumps(first.state_dict())  # before another run is built: that re-seeds the globals
    first.run_round()
    resumed = build_run(cfg)
    resumed.load_state_dict(pickle.loads(state))
    resumed.run_round()
    for k in range(2):
        a, b = (
            th.cat([p.detach().flatten() for p in r.agents[k].policy.parameters()]) for r in (first, resumed)
        )
        assert th.equal(a, b)


def test_agent_draws_names_its_choices():
    with pytest.raises(
        ConfigError, match=r"training\.agent_draws: 'mine' is not allowed; allowed: shared, own"
    ):
        load_config("grid16-dospcot", ['training.agent_draws="mine"'])


def test_a_folder_or_checkpoint_written_before_the_key_reads_shared_whatever_the_default():
    old_table = renamed_to_now(TrainingConfig, {"rounds": 3})
    assert old_table == {
        "agent_draws": "shared",
        "cotrain_passes": 1,
        "first_labels": "round_end",
        "passes_from_round": 1,
        "pass_kind": "cotrain",
        "query_end_states": "random",
        "stop_patience": 0,
        "rounds": 3,
    }
    state = dict(TrainingConfig(agent_draws="own").__dict__)
    del state["agent_draws"]
    old = TrainingConfig.__new__(TrainingConfig)
    old.__setstate__(state)
    assert old.agent_draws == "shared"
