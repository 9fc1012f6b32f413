"""The tabular benchmark's per-step reference (lab/bench_rows.py) is the vectorised learner, one step at
a time."""

from __future__ import annotations

import json

import numpy as np
import test_tabular
from test_tabular import ALL_METHODS, SMALL

mdp, all_methods = test_tabular.mdp, test_tabular.all_methods
"""The library tests' fixtures: the CliffWalking MDP and every method's run of it."""


def test_the_benchmarks_per_step_python_loop_is_the_same_learner(mdp, all_methods):
    """The tabular benchmark's reference does the vectorised agents' work one step at a time: every
    kind, every method, the same Q-tables and records bit for bit, and the same step count."""
    from dospcot_lab.bench_rows import PerStepTabularCoTraining

    ours, a = all_methods
    loop = PerStepTabularCoTraining(mdp, ALL_METHODS, SMALL)
    b = loop.run()
    assert np.array_equal(a.q, b.q)
    assert json.dumps(a.records) == json.dumps(b.records)
    assert ours.env_steps == loop.env_steps > 2 * 60 * 8  # 8 agents, 2 rounds of 60 episodes
