"""dospcot: Dual-Observation Self-paced Policy Co-Training.

Several agents, each seeing the world through its own view, co-train on mostly hidden rewards by
exchanging confident pseudo-rewards under a self-paced schedule.
"""

__version__ = "0.1.0"

from dospcot.config.errors import ConfigError

__all__ = ["ConfigError", "__version__"]
