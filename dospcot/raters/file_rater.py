"""The file rater: a person answers a run's reward queries (docs/queries.md). The simulated rater,
which answers from the hidden reward, is :class:`dospcot.core.queries.SimulatedRater`.

:class:`FileRater` writes each round's queries to ``queries/round_<r>.csv`` in the run folder and stops
the run (:class:`QueriesPending`); ``dospcot train --resume`` reads the answers from the ``reward``
column of that file (:mod:`dospcot.raters.answer_files`). A query's frames (PNG images,
:func:`encode_png`) go beside it, in ``queries/round_<r>/``, its row naming them.
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from dospcot.raters.answer_files import (
    QUERY_COLUMNS,
    RaterError,
    read_answers,
    rewards_seen,
    show,
    write_rows,
)

__all__ = ["FileRater", "QueriesPending", "RaterError", "action_names", "encode_png"]

ACTION_NAMES = {
    "GridWorld": ("up", "right", "down", "left"),
    "CliffWalkingEnv": ("up", "right", "down", "left"),
}
"""What the actions of the envs that do not name them mean, by the unwrapped env's class."""


def encode_png(image: np.ndarray) -> bytes:
    """A PNG of ``image``, (H, W, 3) uint8 RGB (an env's ``render()`` in mode ``"rgb_array"``)."""
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


class QueriesPending(Exception):
    """The rater has queries waiting for a person's answers; the run stops until they are given."""

    def __init__(self, count: int, path: Path) -> None:
        super().__init__(f"{count} reward queries wait in {path}: fill in its reward column, then resume")
        self.count, self.path = count, path


class FileRater:
    """Writes each round's queries for a person and reads the answers back.

    :param folder: where the query files go (``<run>/queries``).
    :param views: the run's view names, which name each view's prediction column.
    """

    def __init__(self, folder: Path, views: Sequence[str] = ()) -> None:
        self.folder, self.views = folder, tuple(views)
        self.actions: tuple[str, ...] | None = None
        """What each action means (:func:`action_names`), shown beside its number; None: unknown."""

    def path(self, round_: int) -> Path:
        """The query file of round ``round_``."""
        return self.folder / f"round_{round_}.csv"

    def answer(self, round_: int, ids: np.ndarray, described: Sequence[dict[str, object]]) -> np.ndarray:
        """The rewards a person wrote for ``ids``; the first time, write the queries and raise
        :class:`QueriesPending`.

        :raises RaterError: the file does not answer every query with a finite number, or gives a
            reward not seen in an earlier round without its confirmation (:mod:`dospcot.raters.answer_files`).
        """
        path = self.path(round_)
        seen = rewards_seen(self.folder, round_)
        if not path.is_file():
            self.folder.mkdir(parents=True, exist_ok=True)
            listed = ", ".join(show(v) for v in seen) or "none yet"
            classes = self._class_values()
            rows = [
                {"sample": int(i), **self._shown(round_, int(i), row, classes), "rewards_seen": listed}
                for i, row in zip(ids, described, strict=True)
            ]
            fields = list(dict.fromkeys([*QUERY_COLUMNS, *(k for row in rows for k in row)]))
            write_rows(path, fields, rows)
            raise QueriesPending(len(ids), path)
        return read_answers(path, ids, seen, self.folder.parent)

    def _class_values(self) -> list[float]:
        """The reward of each class of the run's classifiers, as its last finished round wrote them
        (``reward_classes.json`` beside the queries folder); empty before."""
        path = self.folder.parent / "reward_classes.json"
        return json.loads(path.read_text())["rewards"] if path.is_file() else []

    def _shown(
        self, round_: int, sample: int, described: dict[str, object], classes: Sequence[float]
    ) -> dict[str, object]:
        """What a person reads of a query: ``described`` with each PNG written to
        ``round_<r>/<sample>_<column>.png`` and named in its place (relative to the queries folder),
        the action's meaning beside its number, and each view's prediction as a reward, named by view."""
        row: dict[str, Any] = {}
        for column, value in described.items():
            if isinstance(value, bytes):
                name = Path(f"round_{round_}") / f"{sample}_{column}.png"
                (self.folder / name).parent.mkdir(exist_ok=True)
                (self.folder / name).write_bytes(value)
                value = name.as_posix()
            prediction = re.fullmatch(r"view(\d+)_(class|confidence)", column)
            if prediction is not None and int(prediction.group(1)) < len(self.views):
                view = self.views[int(prediction.group(1))]
                if prediction.group(2) == "class":
                    column = f"{view}_predicts"
                    value = show(classes[int(value)]) if int(value) < len(classes) else f"class {value}"
                else:
                    column = f"{view}_confidence"
            if column == "key" and self.actions is not None:
                action = re.search(r"action (\d+)$", str(value))
                if action is not None and int(action.group(1)) < len(self.actions):
                    value = f"{value} ({self.actions[int(action.group(1))]})"
            row[column] = value
        return row


def action_names(task: Any) -> tuple[str, ...] | None:
    """What each action of a task's env means, where the env tells it (MiniGrid, highway-env) or
    :data:`ACTION_NAMES` knows it; None otherwise.

    :param task: a task adapter, whose ``eval_envs`` or ``make_env()`` gives an env of the task.
    """
    envs = getattr(task, "eval_envs", None)
    env = envs[0] if envs else getattr(task, "make_env", lambda: None)()
    env = getattr(env, "envs", [env])[0]  # an SB3 VecEnv's first env
    if env is None:
        return None
    base = env.unwrapped
    if base.__class__.__name__ in ACTION_NAMES:
        return ACTION_NAMES[base.__class__.__name__]
    enum = getattr(base, "actions", None)  # MiniGrid: an IntEnum of its actions
    if enum is not None and hasattr(enum, "__members__"):
        try:
            kept = env.get_wrapper_attr("actions")  # a wrapper that keeps some of them, in order
        except AttributeError:
            kept = enum
        kept = list(enum) if kept is enum else kept
        return tuple(enum(int(a)).name.replace("_", " ") for a in kept)
    meta = getattr(getattr(base, "action_type", None), "actions", None)  # highway-env's meta actions
    if isinstance(meta, dict):
        return tuple(str(meta[i]).replace("_", " ").lower() for i in sorted(meta))
    return None
