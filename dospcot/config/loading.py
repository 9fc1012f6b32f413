"""Reading a config: TOML presets and files, ``extends`` chains, ``--set`` overrides, and the checked
conversion of the resulting table into the config tree (:mod:`dospcot.config.run_configs`). The
task's own checks follow in :func:`dospcot.tasks.load_config`, which most callers want.

A config is a TOML table read with the stdlib's :mod:`tomllib`. Its keys mirror
:class:`~dospcot.config.run_configs.TrainConfig`; sections (``[env]``, ``[training]``, ``[dqn]``,
``[tabular_agent]``, ``[cotraining]``, ``[cotraining.classifier]``, ``[demonstrations]``, ...) mirror
its nested dataclasses. A config with ``task = "paper"`` is a
:class:`~dospcot.config.run_configs.PaperConfig` instead. Every key is checked against the dataclass
fields and their type hints before anything is built, so a typo or a wrong type stops the run with one
line (:class:`~dospcot.config.errors.ConfigError`) naming the key and what is allowed; a key that was
renamed names its new name.

Presets ship in ``dospcot/presets/*.toml``; a name without ``.toml`` is looked up there, anything
else is read as a path. A config may start from another with ``extends = "<preset or path>"``: its
tables are merged key by key over the base's.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import functools
import math
import re
import tomllib
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from dospcot.config.errors import ConfigError
from dospcot.config.presets import is_preset, read_config_text

BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.:/-]*")
"""A value ``--set`` takes as a string without TOML's quotes: a name, a dotted path or a file path."""
INT64 = (-(2**63), 2**63 - 1)
"""The integers a config holds: TOML 1.0's, so that every reader of a run folder's ``config.toml`` and
``summary.json`` reads them back."""
LEADING_DOT = re.compile(r"[+-]?\.[0-9]+(?:[eE][+-]?[0-9]+)?")
"""A number written without its leading zero (``.5``, ``-.25``), which TOML refuses: read as ``0.5``."""


