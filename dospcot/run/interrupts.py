"""Ctrl-C and SIGTERM: a long command stops within seconds, says in one line what it kept and how to
resume, and leaves no child behind (docs/troubleshooting.md).

SIGTERM is turned into the ``KeyboardInterrupt`` that SIGINT raises, so both take one path; a command
that knows what it kept raises :class:`Interrupted` with it, which the command line prints.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from multiprocessing.context import BaseContext, SpawnContext, SpawnProcess
from types import FrameType


class Interrupted(Exception):  # a stop the user asked for, not a failure
    """A command stopped by SIGINT or SIGTERM.

    :param kept: what is on disk, in words (e.g. "3 of 5 rounds, in runs/tiny/<stamp>").
    :param resume: the command that continues it; empty: nothing to continue.
    """

    def __init__(self, kept: str, resume: str = "") -> None:
        super().__init__(kept + (f"; resume with: {resume}" if resume else ""))
        self.kept, self.resume = kept, resume


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Within the block, SIGTERM raises ``KeyboardInterrupt`` in the main thread as SIGINT does."""
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class _DeafToCtrlC(SpawnProcess):
    """A spawned process that starts with SIGINT ignored: the one disposition a new program inherits,
    and one Python keeps at start-up, so that a Ctrl-C while the child is still importing prints no
    ``KeyboardInterrupt`` traceback there (:func:`leave_interrupts_to_the_parent` comes too late)."""

    def start(self) -> None:
        if threading.current_thread() is not threading.main_thread():  # signal() is the main thread's
            super().start()
            return
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # for the instant of fork and exec
        try:
            super().start()
        finally:
            signal.signal(signal.SIGINT, previous)


class _DeafSpawnContext(SpawnContext):
    Process = _DeafToCtrlC


def worker_context() -> BaseContext:
    """The ``spawn`` context of processes that leave Ctrl-C to their parent from their first
    instruction (spawn, not fork: a forked child inherits torch's thread pools and locks)."""
    return _DeafSpawnContext()


def leave_interrupts_to_the_parent() -> None:
    """In a worker process: ignore SIGINT (Ctrl-C reaches the whole process group), so that the parent
    alone decides how to stop, and stops the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
