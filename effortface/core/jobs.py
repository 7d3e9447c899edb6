"""Blocking work (opening ports, probing cameras) run off the GUI thread, drained on a QTimer.

Qt-free on purpose: the GUI calls :meth:`Jobs.submit`, and its timer calls :meth:`Jobs.drain`,
which returns the finished results without ever waiting (STYLE.md L5).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
from collections.abc import Callable
from typing import Any


@dataclasses.dataclass(frozen=True)
class JobResult:
    """A finished job: its ``key``, and its ``value`` or the ``error`` it raised."""

    key: str
    value: Any = None
    error: BaseException | None = None


class Jobs:
    """A small thread pool whose results are collected by polling.

    Parameters
    ----------
    workers : int
        Threads in the pool.
    """

    def __init__(self, workers: int = 2) -> None:
        self._pool = cf.ThreadPoolExecutor(max_workers=workers, thread_name_prefix="gui-job")
        self._pending: list[tuple[str, cf.Future[Any]]] = []

    def submit(self, key: str, fn: Callable[..., Any], *args: Any) -> None:
        """Run ``fn(*args)`` in a worker; its result comes back from :meth:`drain` under ``key``."""
        self._pending.append((key, self._pool.submit(fn, *args)))

    def busy(self, key: str) -> bool:
        """True while a job named ``key`` is running."""
        return any(k == key and not f.done() for k, f in self._pending)

    def idle(self) -> bool:
        """True when no job is waiting to be drained."""
        return not self._pending

    def drain(self) -> list[JobResult]:
        """Return the jobs finished since the last call (never blocks)."""
        done = [(k, f) for k, f in self._pending if f.done()]
        self._pending = [(k, f) for k, f in self._pending if not f.done()]
        return [JobResult(k, None, f.exception()) if f.exception() else JobResult(k, f.result())
                for k, f in done]

    def shutdown(self) -> None:
        """Stop accepting jobs; running ones finish in the background."""
        self._pool.shutdown(wait=False, cancel_futures=True)
