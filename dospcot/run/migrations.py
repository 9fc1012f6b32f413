"""What older code wrote, read by today's, in one place.

A run folder outlives the code that trained it (the record's folders do, and a killed run resumes
under newer code), so every field later code added to a checkpoint is filled in here, at the value
that reads as "not recorded", before anything continues from it. A ``config.toml`` with a key since
renamed is read under its new name by :func:`dospcot.tasks.load_run_config` (the sections'
``renamed_keys``), while a config a person writes with an old key is refused.
"""

from __future__ import annotations

import math
from typing import Any

CHECKPOINT_FIELDS_ADDED: tuple[tuple[str, str], ...] = (
    ("cpu_s", "the CPU seconds of the sessions before: unknown (NaN)"),
    ("commits", "each earlier session's source commit: none recorded"),
    ("config_sha256", "the digest of the config the rounds trained under: not checked"),
    ("extra", "what a batch keeps beside a member's run: nothing"),
    ("run.segment_classes", "a run on segment labels' reward classes: the run's fresh ones"),
    ("run.collected", "whether a round was collected and awaits a person's answers: no, at a round's end"),
    ("run.class_records", "the pseudo-rewards per reward class of the rounds before: not recorded"),
    (
        "run.patience",
        "why the run stopped and its best greedy evaluation so far: the co-trainer's rule if it had "
        "stopped, no best yet",
    ),
)
"""The fields of a run's checkpoint state added since format 1, and what their absence means."""


def upgrade_run_state(state: dict[str, Any]) -> dict[str, Any]:
    """A run's checkpoint state (:meth:`dospcot.run.run_session.RunSession.checkpoint_state`) with every
    field of :data:`CHECKPOINT_FIELDS_ADDED` present."""
    upgraded = {
        "cpu_s": math.nan,
        "commits": [None] * state["sessions"],
        "config_sha256": None,
        "extra": {},
        **state,
    }
    # A checkpoint written before the patience rule: its co-trainer's stop, if any, is the reason.
    reason = (
        "the co-trainer's stopping rule (cotraining.tol or every sample admitted)"
        if state["run"]["stopped"]
        else ""
    )
    upgraded["run"] = {
        "segment_classes": None,
        "collected": False,
        "class_records": [],
        "patience": (reason, None, 0),
        **state["run"],
    }
    return upgraded
