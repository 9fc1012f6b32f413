"""Reading a config under its version of the defaults (:mod:`dospcot.config.versions` says what each
version moves): which version a table names, the keys that version moves for it, and the table with
them filled in. Nothing here imports torch."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from typing import Any, get_args

from dospcot.config.choices import Method
from dospcot.config.errors import ConfigError
from dospcot.config.loading import set_key
from dospcot.config.task_sections import EnvConfig, GymConfig
from dospcot.config.versions import ADOPTED, BASES, CANDIDATES, FIRST, VERSIONS, TaskSection


def version_of(table: Mapping[str, Any]) -> int:
    """The version of the defaults ``table`` was written against: its ``defaults``, else :data:`ADOPTED`.

    :raises ConfigError: an unknown version.
    """
    version = table.get("defaults", ADOPTED)
    if isinstance(version, bool) or not isinstance(version, int) or version not in VERSIONS:
        raise ConfigError(f"defaults: unknown version {version!r}; {versions_text()}")
    return version


def versions_text() -> str:
    """The versions in words, for messages and ``dospcot config``."""
    words = []
    for version in VERSIONS:
        state = " (adopted)" if version == ADOPTED else " (candidate)" if version in CANDIDATES else ""
        words.append(f"{version}{state}")
    return "the versions: " + ", ".join(words)


def lineage(version: int) -> list[int]:
    """The versions whose moves make up ``version``'s defaults, oldest first (without the first
    version, which moves nothing): ``version`` after the versions it builds on (:data:`BASES`)."""
    chain = []
    while version != FIRST:
        chain.append(version)
        version = BASES[version]
    return chain[::-1]


def adopted_moves(method: str | None = None) -> dict[str, Any]:
    """The keys the adopted version moves for a config that sets nothing of its own but ``method`` (None:
    the default method; the default views and task): dotted key -> its default there. The configuration
    reference shows these."""
    table = {} if method is None else {"method": method}
    return {key: value for key, (value, _) in moved_keys(table, ("env", EnvConfig)).items()}


def moved_for_some_methods() -> dict[str, list[str]]:
    """The keys the adopted version moves to their default for :func:`adopted_moves` under some methods
    and not others: dotted key -> the methods it moves them for (the reward-model peer keeps one
    co-training pass a round, say, where DOSPCoT takes ten)."""
    adopted = adopted_moves()
    by_method = {method: adopted_moves(method) for method in get_args(Method)}
    found = {
        key: [m for m, moves in by_method.items() if moves.get(key) == value]
        for key, value in adopted.items()
    }
    return {key: methods for key, methods in found.items() if len(methods) < len(by_method)}


def gym_moves() -> dict[str, tuple[Any, list[str]]]:
    """The keys the adopted version moves otherwise for a gym task (``task = "gym"``) than for
    :func:`adopted_moves`'s grid, under some method: dotted key -> (its default there, the methods it is
    moved for). The configuration reference shows these beside the grid's default."""
    grid = {method: adopted_moves(method) for method in get_args(Method)}
    found: dict[str, tuple[Any, list[str]]] = {}
    for method in get_args(Method):
        for key, (value, _) in moved_keys({"method": method, "task": "gym"}, ("gym", GymConfig)).items():
            if grid[method].get(key) != value:
                found.setdefault(key, (value, []))[1].append(method)
    return found


def moved_keys(table: Mapping[str, Any], section: TaskSection) -> dict[str, tuple[Any, str]]:
    """The keys ``table``'s version moves for it and that it does not set itself: dotted key -> (the
    version's value, why).

    :param section: the config's task section: its name, and its dataclass, whose fields say which
        ``{section}`` keys it has.
    """
    version = version_of(table)
    name, fields = section[0], {f.name for f in dataclasses.fields(section[1])}
    moved: dict[str, tuple[Any, str]] = {}
    for number in lineage(version):
        for rule in VERSIONS[number]:
            if rule.sections is not None and name not in rule.sections:
                continue
            head, _, key = rule.key.partition(".")
            if head == "{section}" and key not in fields:
                continue
            dotted = f"{name}.{key}" if head == "{section}" else rule.key
            value = rule.value(table)
            if value is not None and not _has(table, dotted):
                moved[dotted] = (value, rule.why)
    return moved


def with_version_defaults(table: Mapping[str, Any], section: TaskSection) -> dict[str, Any]:
    """``table`` with the defaults its version moves filled in where it sets nothing itself."""
    out = copy.deepcopy(dict(table))
    for key, (value, _) in moved_keys(table, section).items():
        set_key(out, key.split("."), value, f"defaults = {version_of(table)}")
    return out


def fit_budget(table: Mapping[str, Any], section: TaskSection, most_samples: int) -> dict[str, Any] | None:
    """``table`` with the version's label budget lowered to ``most_samples`` (a run too short to meet
    :data:`BUDGET` samples), or None where the budget is the config's own or fits."""
    moved = moved_keys(table, section)
    if "training.label_budget" not in moved or moved["training.label_budget"][0] <= most_samples:
        return None
    out = copy.deepcopy(dict(table))
    set_key(out, ["training", "label_budget"], most_samples, "training.label_budget")
    return out


def _has(table: Mapping[str, Any], key: str) -> bool:
    part: Any = table
    for name in key.split("."):
        if not isinstance(part, Mapping) or name not in part:
            return False
        part = part[name]
    return True
