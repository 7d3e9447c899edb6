"""Training on a local Dask cluster (effortface/synth/parallel.py): the training data goes to the workers once,
a task carries only fold indices and hyper-parameters, the results are the serial run's, abandoned
tasks are cancelled, the workers start warm and keep their freed memory, and the data arrives
aligned. A real two-worker cluster in this process; the Client's own ``scatter`` and ``submit`` are
observed (wrapped, still called), nothing is stubbed."""

from __future__ import annotations

import multiprocessing
import os
import pickle
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from distributed import Client, Event, Future

from effortface.core.blendshapes import DEFAULT_SET
from effortface.train.dataset import prepare, synthetic_table
from effortface.train.face_fit import (PROTOCOLS, FaceData, FaceFitConfig, _protocol_folds, cv_folds, face_data,
                                       fit_face_models, held_out_scores, nested_choices, protocol_scores)
from effortface.synth.parallel import (FORKSERVER_PRELOAD, TASKS_PER_THREAD, ComputeSettings, compute_backend,
                                       _chunks, map_ordered, single_threaded)

#: a task may carry its fold's row indices, never the training data: at most this share of its bytes
#: (a fold's indices are one int64 per training row, the data about 13 float64 values per row, its
#: text columns shared strings)
MAX_TASK_SHARE_OF_DATA = 0.1


class Recorder:
    """The Client's scatter and submit calls: what was scattered, each task's pickled size."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.scattered: list[tuple[Any, dict[str, Any]]] = []
        self.task_bytes: list[int] = []
        self.futures: list[Future] = []
        real_scatter, real_submit = Client.scatter, Client.submit

        def scatter(client: Client, data: Any, *args: Any, **kwargs: Any) -> Any:
            self.scattered.append((data, kwargs))
            return real_scatter(client, data, *args, **kwargs)

        def submit(client: Client, func: Any, *args: Any, **kwargs: Any) -> Future:
            plain = [None if isinstance(a, Future) else a for a in args]  # a future is a key
            self.task_bytes.append(len(pickle.dumps((func, plain, kwargs), protocol=5)))
            future = real_submit(client, func, *args, **kwargs)
            self.futures.append(future)
            return future

        monkeypatch.setattr(Client, "scatter", scatter)
        monkeypatch.setattr(Client, "submit", submit)


@pytest.fixture(scope="module")
def table():
    """3,200 face rows (4 participants x 2 exercises): the approximation."""
    return prepare(synthetic_table(n_participants=4, seconds=400, seed=3))


def _train(table) -> tuple[Any, Any, Any]:
    fit = fit_face_models(table, DEFAULT_SET.names, FaceFitConfig())
    return fit, held_out_scores(fit), protocol_scores(fit)


@pytest.fixture(scope="module")
def serial(table) -> tuple[Any, Any, Any]:
    """The face part of a training run in this process (before the cluster opens), and the nested
    search's choices."""
    fit, held, protos = _train(table)
    return fit, held, protos, nested_choices(fit.data, fit.config, cv_folds(fit.data, "lopo"))


@pytest.fixture(scope="module")
def cluster(serial) -> Iterator[Client]:
    with compute_backend(ComputeSettings(workers=2)) as client:
        yield client


def test_the_training_data_is_sent_to_the_workers_once(table, serial, cluster, monkeypatch):
    serial_fit, serial_held, (serial_protos, serial_preds), _ = serial
    calls = Recorder(monkeypatch)
    fit, held, (protos, preds) = _train(table)
    # one scatter of the training data to every worker, and one of the search's fold numbers
    assert len(calls.scattered) == 2
    data, kwargs = calls.scattered[0]
    assert isinstance(data, FaceData) and data is fit.data and kwargs.get("broadcast") is True
    fold_of = calls.scattered[1][0]
    assert fold_of.dtype == np.int16 and len(fold_of) == len(data.x)
    # the folds, final fits and protocol folds in a few tasks per worker, each carrying indices, not the data
    n_calls = [len(cv_folds(data, max_folds=fit.config.max_folds)), len(DEFAULT_SET.names)]
    # (the unseen-participant protocol of an approximate fit reads the search's own fold fits: no task)
    assert fit.method == "nystroem"
    n_calls += [len(_protocol_folds(data, p, max_folds=fit.config.max_folds)) for p in PROTOCOLS
                if p != "unseen_participant"]
    assert n_calls == [4, 4, 40, 2]
    assert len(calls.task_bytes) == sum(min(n, TASKS_PER_THREAD * 2) for n in n_calls)
    data_bytes = len(pickle.dumps(data, protocol=5))
    assert max(calls.task_bytes) < MAX_TASK_SHARE_OF_DATA * data_bytes, (max(calls.task_bytes), data_bytes)
    # the serial run's numbers
    for name in fit.blendshapes:
        np.testing.assert_array_equal(fit.svrs[name].dual_coef_, serial_fit.svrs[name].dual_coef_)
        np.testing.assert_array_equal(fit.svrs[name].support_vectors_, serial_fit.svrs[name].support_vectors_)
        np.testing.assert_array_equal(fit.search[name].oof, serial_fit.search[name].oof)
    assert held.equals(serial_held) and protos.equals(serial_protos)
    for protocol in PROTOCOLS:
        np.testing.assert_array_equal(preds[protocol], serial_preds[protocol])


