"""Stops (SIGTERM, SIGINT) as exceptions, so that a stopped command cleans up after itself (stdlib only).

By default SIGTERM ends Python at once: no ``finally`` runs, so staging folders (a model's
``.MODEL.partial-*``, a dataset's ``.DS.*.tmp``) stay forever and worker processes are orphaned.
:func:`stops_as_exceptions` (the command line wraps every command in it) turns SIGTERM into
:class:`Terminated` and SIGINT into :class:`KeyboardInterrupt`, both BaseExceptions that the
commands' ``finally`` and ``except BaseException`` cleanups see; the first stop is raised, later
ones are ignored until the command has returned, so its cleanup runs whole.
:func:`stops_deferred` marks a step that must not be cut in two (renaming a finished output into
place and removing what it replaced, several files replaced together): a stop arriving inside is
raised when it ends. Both work only in the main thread (where Python runs signal handlers); elsewhere,
and where no handler is installed, :func:`stops_deferred` changes nothing.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

#: the signals a long command stops on
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(SystemExit):
    """The process was sent SIGTERM (raised in the main thread by :func:`stops_as_exceptions`).

    A SystemExit whose code is 128 + the signal number, so that a worker process it ends exits
    quietly with the shell's status (no traceback).
    """

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(128 + signum)
        self.signum = signum

    def __str__(self) -> str:
        return f"stopped by {signal.Signals(self.signum).name}"


def exit_status(exc: BaseException) -> int:
    """The shell's exit status for a stop: 128 + the signal number (130 for SIGINT, 143 for SIGTERM)."""
    return 128 + (exc.signum if isinstance(exc, Terminated) else signal.SIGINT)


class _State:
    """What the handler needs: whether a stop was raised, and the nesting of deferred steps."""

    def __init__(self) -> None:
        self.installed = False
        self.stopping = False
        self.deferred = 0
        self.pending: int | None = None


_STATE = _State()


def _stop(signum: int) -> BaseException:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


def _handler(signum: int, _frame: FrameType | None) -> None:
    if _STATE.stopping:
        return  # the cleanup of the first stop is under way: let it finish
    if _STATE.deferred:
        _STATE.pending = signum
        return
    _STATE.stopping = True
    raise _stop(signum)


@contextlib.contextmanager
def stops_as_exceptions() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` and SIGINT :class:`KeyboardInterrupt`, once.

    A signal the process ignores (SIG_IGN) stays ignored. The previous handlers are put back when the block ends. Outside the main thread it changes nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    # a signal ignored on purpose (a command started with ``cmd &`` by a shell ignores SIGINT) stays ignored
    previous = {s: h for s in STOP_SIGNALS if (h := signal.getsignal(s)) is not signal.SIG_IGN}
    was = (_STATE.installed, _STATE.stopping, _STATE.pending)
    _STATE.installed, _STATE.stopping, _STATE.pending = True, False, None
    for s in previous:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _STATE.installed, _STATE.stopping, _STATE.pending = was


@contextlib.contextmanager
def stops_deferred() -> Iterator[None]:
    """A step that a stop must not cut in two: a stop arriving inside is raised when it ends.

    The stop is raised even if the step failed (its error is the stop's context): the user asked
    to stop, and the step's own cleanup has run.
    """
    _STATE.deferred += 1
    try:
        yield
    finally:
        _STATE.deferred -= 1
        if not _STATE.deferred and _STATE.pending is not None and not _STATE.stopping:
            signum, _STATE.pending = _STATE.pending, None
            _STATE.stopping = True
            raise _stop(signum)  # noqa: B012 - the stop outranks the step's own error


def ignore_stops_in_worker() -> None:
    """In a worker process: leave stopping to the parent, which ends its workers itself.

    A worker started with ``spawn`` gets the parent's terminal's Ctrl-C too; ignoring SIGINT leaves
    the parent to decide. SIGTERM is turned into :class:`Terminated`, so the worker's own atomic
    writes clean up their temporary files when the parent ends it.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _STATE.installed, _STATE.stopping, _STATE.pending = True, False, None
    signal.signal(signal.SIGTERM, _handler)


__all__ = ["STOP_SIGNALS", "Terminated", "exit_status", "ignore_stops_in_worker", "stops_as_exceptions",
           "stops_deferred"]
