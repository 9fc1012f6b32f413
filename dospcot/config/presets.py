"""The shipped presets, by name: listed and read without importing torch or stable-baselines3, so
that ``dospcot --help`` and ``dospcot train --list`` answer at once."""

from __future__ import annotations

import difflib
from collections.abc import Iterable
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


def did_you_mean(name: str, names: Iterable[str], what: str, shown: int | None = 6) -> str:
    """``"; did you mean 'grid16'?"`` where some of ``names`` are close to ``name`` (:mod:`difflib`),
    else ``"; <what>: a, b, ..."`` with the first ``shown`` names (None: all): a misspelling
    is answered with the name meant, not with a list to search."""
    names = list(names)
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.6)
    if close:
        return "; did you mean " + " or ".join(repr(c) for c in close) + "?"
    listed = names if shown is None else names[:shown]
    return f"; {what}: " + ", ".join(listed) + (", ..." if len(listed) < len(names) else "")


def read_config_text(config: str) -> tuple[str, str]:
    """The TOML text of a preset name or a path, and where it came from."""
    path = Path(config)
    if path.is_dir():
        raise ConfigError(_folder_given(path))
    if not config.endswith(".toml") and "/" not in config:
        if config not in preset_names():
            hint = did_you_mean(config, preset_names(), "presets (dospcot train --list)")
            raise ConfigError(f"no preset {config!r}{hint} (or give a path to a .toml)")
        return _presets().joinpath(f"{config}.toml").read_text(), f"preset {config}"
    if not path.is_file():
        raise ConfigError(f"no config file {config}")
    return path.read_text(), str(path)


def _folder_given(path: Path) -> str:
    """What a folder given as a config is, and what to give instead."""
    if (path / "config.toml").is_file():
        return (
            f"{path} is a run folder, not a config; to train its config again: dospcot train "
            f"{path / 'config.toml'}; to continue it: dospcot train --resume {path}"
        )
    return f"{path} is a folder, not a config: give a preset (see dospcot train --list) or a .toml file"
