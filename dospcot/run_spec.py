"""What one run is: a method, one agent per view, gamma and a seed (shared by both co-trainers)."""

from __future__ import annotations

from dataclasses import dataclass

METHODS: tuple[str, ...] = ("oracle", "masked-zero", "labels-only", "cotrain")
"""``oracle``: every key labelled; ``masked-zero``: masked rewards read as 0; ``labels-only``: masked
steps drive no update; ``cotrain``: DOSPCoT with the run's views (m = 1 is self-training)."""


@dataclass(frozen=True)
class RunSpec:
    """One run.

    :param method: one of :data:`METHODS`.
    :param agents: agent kind of each view.
    :param views: the view of each agent (its reward classifier's input).
    :param gamma: co-regularisation weight (co-training only).
    :param seed: seeds the mask, the exploration and the classifiers; runs of different methods
        with the same seed share the labelled key set.
    """

    method: str
    agents: tuple[str, ...]
    views: tuple[str, ...]
    gamma: float = 0.3
    seed: int = 0

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if len(self.agents) < 1 or len(self.agents) != len(self.views):
            raise ValueError(
                "need one view per agent and at least one agent; "
                f"got agents={self.agents}, views={self.views}"
            )
        for kind in self.agents:
            self.check_agent(kind)

    def check_agent(self, kind: str) -> None:
        """Raise ``ValueError`` for an agent kind this co-trainer cannot drive."""
