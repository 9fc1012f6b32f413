"""Checkpointing of the objects a co-training run shares by reference (stores, the reward table)."""

from __future__ import annotations

from typing import Any


class InPlaceState:
    """``state_dict()`` / ``load_state_dict()`` for an object others hold a reference to: loading
    updates it in place, so the wrappers and buffers that point at it keep doing so."""

    def state_dict(self) -> dict[str, Any]:
        """Everything the object holds, for a checkpoint (arrays are shared, not copied: pickle at once)."""
        return dict(vars(self))

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict`, in place."""
        vars(self).update(state)
