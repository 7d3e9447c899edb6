"""Where the training folds and the batch synthesis run: in this process, or on a Dask cluster.

One switch for ``effortface train`` and ``effortface synth`` (``--workers N`` | ``--scheduler ADDRESS``):

- neither: everything runs in this process, one task after the other (the default);
- ``--workers N``: a local Dask cluster of N single-threaded worker processes, listening on the
  loopback interface only (127.0.0.1, no dashboard), closed when the run ends;
- ``--scheduler ADDRESS``: an existing Dask scheduler (``tcp://host:8786``), for labs that outgrow
  one machine; its workers must have the same effortface installed.

The training code calls :func:`map_ordered`: in this process, or as Dask tasks when a cluster is
open. The training data every fold reads (``shared``) goes to the workers once per cluster
(``client.scatter(..., broadcast=True)``, kept until the cluster closes); the folds go in a few
chunks per worker (:data:`TASKS_PER_THREAD`), each carrying only row indices and hyper-parameters.
A fold computes the same numbers wherever it runs (single-threaded BLAS and OpenMP) and the results
come back in submission order: a parallel run gives the model of the serial run. Batch synthesis
uses :func:`map_unordered` (results as they finish, for its progress bar). The local cluster's
workers are set up for this work (:data:`LOCAL_WORKER_CONFIG`, :data:`FORKSERVER_PRELOAD`).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import multiprocessing
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from threadpoolctl import ThreadpoolController

from effortface.core.errors import UserError

#: Seconds to wait for a local cluster to start or a scheduler to answer.
CONNECT_TIMEOUT_S = 60
#: Dask settings of the local cluster's worker processes (``--workers``). Dask starts its workers
#: with ``MALLOC_TRIM_THRESHOLD_=65536``, which also pins glibc's mmap threshold at 128 KiB: every
#: temporary array of a fold is then fresh pages from the kernel (measured: 7,400 page faults and
#: +40 % CPU per protocol fold against the same fold in this process). These keep arrays under
#: 32 MiB on the heap and up to 64 MiB of freed memory for reuse (where glibc's own dynamic
#: threshold ends up in a long run); the profiler samples for a dashboard the cluster does not have.
#: The workers of a ``--scheduler`` cluster keep their own settings (the same keys in their Dask
#: configuration give them the same speed).
LOCAL_WORKER_CONFIG: dict[str, object] = {
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": 64 * 2**20,
    "distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": 32 * 2**20,
    "distributed.worker.profile.enabled": False,
}
#: Where the platform has it (Linux, macOS), the local workers are forked from one fork server that
#: imported these modules (the tasks' own) once, with the environment above, instead of each
#: spawned worker importing Dask, then numpy, pandas and scikit-learn at its first task (measured,
#: 2 workers, from opening the cluster to the first results: 5.8 s spawned, 1.7 s forked). The fork
#: server lives as long as this process: the next cluster starts in 0.3 s.
FORKSERVER_PRELOAD = ("distributed", "effortface.train.face_fit", "effortface.synth.batch_synth")
#: One :func:`map_ordered` call gives a cluster at most this many tasks per worker thread (its
#: calls grouped into consecutive chunks): each task costs this process about 5 ms of scheduling,
#: which 300 protocol folds of 35 ms each would feel; a few chunks per thread still balance the load.
TASKS_PER_THREAD = 4


@dataclasses.dataclass(frozen=True)
class ComputeSettings:
    """Where tasks run (see the module docstring).

    Parameters
    ----------
    workers : int or None
        Worker processes of a local Dask cluster (None: run in this process).
    scheduler : str or None
        Address of an existing Dask scheduler (exclusive with ``workers``).
    """

    workers: int | None = None
    scheduler: str | None = None

    def __post_init__(self) -> None:
        if self.workers is not None and self.scheduler is not None:
            raise UserError("--workers/--scheduler: expected one of the two, found both")
        if self.workers is not None and self.workers < 1:
            raise UserError(f"--workers: expected a number of worker processes >= 1, found {self.workers}")
        if self.scheduler is not None and not self.scheduler.strip():
            raise UserError("--scheduler: expected an address such as tcp://host:8786, found nothing")

    @property
    def distributed(self) -> bool:
        """True when tasks go to a Dask cluster."""
        return self.workers is not None or self.scheduler is not None


def add_compute_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """The ``--workers N`` and ``--scheduler ADDRESS`` options (one of the two) of a command."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--workers", type=int, default=None, metavar="N",
                       help=f"run {what} on a local Dask cluster of N worker processes (loopback only)")
    group.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help=f"run {what} on the Dask scheduler at ADDRESS (e.g. tcp://host:8786)")


@dataclasses.dataclass
class _Cluster:
    """The open cluster: its client, and the objects already on every worker.

    ``shipped`` maps ``id(obj)`` to ``(obj, future)``; holding ``obj`` keeps its id from being reused
    while the cluster is open.
    """

    client: Any
    shipped: dict[int, tuple[Any, Any]] = dataclasses.field(default_factory=dict)

    def n_threads(self) -> int:
        """Worker threads of the cluster now (at least 1)."""
        return max(1, sum(self.client.nthreads().values()))

    def ship(self, obj: Any) -> Any:
        """A Dask future of ``obj`` held by every worker; ``obj`` is sent once while the cluster is open."""
        entry = self.shipped.get(id(obj))
        if entry is None:
            future = self.client.scatter(obj, broadcast=True, hash=False)
            entry = self.shipped[id(obj)] = (obj, future)
        return entry[1]


_OPEN: list[_Cluster] = []  # the open cluster (at most one), for map_ordered and map_unordered


