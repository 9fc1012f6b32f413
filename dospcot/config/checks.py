"""Range checks the config sections share; each raises ``ValueError`` naming the field, its value and
what is allowed (the loader prefixes the section: ``training: eps_end must lie in [0, 1], got 2.0``)."""

from __future__ import annotations

from typing import Any


def check_at_least(section: Any, bound: int, *names: str) -> None:
    """Raise ``ValueError`` for the first of the section's fields ``names`` below ``bound``."""
    for name in names:
        if getattr(section, name) < bound:
            raise ValueError(f"{name} must be >= {bound}, got {getattr(section, name)}")


def check_within(section: Any, low: float, high: float, *names: str) -> None:
    """Raise ``ValueError`` for the first of the section's fields ``names`` outside [low, high]."""
    for name in names:
        if not low <= getattr(section, name) <= high:
            raise ValueError(f"{name} must lie in [{low:g}, {high:g}], got {getattr(section, name)}")


def check_positive(section: Any, *names: str) -> None:
    """Raise ``ValueError`` for the first of the section's fields ``names`` that is not above 0."""
    for name in names:
        if not getattr(section, name) > 0:
            raise ValueError(f"{name} must be > 0, got {getattr(section, name)}")


def check_label_fraction(label_fraction: float, *, queried: bool = False) -> float:
    """Return ``label_fraction`` as a float, or raise ``ValueError`` if it is outside (0, 1]: the one
    range check of a mask's random share, for the config sections and the masks alike.

    :param queried: also allow 0, a mask with no random share: the rewards are bought by queries
        instead (:mod:`dospcot.core.queries`), and only monitors and demonstrations reveal any up front.
    """
    fraction = float(label_fraction)
    if not (0.0 < fraction <= 1.0 or (queried and fraction == 0.0)):
        raise ValueError(f"label_fraction must lie in (0, 1], got {label_fraction!r}")
    return fraction
