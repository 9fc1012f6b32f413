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


def did_you_mean(name: str, names: Iterable[str], what: str | None, shown: int | None = 6) -> str:
    """``"; did you mean 'grid16'?"`` where some of ``names`` are close to ``name`` (:mod:`difflib`,
    letter case aside), else ``"; <what>: a, b, ..."`` with the first ``shown`` names (None: all), or
    ``""`` where ``what`` is None: a misspelling is answered with the name meant, not with a list to
    search."""
    names = list(names)
    by_lower = {n.lower(): n for n in names}
    close = [by_lower[c] for c in difflib.get_close_matches(name.lower(), list(by_lower), n=3, cutoff=0.6)]
    if close:
        return "; did you mean " + " or ".join(repr(c) for c in close) + "?"
    if what is None:
        return ""
    listed = names if shown is None else names[:shown]
    return f"; {what}: " + ", ".join(listed) + (", ..." if len(listed) < len(names) else "")


CONFIG_MAX_BYTES = 1 << 20
"""The largest config file read: a config is a page of keys, and a larger file is some other file."""
BOM = "\ufeff"
"""The byte-order mark some editors write at the start of a UTF-8 file; TOML has no place for it."""


def is_preset(config: str) -> bool:
    """Whether ``config`` names a shipped preset rather than a path (no ``.toml`` and no folder)."""
    return not config.endswith(".toml") and "/" not in config


def read_config_text(config: str) -> tuple[str, str]:
    """The TOML text of a preset name or a path, and where it came from: a UTF-8 file of at most
    :data:`CONFIG_MAX_BYTES`, a leading byte-order mark dropped.

    :raises ConfigError: no such preset or file; a folder, a device or another file that is not a
        regular one (never read: ``/dev/zero`` would not end); a file too large or not UTF-8 text.
    """
    path = Path(config)
    if path.is_dir():
        raise ConfigError(_folder_given(path))
    if is_preset(config):
        if config not in preset_names():
            hint = did_you_mean(config, preset_names(), "presets (dospcot train --list)")
            raise ConfigError(f"no preset {config!r}{hint} (or give a path to a .toml)")
        return _presets().joinpath(f"{config}.toml").read_text(), f"preset {config}"
    if not path.exists():
        raise ConfigError(f"no config file {config}")
    if not path.is_file():
        raise ConfigError(f"{config} is not a regular file (a device, a pipe or a socket): give a .toml file")
    try:
        size = path.stat().st_size
        if size > CONFIG_MAX_BYTES:
            raise ConfigError(
                f"{config} holds {size:,} bytes, more than a config's {CONFIG_MAX_BYTES:,}: "
                "give a .toml config"
            )
        data = path.read_bytes()
    except OSError as err:
        raise ConfigError(f"cannot read {config}: {err.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{config} is not UTF-8 text (byte {err.start}: {data[err.start : err.start + 1]!r}); a TOML "
            "config is UTF-8: save it as UTF-8"
        ) from None
    return text.removeprefix(BOM), str(path)


def _folder_given(path: Path) -> str:
    """What a folder given as a config is, and what to give instead."""
    if (path / "config.toml").exists() and not (path / "config.toml").is_file():
        return f"{path} holds a config.toml that is not a file (a folder?): give a preset or a .toml file"
    if (path / "config.toml").is_file():
        return (
            f"{path} is a run folder, not a config; to train its config again: dospcot train "
            f"{path / 'config.toml'}; to continue it: dospcot train --resume {path}"
        )
    return f"{path} is a folder, not a config: give a preset (see dospcot train --list) or a .toml file"
