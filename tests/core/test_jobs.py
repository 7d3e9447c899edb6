"""effortface.core.jobs: the one background-work class of every stage (Qt-free, T1: no Qt here).

Jobs are synchronised with threading.Event, never with sleeps; the only waits are bounded waits for
a job the test has released.
"""

from __future__ import annotations

import threading

import pytest

from effortface.core.jobs import Cancelled, Job, JobResult, Jobs

TIMEOUT_S = 30


@pytest.fixture
def jobs():
    pool = Jobs(workers=1)
    yield pool
    pool.shutdown()


def _drain_all(jobs: Jobs) -> list[JobResult]:
    assert jobs.wait(TIMEOUT_S)
    return jobs.drain()


def test_done_callback_gets_the_value_on_the_draining_thread(jobs) -> None:
    seen: list[tuple[JobResult, threading.Thread]] = []
    jobs.submit("sum", sum, [1, 2, 3], done=lambda r: seen.append((r, threading.current_thread())))
    results = _drain_all(jobs)
    assert results == [JobResult("sum", 6)]
    assert seen == [(JobResult("sum", 6), threading.current_thread())]
    assert jobs.idle() and jobs.drain() == []  # delivered once


def test_each_job_calls_its_own_done_callback(jobs) -> None:
    got: dict[str, object] = {}
    jobs.submit("a", lambda: "A", done=lambda r: got.setdefault("a", r.value))
    jobs.submit("b", lambda: "B", done=lambda r: got.setdefault("b", r.value))
    jobs.submit("c", lambda: "C")  # no callback: only returned by drain
    assert [r.value for r in _drain_all(jobs)] == ["A", "B", "C"]
    assert got == {"a": "A", "b": "B"}


def test_an_error_reaches_the_done_callback_not_the_caller(jobs) -> None:
    results: list[JobResult] = []

    def fail() -> None:
        raise ValueError("bad table")

    jobs.submit("train", fail, done=results.append)
    _drain_all(jobs)
    (result,) = results
    assert isinstance(result.error, ValueError) and str(result.error) == "bad table"
    assert result.value is None and not result.cancelled


def test_progress_is_delivered_in_order_before_done(jobs) -> None:
    log: list[object] = []

    def work(job: Job, n: int) -> int:
        for i in range(n):
            job.report((i + 1) / n, f"step {i + 1}")
        return n

    jobs.submit("fit", work, 3, takes_job=True, progress=lambda f, t: log.append((f, t)),
                done=lambda r: log.append(r.value))
    _drain_all(jobs)
    assert log == [(1 / 3, "step 1"), (2 / 3, "step 2"), (1.0, "step 3"), 3]


def test_progress_of_a_running_job_arrives_before_it_ends(jobs) -> None:
    reported, release = threading.Event(), threading.Event()
    log: list[object] = []

    def work(job: Job) -> str:
        job.report(0.5, "half")
        reported.set()
        assert release.wait(TIMEOUT_S)
        return "end"

    jobs.submit("fit", work, takes_job=True, progress=lambda f, t: log.append(t), done=lambda r: log.append(r.value))
    assert reported.wait(TIMEOUT_S)
    assert jobs.drain() == [] and log == ["half"] and jobs.busy("fit")
    release.set()
    _drain_all(jobs)
    assert log == ["half", "end"] and not jobs.busy()


def test_cancel_stops_a_running_job_at_its_next_check(jobs) -> None:
    started, release = threading.Event(), threading.Event()
    steps: list[int] = []

    def work(job: Job) -> str:
        for i in range(100):
            job.check(f"step {i}")
            steps.append(i)
            started.set()
            assert release.wait(TIMEOUT_S)
        return "finished"

    results: list[JobResult] = []
    jobs.submit("train", work, takes_job=True, done=results.append)
    assert started.wait(TIMEOUT_S)
    assert jobs.cancel("other") == 0 and jobs.cancel("train") == 1
    release.set()
    _drain_all(jobs)
    (result,) = results
    assert result.cancelled and isinstance(result.error, Cancelled) and str(result.error) == "step 1"
    assert steps == [0]


def test_a_job_cancelled_before_it_starts_never_runs(jobs) -> None:
    release = threading.Event()
    ran: list[str] = []
    jobs.submit("first", release.wait, TIMEOUT_S)  # holds the only worker
    jobs.submit("second", lambda: ran.append("second"))
    assert jobs.running() == ["first", "second"]
    assert jobs.cancel("second") == 1
    release.set()
    results = {r.key: r for r in _drain_all(jobs)}
    assert results["first"].value is True
    assert results["second"].cancelled and ran == []


def test_one_worker_runs_jobs_one_at_a_time_in_order(jobs) -> None:
    order: list[int] = []
    for i in range(5):
        jobs.submit("step", order.append, i)
    _drain_all(jobs)
    assert order == [0, 1, 2, 3, 4]


def test_a_raising_callback_does_not_hide_the_others(jobs) -> None:
    delivered: list[str] = []

    def boom(_: JobResult) -> None:
        raise RuntimeError("callback bug")

    jobs.submit("a", lambda: 1, done=boom)
    jobs.submit("b", lambda: 2, done=lambda r: delivered.append(r.key))
    assert jobs.wait(TIMEOUT_S)
    with pytest.raises(RuntimeError, match="callback bug"):
        jobs.drain()
    assert delivered == ["b"] and jobs.idle()


def test_busy_and_idle_follow_the_jobs(jobs) -> None:
    release = threading.Event()
    assert jobs.idle() and not jobs.busy()
    jobs.submit("wait", release.wait, TIMEOUT_S)
    assert jobs.busy() and jobs.busy("wait") and not jobs.busy("other") and not jobs.idle()
    release.set()
    assert jobs.wait(TIMEOUT_S) and not jobs.busy()
    assert not jobs.idle()  # finished but not drained yet
    jobs.drain()
    assert jobs.idle()


def test_shutdown_cancels_and_refuses_new_jobs() -> None:
    pool = Jobs(workers=1)
    started = threading.Event()

    def work(job: Job) -> None:
        started.set()
        while True:
            job.check()
            job._cancel.wait(TIMEOUT_S)

    pool.submit("train", work, takes_job=True)
    assert started.wait(TIMEOUT_S)
    pool.shutdown()
    assert pool.wait(TIMEOUT_S)
    (result,) = pool.drain()
    assert result.cancelled
    with pytest.raises(RuntimeError, match="shut down"):
        pool.submit("late", print)


def test_threads_start_on_demand_up_to_the_pool_size() -> None:
    def ours() -> list[str]:
        return [t.name for t in threading.enumerate() if t.name.startswith("probe-pool-")]

    pool = Jobs(workers=2, name="probe-pool")
    assert ours() == []  # a stage that never runs a job starts no thread
    release = threading.Event()
    for _ in range(5):
        pool.submit("wait", release.wait, TIMEOUT_S)
    assert sorted(ours()) == ["probe-pool-0", "probe-pool-1"]
    assert all(t.daemon for t in threading.enumerate() if t.name.startswith("probe-pool-"))
    release.set()
    assert pool.wait(TIMEOUT_S) and [r.value for r in pool.drain()] == [True] * 5
    pool.shutdown()