@contextlib.contextmanager
def compute_backend(settings: ComputeSettings | None) -> Iterator[Any]:
    """Open the Dask cluster of ``settings`` (if any); :func:`map_ordered` and :func:`map_unordered`
    send their tasks to it for the block.

    Yields the Dask client, or None when everything runs in this process.

    Raises
    ------
    UserError
        Dask not installed, or a scheduler that cannot be reached (named).
    """
    if settings is None or not settings.distributed:
        yield None
        return
    try:
        import dask
        from dask.distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - dask is a dependency
        raise UserError("--workers/--scheduler: expected dask[distributed] installed, found it missing") \
            from None
    with contextlib.ExitStack() as stack:
        if settings.workers is not None:
            stack.enter_context(dask.config.set(LOCAL_WORKER_CONFIG))
            _use_forkserver(stack)
            cluster = stack.enter_context(LocalCluster(
                n_workers=settings.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None, silence_logs=50))
            client = stack.enter_context(Client(cluster, timeout=CONNECT_TIMEOUT_S))
        else:
            try:
                client = stack.enter_context(Client(settings.scheduler, timeout=CONNECT_TIMEOUT_S))
            except (OSError, TimeoutError) as exc:
                raise UserError(f"--scheduler {settings.scheduler}: expected a reachable Dask scheduler, "
                                f"found {exc}") from None
        opened = _Cluster(client)
        _OPEN.append(opened)
        try:
            yield client
        finally:
            _OPEN.remove(opened)
            opened.shipped.clear()  # releases the shipped data on the workers


def _use_forkserver(stack: contextlib.ExitStack) -> None:
    """Start the local workers from the fork server (:data:`FORKSERVER_PRELOAD`) where there is one."""
    import dask
    from distributed.utils import get_mp_context

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return  # Windows: spawned workers
    stack.enter_context(dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}))
    context = get_mp_context()  # Dask sets its own preload list at its first call: replace it
    context.set_forkserver_preload(list(FORKSERVER_PRELOAD))  # no effect once the server runs


def _thread_pools() -> ThreadpoolController:
    """This process's BLAS and OpenMP thread pools (a ``threadpoolctl.ThreadpoolController``), found
    afresh at every call (about 0.2 ms): a library loaded since the last call (OpenCV brings an
    OpenBLAS of its own) is limited too, so no task runs with a pool it did not see."""
    return ThreadpoolController()


def single_threaded(func: Callable[..., Any], *args: Any) -> Any:
    """``func(*args)`` with the BLAS and OpenMP thread pools at one thread.

    A matrix product sums in an order that depends on its thread count; a task run with one
    thread everywhere (this process or a Dask worker) gives the same bits.
    """
    with _thread_pools().limit(limits=1):
        return func(*args)


def map_ordered(func: Callable[..., Any], calls: Iterable[tuple[Any, ...]],
                shared: tuple[Any, ...] = ()) -> Iterator[Any]:
    """``func(*shared, *args)`` for every ``args`` of ``calls``, results in the same order, lazily.

    In this process, or on the Dask cluster opened by :func:`compute_backend`: all submitted at
    once, in at most :data:`TASKS_PER_THREAD` tasks per worker thread. Every call runs
    :func:`single_threaded`, so the results do not depend on where it ran.

    Parameters
    ----------
    func : callable
        A module-level function (pickled by reference onto the workers).
    calls : iterable of tuple
        Each task's own arguments: keep them small (row indices, hyper-parameters).
    shared : tuple
        Arguments every task takes first (the training data): on a cluster they are sent to every
        worker once while it is open (:meth:`_Cluster.ship`), and the tasks carry only a reference.

    Returns
    -------
    iterator
        The results, in the order of ``calls``.
    """
    if not _OPEN:
        return (single_threaded(func, *shared, *args) for args in calls)
    cluster, calls = _OPEN[-1], list(calls)
    shipped = tuple(cluster.ship(obj) for obj in shared)
    futures = [cluster.client.submit(_run_chunk, func, shipped, chunk, pure=False)
               for chunk in _chunks(calls, TASKS_PER_THREAD * cluster.n_threads())]
    return _results_in_order(cluster.client, futures)


def _chunks(calls: list[Any], n_max: int) -> list[list[Any]]:
    """``calls`` cut into at most ``n_max`` consecutive chunks of nearly equal length."""
    n = max(1, min(len(calls), n_max))
    bounds = [round(k * len(calls) / n) for k in range(n + 1)]
    return [calls[a:b] for a, b in zip(bounds, bounds[1:]) if b > a]


def _run_chunk(func: Callable[..., Any], shared: tuple[Any, ...], chunk: list[tuple[Any, ...]]) -> list[Any]:
    """``func(*shared, *args)`` for every ``args`` of ``chunk``, each single-threaded (one Dask task)."""
    return [single_threaded(func, *shared, *args) for args in chunk]


def _results_in_order(client: Any, futures: list[Any]) -> Iterator[Any]:
    """The chunks' results in order, each chunk released once read; the rest cancelled if abandoned."""
    try:
        for k, future in enumerate(futures):
            yield from future.result()
            futures[k] = None
    finally:
        pending = [f for f in futures if f is not None]
        if pending:
            client.cancel(pending)


def map_unordered(func: Callable[..., Any], items: Iterable[Any]) -> Iterator[Any]:
    """``func(item)`` for every item, results as they finish (on the open Dask cluster, if any)."""
    if not _OPEN:
        yield from (func(item) for item in items)
        return
    from dask.distributed import as_completed

    client = _OPEN[-1].client
    futures = [client.submit(func, item, pure=False) for item in items]
    for future in as_completed(futures):
        yield future.result()
