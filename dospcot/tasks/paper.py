"""The seed paper's protocol (``task = "paper"``): its config is a
:class:`~dospcot.config.run_configs.PaperConfig`, one seed of 26 tabular runs on masked CliffWalking,
which the run layer trains in one vectorised batch (:mod:`dospcot.run.paper_protocol`)."""

from __future__ import annotations

from dospcot.config.run_configs import PaperConfig
from dospcot.tasks.registry import Task, register


@register
class PaperTask(Task):
    """The paper protocol: its runs, agents and views are fixed by the protocol, not by the config."""

    name = "paper"
    section = "tabular"

    def config_type(self) -> type:
        return PaperConfig
