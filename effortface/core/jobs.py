"""Background work for every stage: run blocking work off the GUI thread, deliver it on a QTimer.

Qt-free on purpose (the rule: worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget): a stage model (or a view with no model, such as the device
pre-flight) calls :meth:`Jobs.submit` with an explicit ``done`` callback (and ``progress`` callback
when the work reports), and the stage's QTimer calls :meth:`Jobs.drain`, which calls them on the GUI
thread without ever waiting. A job that reports progress or can be cancelled takes its :class:`Job`
as first argument (``takes_job=True``): it calls :meth:`Job.report` and :meth:`Job.check` between
steps, and :meth:`Jobs.cancel` makes the next :meth:`Job.check` raise :class:`Cancelled`.

The worker threads are daemons, so closing the application never waits for a long job.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import queue
import threading
from collections.abc import Callable
from typing import Any

DoneFn = Callable[["JobResult"], Any]
ProgressFn = Callable[[float, str], Any]


class Cancelled(Exception):
    """The user cancelled a running job (raised in the job by :meth:`Job.check`)."""


@dataclasses.dataclass(frozen=True)
class JobResult:
    """A finished job: its ``key``, and its ``value`` or the ``error`` it raised."""

    key: str
    value: Any = None
    error: BaseException | None = None

    @property
    def cancelled(self) -> bool:
        """True when the job stopped because it was cancelled."""
        return isinstance(self.error, (Cancelled, cf.CancelledError))


class Job:
    """One submitted job, as its function and its submitter see it.

    Parameters
    ----------
    key : str
        What the job is (``"train"``, ``"start"``...): :meth:`Jobs.busy` and :meth:`Jobs.cancel`
        find it by this name.
    done : callable, optional
        ``done(result)`` on the GUI thread when the job ends (value, error or cancelled).
    progress : callable, optional
        ``progress(fraction, text)`` on the GUI thread for each :meth:`report`.
    """

    def __init__(self, key: str, done: DoneFn | None = None, progress: ProgressFn | None = None) -> None:
        self.key = key
        self.done = done
        self.progress = progress
        self.future: cf.Future[Any] = cf.Future()
        self._cancel = threading.Event()
        self._reports: queue.SimpleQueue[tuple[float, str]] = queue.SimpleQueue()

    @property
    def cancel_requested(self) -> bool:
        """True once :meth:`cancel` was called."""
        return self._cancel.is_set()

    def cancel(self) -> None:
        """Ask the job to stop at its next :meth:`check` (a job not started yet never runs)."""
        self._cancel.set()
        self.future.cancel()

    def check(self, text: str = "") -> None:
        """Raise :class:`Cancelled` (with ``text``) if a cancel was requested (call between steps)."""
        if self._cancel.is_set():
            raise Cancelled(text or f"{self.key} cancelled")

    def report(self, fraction: float, text: str) -> None:
        """Queue a progress report (from the job's thread); :meth:`Jobs.drain` delivers it."""
        self._reports.put((float(fraction), text))

    def take_reports(self) -> list[tuple[float, str]]:
        """The reports queued since the last call (never blocks)."""
        out = []
        while not self._reports.empty():
            out.append(self._reports.get_nowait())
        return out

    def result(self) -> JobResult:
        """The finished job's result (call only when ``future.done()``)."""
        if self.future.cancelled():
            return JobResult(self.key, None, Cancelled(f"{self.key} cancelled before it started"))
        error = self.future.exception()
        return JobResult(self.key, None, error) if error is not None else JobResult(self.key, self.future.result())


class Jobs:
    """A small pool of daemon threads whose results are delivered by polling.

    Parameters
    ----------
    workers : int
        Threads in the pool (1: jobs run one at a time, in the order submitted).
    name : str
        Prefix of the threads' names.
    """

    def __init__(self, workers: int = 2, name: str = "job") -> None:
        self._tasks: queue.SimpleQueue[tuple[Job, Callable[[], Any]] | None] = queue.SimpleQueue()
        self._pending: list[Job] = []
        self._workers, self._name = max(1, int(workers)), name
        self._threads: list[threading.Thread] = []  # started on demand, up to ``workers``
        self._closed = False

    def submit(self, key: str, fn: Callable[..., Any], *args: Any, done: DoneFn | None = None,
               progress: ProgressFn | None = None, takes_job: bool = False) -> Job:
        """Run ``fn(*args)`` in a worker (``fn(job, *args)`` with ``takes_job``).

        Parameters
        ----------
        key : str
            The job's name.
        fn : callable
            The blocking work.
        *args
            Its arguments.
        done, progress : callable, optional
            Called by :meth:`drain` on the caller's thread (see :class:`Job`).
        takes_job : bool
            Pass the :class:`Job` to ``fn`` first, so that it can report progress and check for cancel.

        Returns
        -------
        Job

        Raises
        ------
        RuntimeError
            After :meth:`shutdown`.
        """
        if self._closed:
            raise RuntimeError(f"{key}: the background jobs were shut down")
        job = Job(key, done, progress)
        call = (lambda: fn(job, *args)) if takes_job else (lambda: fn(*args))
        self._pending.append(job)
        self._tasks.put((job, call))
        if len(self._threads) < min(self._workers, len(self.running())):
            thread = threading.Thread(target=self._work, name=f"{self._name}-{len(self._threads)}", daemon=True)
            self._threads.append(thread)
            thread.start()
        return job

    def _work(self) -> None:
        """A worker thread: run tasks until :meth:`shutdown` (a None task)."""
        while (task := self._tasks.get()) is not None:
            job, call = task
            if not job.future.set_running_or_notify_cancel():
                continue
            try:
                job.future.set_result(call())
            except BaseException as exc:  # delivered to the done callback on the GUI thread
                job.future.set_exception(exc)

    def busy(self, key: str | None = None) -> bool:
        """True while a job named ``key`` (any job when None) is waiting or running."""
        return any(not j.future.done() for j in self._pending if key in (None, j.key))

    def running(self) -> list[str]:
        """Keys of the jobs not finished yet, in the order submitted."""
        return [j.key for j in self._pending if not j.future.done()]

    def idle(self) -> bool:
        """True when no job is waiting to be drained."""
        return not self._pending

    def cancel(self, key: str | None = None) -> int:
        """Ask the jobs named ``key`` (every job when None) to stop; return how many were asked."""
        jobs = [j for j in self._pending if key in (None, j.key) and not j.future.done()]
        for job in jobs:
            job.cancel()
        return len(jobs)

    def drain(self) -> list[JobResult]:
        """Deliver progress reports, then the results of the jobs finished since the last call.

        Never blocks. Each job's ``progress`` callback gets its reports in order, and its ``done``
        callback its :class:`JobResult`, on the calling thread; the results are also returned.
        If a callback raises, the other callbacks still run and the first exception is re-raised
        at the end (so an unexpected error reaches ``sys.excepthook``; none is delivered twice).
        """
        finished = [j for j in self._pending if j.future.done()]
        self._pending = [j for j in self._pending if not j.future.done()]
        calls: list[tuple[Callable[..., Any], tuple[Any, ...]]] = []
        for job in [*finished, *self._pending]:
            calls += [(job.progress, r) for r in job.take_reports() if job.progress is not None]
        results = [job.result() for job in finished]
        calls += [(job.done, (r,)) for job, r in zip(finished, results) if job.done is not None]
        errors = []
        for fn, args in calls:
            try:
                fn(*args)
            except BaseException as exc:  # noqa: PERF203 - every callback runs once
                errors.append(exc)
        if errors:
            raise errors[0]
        return results

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until every job has finished (tests and scripts, never the GUI); True if they did."""
        _, not_done = cf.wait([j.future for j in self._pending], timeout=timeout_s)
        return not not_done

    def shutdown(self) -> None:
        """Cancel every job and stop the threads (a running job ends at its next check, or is dropped)."""
        self._closed = True
        self.cancel()
        for _ in self._threads:
            self._tasks.put(None)