def parse_override(text: str, option: str = "--set") -> tuple[list[str], Any]:
    """``"training.rounds=3"`` -> (["training", "rounds"], 3); values are TOML, bare words strings.

    :param option: the option that gave ``text``, as an error names it (``--grid`` gives one value).
    :raises ConfigError: the value is neither TOML nor a bare word (an unclosed quote or table).
    """
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"{option} takes key=value, got {text!r}")
    if LEADING_DOT.fullmatch(raw.strip()):  # ".5": a number, as the shell and most languages read it
        raw = raw.strip().replace(".", "0.", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        opened = {"[": raw.count("[") - raw.count("]"), "{": raw.count("{") - raw.count("}")}
        unclosed = [bracket for bracket, count in opened.items() if count]
        if unclosed:
            closing = {"[": "]", "{": "}"}[unclosed[0]]
            raise ConfigError(
                f"{option} {text}: {raw!r} opens and closes a different number of {unclosed[0]} and "
                f"{closing}; a list is [1, 2], a table {{key = 1}}"
            ) from None
        if not BARE_WORD.fullmatch(raw.strip()):
            raise ConfigError(
                f"{option} {text}: {raw!r} is not a TOML value; a string needs its quotes past the shell, "
                f"e.g. {option} '{key.strip()}=\"text\"'"
            ) from None
        value = raw.strip()
    return key.strip().split("."), value


def check_overrides(
    overrides: Sequence[str],
    grid: Sequence[str] = (),
    seeds_option: str | None = None,
    grid_name: str = "--grid",
) -> None:
    """Refuse ``--set`` overrides that would lose to something else without a word: a key set twice
    (or a key and its section), a key a ``--grid`` also sets, or ``seed`` where an option
    (``seeds_option``: ``"--seeds"`` or ``"--seed"``) gives the seeds. ``grid_name`` names the grid in
    the error (a study's sweeps vary keys of their own).

    :raises ConfigError: one line naming the key and what to give instead.
    """
    seen: dict[str, str] = {}
    for override in overrides:
        path, _ = parse_override(override)
        key = ".".join(path)
        if seeds_option is not None and key == "seed":
            seed = override.partition("=")[2].strip()
            given = seed if seeds_option == "--seed" else f"{seed}-{seed}"  # "--seeds 5" is seeds 0-4
            raise ConfigError(
                f"--set {override}: {seeds_option} gives the seeds here and would replace it; give the "
                f"seed as {seeds_option} {given} instead"
            )
        for other, text in seen.items():
            if key == other or key.startswith(f"{other}.") or other.startswith(f"{key}."):
                raise ConfigError(
                    f"--set {override} and --set {text} both set {min(key, other, key=len)}: give it once"
                )
        for name in grid:
            if key == name or name.startswith(f"{key}.") or key.startswith(f"{name}."):
                raise ConfigError(
                    f"--set {override}: {grid_name} {name} sets {min(key, name, key=len)} in every trial, "
                    "which would replace it; give it in one of the two"
                )
        seen[key] = override


def read_config_data(config: str, _seen: tuple[str, ...] = ()) -> dict[str, Any]:
    """The TOML table of a preset or a path, with its ``extends`` chain merged in."""
    if config in _seen:
        raise ConfigError(f"extends: a cycle through {' -> '.join([*_seen, config])}")
    data = copy.deepcopy(_preset_data(config)) if is_preset(config) else _toml_data(*read_config_text(config))
    if not data:  # it would train the code's defaults, which no one asked for
        raise ConfigError(
            f'{read_config_text(config)[1]} holds no key; start it from a preset: extends = "tiny"'
        )
    base = data.pop("extends", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError(f"extends: expected a preset name or a path, got {base!r}")
    return _merge(read_config_data(extends_target(config, base), (*_seen, config)), data)


@functools.cache
def _preset_data(name: str) -> dict[str, Any]:
    """A shipped preset's own table (package data, the same all process long), parsed once: a study
    resolves each of its presets for every one of its trials."""
    return _toml_data(*read_config_text(name))


def _toml_data(text: str, origin: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{origin} is not valid TOML: {err}") from None


def extends_target(config: str, base: str) -> str:
    """What ``extends = base`` in ``config`` names: a preset, or a path read from the folder of the
    file that holds it (as an ``#include`` is), not from the current folder."""
    if is_preset(base) or Path(base).is_absolute() or is_preset(config):
        return base
    return str(Path(config).parent / base)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def config_table(config: str, overrides: Sequence[str] = ()) -> dict[str, Any]:
    """The table of a preset or a TOML file with its ``extends`` chain merged in and the ``--set``
    overrides applied, not yet checked against the config tree (no I/O beyond the files)."""
    data = read_config_data(config)
    for override in overrides:
        path, value = parse_override(override)
        if path == ["extends"]:
            raise ConfigError(
                f"--set {override}: extends is read with the file, before any --set; write a .toml "
                f'holding extends = "{value}" and your keys, and pass its path as CONFIG'
            )
        set_key(data, path, value, f"--set {override}")
    return data


def given_keys(config: str, overrides: Sequence[str] = ()) -> tuple[set[str], set[str]]:
    """The dotted keys a person wrote for this config: those of its ``--set`` overrides, and, where
    ``config`` is a file rather than a shipped preset that ``extends`` another, those of that file
    itself (what it changes; a whole config written out, a run folder's ``config.toml``, holds every
    key and extends nothing). A table value names each of its keys (``--set 'training={rounds=1}'``:
    ``training.rounds``)."""
    in_file: set[str] = set()
    if not is_preset(config):
        text, _ = read_config_text(config)
        own = tomllib.loads(text)
        in_file = _dotted(own) - {"extends"} if "extends" in own else set()
    set_here: set[str] = set()
    for override in overrides:
        path, value = parse_override(override)
        table: dict[str, Any] = {}
        set_key(table, path, value, f"--set {override}")
        set_here |= _dotted(table)
    return in_file, set_here


def _dotted(table: Mapping[str, Any], prefix: str = "") -> set[str]:
    keys: set[str] = set()
    for key, value in table.items():
        if isinstance(value, Mapping):
            keys |= _dotted(value, f"{prefix}{key}.")
        else:
            keys.add(f"{prefix}{key}")
    return keys


@functools.cache
def type_hints(cls: type) -> dict[str, Any]:
    """The resolved field types of the config dataclass ``cls``, read once: resolving them is most of
    what reading a config costs, and a study checks thousands of run folders against their configs."""
    return typing.get_type_hints(cls)


def renamed_to_now(cls: type, data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` with the renamed keys of ``cls`` and of its sections (``renamed_keys``) under their new
    names, and the keys added since (``added_keys``) at the value a folder written before them ran
    under: a run folder outlives its code (the record's do), so its ``config.toml`` is read this way,
    while a config a person writes with an old key is refused (:func:`from_mapping`)."""
    renamed: dict[str, str] = getattr(cls, "renamed_keys", {})
    hints = type_hints(cls)
    out: dict[str, Any] = dict(getattr(cls, "added_keys", {}))
    for key, value in data.items():
        key = renamed.get(key, key)
        hint = hints.get(key)
        section = dataclasses.is_dataclass(hint) and isinstance(value, Mapping)
        out[key] = renamed_to_now(hint, value) if section else value
    return out


def set_key(data: dict[str, Any], path: Sequence[str], value: Any, where: str) -> None:
    """Set the key ``path`` (sections, then the key) of the config table ``data`` to ``value``,
    making missing sections; a table ``value`` merges key by key into the table already there, as
    ``extends`` does, so ``--set 'training={rounds=1}'`` changes one key, not the whole section.
    ``where`` names the override in the error for a key that is no section."""
    table = data
    for part in path[:-1]:
        table = table.setdefault(part, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {part!r} is not a section")
    old = table.get(path[-1])
    table[path[-1]] = _merge(old, value) if isinstance(old, dict) and isinstance(value, dict) else value


def from_mapping(cls: type, data: Mapping[str, Any], prefix: str = "") -> Any:
    """Build the dataclass ``cls`` from ``data``, checking every key and type (recursively)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: expected a table, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    set_elsewhere: dict[str, str] = getattr(cls, "set_elsewhere", {})
    renamed: dict[str, str] = getattr(cls, "renamed_keys", {})
    for key in data:
        if key in renamed:
            raise ConfigError(f"{prefix}{key}: renamed; the key is now {prefix}{renamed[key]}")
        if key in set_elsewhere:
            raise ConfigError(f"{prefix}{key}: not a config key here; it is set by {set_elsewhere[key]}")
        if key not in fields:
            if prefix and key in ROOT_SECTIONS:  # [env.training]: a section written inside another
                raise ConfigError(
                    f"unknown key '{prefix}{key}': [{key}] is a section of its own, not one of "
                    f"[{prefix.rstrip('.')}]; write it as [{key}] (or --set {key}.KEY=VALUE)"
                )
            close = difflib.get_close_matches(key, fields, n=3, cutoff=0.6)
            if close:
                raise ConfigError(
                    f"unknown key '{prefix}{key}'; did you mean "
                    + " or ".join(f"'{prefix}{name}'" for name in close)
                    + "?"
                )
            raise ConfigError(f"unknown key '{prefix}{key}'; allowed: {', '.join(fields)}")
    hints = type_hints(cls)
    unbounded: frozenset[str] = getattr(cls, "infinite_keys", frozenset())
    respelled: dict[str, dict[str, str]] = getattr(cls, "renamed_values", {})
    if respelled:  # only a root config has values read under a newer spelling
        data = {
            key: respelled[key].get(value, value) if key in respelled and isinstance(value, str) else value
            for key, value in data.items()
        }
    kwargs = {
        key: _convert(hints[key], value, f"{prefix}{key}", may_be_infinite=key in unbounded)
        for key, value in data.items()
    }
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: {err}") from None


SCALARS: dict[type, tuple[type | tuple[type, ...], str]] = {
    bool: (bool, "true or false"),
    int: (int, "an integer"),
    float: ((int, float), "a number"),
    str: (str, "a string"),
}
"""The scalar field types of a config: the TOML values each takes, and its name in an error."""


ROOT_SECTIONS = frozenset(
    {"env", "highway", "gym", "training", "dqn", "tabular_agent", "cotraining", "demonstrations", "tabular"}
)
"""The sections of a config's top level, which a key inside another section cannot name."""


def check_integers(value: Any, key: str) -> None:
    """Refuse any integer in ``value`` (a scalar, or lists and tables of them) outside :data:`INT64`.

    :raises ConfigError: one line naming the key and the bounds.
    """
    if isinstance(value, bool):
        return
    if isinstance(value, int) and not INT64[0] <= value <= INT64[1]:
        raise ConfigError(
            f"{key}: {value} is beyond a 64-bit integer (TOML's, from {INT64[0]:,} to {INT64[1]:,})"
        )
    if isinstance(value, Mapping):
        for name, item in value.items():
            check_integers(item, f"{key}.{name}")
    elif isinstance(value, list | tuple):
        for item in value:
            check_integers(item, key)


def _convert(hint: Any, value: Any, key: str, may_be_infinite: bool = False) -> Any:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if dataclasses.is_dataclass(hint):
        return from_mapping(hint, value, f"{key}.")
    if origin is Literal:
        if value not in args:
            raise ConfigError(f"{key}: {value!r} is not allowed; allowed: {', '.join(map(str, args))}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        return tuple(_convert(args[0], item, key, may_be_infinite) for item in value)
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key}: expected a table, got {value!r}")
        check_integers(value, key)
        return dict(value)
    if hint in SCALARS:
        accepted, what = SCALARS[hint]
        # A TOML true is a Python int too: only a bool field takes it.
        if not isinstance(value, accepted) or (isinstance(value, bool) and hint is not bool):
            raise ConfigError(f"{key}: expected {what}, got {value!r}")
        # NaN compares false with every bound, and an infinite value with most: neither is a setting.
        check_integers(value, key)
        if hint is float and (math.isnan(value) or (math.isinf(value) and not may_be_infinite)):
            raise ConfigError(f"{key}: expected a finite number, got {value!r}")
        return hint(value)
    raise ConfigError(f"{key}: cannot be set from a config")  # pragma: no cover - a field type we never use
