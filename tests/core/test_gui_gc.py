"""Garbage is collected by a GUI-thread timer while a window is up, never by a worker thread."""

import gc
import threading

from effortface.core.gui.gui_gc import collect_in_gui_thread


class _Cycle:
    collected_in: list[str] = []

    def __init__(self) -> None:
        self.me = self

    def __del__(self) -> None:
        _Cycle.collected_in.append(threading.current_thread().name)


def test_cycles_made_by_a_worker_are_freed_in_the_gui_thread(qtbot) -> None:
    assert not gc.isenabled()  # the autouse fixture (as the application) already switched it off
    with collect_in_gui_thread(interval_s=0.05):
        _Cycle.collected_in.clear()

        def churn() -> None:
            for _ in range(5000):
                _Cycle()

        worker = threading.Thread(target=churn, name="worker")
        worker.start()
        worker.join(30)
        assert _Cycle.collected_in == []  # the worker made plenty of garbage and collected none
        qtbot.waitUntil(lambda: len(_Cycle.collected_in) > 0, timeout=10_000)
    assert set(_Cycle.collected_in) == {threading.main_thread().name}
    assert not gc.isenabled()  # restored to what the outer block had


def test_automatic_collection_is_restored_after_the_block(qapp) -> None:
    assert gc.isenabled()
    with collect_in_gui_thread():
        assert not gc.isenabled()
    assert gc.isenabled()
