"""A co-training run's checkpoint: everything its next rounds depend on, as one picklable dict
(:meth:`dospcot.core.sb3_round.CoTrainingRun.state_dict`), and the way back into a run built from the
same config."""

from __future__ import annotations

import io
from typing import Any

from dospcot.core.agent_draws import global_draws, set_global_draws


def run_state(run: Any) -> dict[str, Any]:
    """Everything the next rounds of ``run`` depend on, picklable: agents (SB3 zips as bytes), their
    replay buffers, the store, the reward table, the co-trainer and the global and action-space RNGs.
    ``run`` is a :class:`~dospcot.core.sb3_round.CoTrainingRun`, which imports this module.

    The envs hold no state across rounds (each round starts from seeded resets). The dict refers
    to live objects: pickle it at once (as ``dospcot train`` does), do not keep it.
    """
    zips = []
    for agent in run.agents:
        blob = io.BytesIO()
        agent.save(blob)
        zips.append(blob.getvalue())
    return {
        "round": run.round,
        "stopped": run.stopped,
        "patience": (run.stop_reason, *run.patience.state()),
        "agents": zips,
        "buffers": [agent.replay_buffer for agent in run.agents],
        "action_space_rng": [agent.action_space.np_random.bit_generator.state for agent in run.agents],
        "store": run.store.state_dict(),
        "segments": None if run.segments is None else run.segments.state_dict(),
        "segment_classes": run.segment_classes,
        "table": run.table.state_dict(),
        "classes": run.classes,
        "trainer": run.trainer,
        "collected": run.collected,
        "class_records": run.class_records,
        "queries": None
        if run.queries is None
        else (run.queries.revealed, run.queries.met_round, run.queries.log),
        # SB3 draws exploration and replay batches from the legacy global generators.
        "rng": global_draws(),
        "agent_draws": None if run.agent_draws is None else run.agent_draws.states,
    }


def load_run_state(run: Any, state: dict[str, Any]) -> None:
    """Continue ``run`` from :func:`run_state` (``run`` must be built from the same spec and config)."""
    run.round, run.stopped = state["round"], state["stopped"]
    run.stop_reason, *patience = state["patience"]
    run.patience.load_state(tuple(patience))
    run.store.load_state_dict(state["store"])  # in place: the store wrappers keep pointing at it
    if run.segments is not None:
        run.segments.load_state_dict(state["segments"])
    if state["segment_classes"] is not None:  # None: a checkpoint written before they were kept
        run.segment_classes = state["segment_classes"]
    run.table.load_state_dict(state["table"])
    run.task.classes, run.trainer = state["classes"], state["trainer"]
    # A checkpoint is written after a round's co-training, whose classes the run still has.
    run.scored_classes = run.classes.mask.copy() if run.round else None
    run.collected, run.class_records = state["collected"], state["class_records"]
    if run.queries is not None:
        run.queries.revealed, run.queries.met_round, run.queries.log = state["queries"]
    for k, agent in enumerate(run.agents):
        loaded = type(agent).load(io.BytesIO(state["agents"][k]), env=agent.get_env())
        loaded.replay_buffer = state["buffers"][k]
        loaded.replay_buffer.reward_table = agent.replay_buffer.reward_table
        loaded.action_space.np_random.bit_generator.state = state["action_space_rng"][k]
        run.agents[k] = loaded
        run.give_demonstrations(k)
    if run.agent_draws is not None:
        run.agent_draws.states = state["agent_draws"]
    # Loading re-seeds the global generators (SB3's _setup_model): restore them last.
    set_global_draws(state["rng"])
