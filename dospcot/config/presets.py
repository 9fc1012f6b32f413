"""The shipped presets, by name: listed and read without importing torch or stable-baselines3, so
that ``dospcot --help`` and ``dospcot train --list`` answer at once."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from dospcot.config.errors import ConfigError

PAPER_PRESETS: dict[str, str] = {"paper-text": "paper-text", "published-code": "paper-published-code"}
"""``dospcot reproduce-paper --preset`` choices and the config preset each one names."""


def _presets() -> Any:
    return resources.files("dospcot").joinpath("presets")


def preset_names() -> list[str]:
    """The shipped presets, by name."""
    return sorted(p.name[:-5] for p in _presets().iterdir() if p.name.endswith(".toml"))


def read_config_text(config: str) -> tuple[str, str]:
    """The TOML text of a preset name or a path, and where it came from."""
    if not config.endswith(".toml") and "/" not in config:
        if config not in preset_names():
            names = ", ".join(preset_names())
            raise ConfigError(f"no preset {config!r}; presets: {names} (or a path to a .toml)")
        return _presets().joinpath(f"{config}.toml").read_text(), f"preset {config}"
    path = Path(config)
    if not path.is_file():
        raise ConfigError(f"no config file {config}")
    return path.read_text(), str(path)
