"""Where the training folds and the batch synthesis run: in this process, or on a Dask cluster.

One switch for ``effortface train`` and ``effortface synth`` (``--workers N`` | ``--scheduler ADDRESS``):

- neither: everything runs in this process, one task after the other (the default);
- ``--workers N``: a local Dask cluster of N single-threaded worker processes, listening on the
  loopback interface only (127.0.0.1, no dashboard), closed when the run ends;
- ``--scheduler ADDRESS``: an existing Dask scheduler (``tcp://host:8786``), for labs that outgrow
  one machine; its workers must have the same effortface installed.

The training code calls :func:`map_ordered` (joblib underneath, with joblib's Dask backend when a
cluster is open), so a fold computes the same numbers wherever it runs and the results come back
in submission order: a parallel run gives the model of the serial run. Batch synthesis uses
:func:`map_unordered` (results as they finish, for its progress bar).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import joblib

from effortface.core.errors import UserError

#: Seconds to wait for a local cluster to start or a scheduler to answer.
CONNECT_TIMEOUT_S = 60


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


_CLIENT: list[Any] = []  # the client of the open cluster (at most one), for map_unordered


@contextlib.contextmanager
def compute_backend(settings: ComputeSettings | None) -> Iterator[Any]:
    """Open the Dask cluster of ``settings`` (if any) and route joblib to it for the block.

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
        from dask.distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - dask is a dependency
        raise UserError("--workers/--scheduler: expected dask[distributed] installed, found it missing") \
            from None
    with contextlib.ExitStack() as stack:
        if settings.workers is not None:
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
        stack.enter_context(joblib.parallel_config(backend="dask"))
        _CLIENT.append(client)
        try:
            yield client
        finally:
            _CLIENT.remove(client)


def single_threaded(func: Callable[..., Any], *args: Any) -> Any:
    """``func(*args)`` with the BLAS and OpenMP thread pools at one thread.

    A matrix product sums in an order that depends on its thread count; a task run with one
    thread everywhere (this process or a Dask worker) gives the same bits.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return func(*args)


def map_ordered(func: Callable[..., Any], calls: Iterable[tuple[Any, ...]]) -> Iterator[Any]:
    """``func(*args)`` for every ``args`` of ``calls``, results in the same order, lazily.

    Runs on joblib: in this process, or on the Dask cluster opened by :func:`compute_backend`.
    Every task runs :func:`single_threaded`, so the results do not depend on where it ran.
    """
    tasks = (joblib.delayed(single_threaded)(func, *args) for args in calls)
    return iter(joblib.Parallel(return_as="generator")(tasks))


def map_unordered(func: Callable[..., Any], items: Iterable[Any]) -> Iterator[Any]:
    """``func(item)`` for every item, results as they finish (on the open Dask cluster, if any)."""
    if not _CLIENT:
        yield from (func(item) for item in items)
        return
    from dask.distributed import as_completed

    client = _CLIENT[-1]
    futures = [client.submit(func, item, pure=False) for item in items]
    for future in as_completed(futures):
        yield future.result()