def test_the_nested_search_sends_the_folds_once_and_matches_the_serial_one(table, serial, cluster, monkeypatch):
    """The nested search's tasks carry two fold numbers (the rows' folds are shipped with the data),
    and its choices on the workers are the serial ones."""
    fit, expected = serial[0], serial[3]
    calls = Recorder(monkeypatch)
    assert nested_choices(fit.data, fit.config, cv_folds(fit.data, "lopo")) == expected
    assert len(calls.futures) > 0 and max(calls.task_bytes) < 2_000  # no row indices in a task
    fold_of = [d for d, _ in calls.scattered if isinstance(d, np.ndarray)]
    assert len(fold_of) == 1 and len(fold_of[0]) == len(fit.data.x)


def _worker_settings() -> dict[str, Any]:
    import dask

    cmdline = Path(f"/proc/{os.getppid()}/cmdline")
    parent = cmdline.read_bytes().replace(b"\0", b" ").decode() if cmdline.exists() else None
    return {"trim": os.environ.get("MALLOC_TRIM_THRESHOLD_"), "mmap": os.environ.get("MALLOC_MMAP_THRESHOLD_"),
            "profile": dask.config.get("distributed.worker.profile.enabled"), "parent": parent}


def test_local_workers_start_warm_keep_freed_memory_and_run_single_threaded(cluster):
    """Dask's MALLOC_TRIM_THRESHOLD_=65536 made every fold's temporaries fresh pages (+40 % CPU);
    spawned workers each imported Dask, numpy, pandas and scikit-learn (4 s of CPU for two)."""
    for settings in cluster.run(_worker_settings).values():
        assert settings["trim"] == str(64 * 2**20) and settings["mmap"] == str(32 * 2**20)
        assert settings["profile"] is False
        if "forkserver" in multiprocessing.get_all_start_methods() and settings["parent"] is not None:
            assert "multiprocessing.forkserver" in settings["parent"], settings["parent"]
            assert all(m in settings["parent"] for m in FORKSERVER_PRELOAD), settings["parent"]
    inside = list(map_ordered(_thread_counts, [()]))[0]
    assert inside == {1}


def _thread_counts() -> set[int]:
    from threadpoolctl import threadpool_info

    return {p["num_threads"] for p in threadpool_info()}


def test_a_task_in_this_process_runs_single_threaded():
    assert single_threaded(_thread_counts) == {1}


def _first_or_wait(k: int, event_name: str) -> int:
    if k:
        Event(event_name).wait(timeout=120)
    return k


def test_abandoned_tasks_are_cancelled(cluster, monkeypatch):
    calls = Recorder(monkeypatch)
    hold = Event("hold-the-rest", client=cluster)
    results = map_ordered(_first_or_wait, [(k, "hold-the-rest") for k in range(5)])
    try:
        assert next(results) == 0
        results.close()  # the reader stops (a cancelled training)
        assert [f.status for f in calls.futures[1:]] == ["cancelled"] * 4
    finally:
        hold.set()


def _unaligned_copy(a: np.ndarray) -> np.ndarray:
    raw = bytearray(a.nbytes + 1)
    out = np.frombuffer(raw, dtype=a.dtype, offset=1, count=a.size).reshape(a.shape)
    out[...] = a
    return out


def _alignment(data: FaceData) -> dict[str, bool]:
    return {k: v.flags.aligned for k, v in vars(data).items() if isinstance(v, np.ndarray)}


def test_face_data_is_aligned_when_unpickled(table, cluster):
    """A worker received ``x`` at an odd byte offset (slower loops; a sum may group differently)."""
    data = face_data(table.dropna(subset=["nhr"]).head(50), DEFAULT_SET.names)
    data.x = _unaligned_copy(data.x)
    assert not data.x.flags.aligned
    buffers: list[Any] = []
    back = pickle.loads(pickle.dumps(data, protocol=5, buffer_callback=buffers.append), buffers=buffers)
    assert all(_alignment(back).values()) and np.array_equal(back.x, data.x)
    on_worker = list(map_ordered(_alignment, [()], shared=(face_data(table, DEFAULT_SET.names),)))[0]
    assert all(on_worker.values()), on_worker


def test_calls_are_cut_into_a_few_even_chunks_in_order():
    for n_calls in (0, 1, 7, 8, 9, 300):
        chunks = _chunks(list(range(n_calls)), 8)
        assert [c for chunk in chunks for c in chunk] == list(range(n_calls))
        assert len(chunks) == min(n_calls, 8) and all(chunks)
        assert not chunks or max(map(len, chunks)) - min(map(len, chunks)) <= 1
