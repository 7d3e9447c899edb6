"""Garbage collection in the GUI thread only.

A worker thread (training, report plotting, decoding) that triggers Python's cyclic garbage
collector may free Qt wrappers from the wrong thread, which can deadlock or crash PySide. While a
window is up, automatic collection is switched off and pyqtgraph's collector runs it from a timer in
the GUI thread instead.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

from pyqtgraph.util.garbage_collector import GarbageCollector


@contextlib.contextmanager
def collect_in_gui_thread(interval_s: float = 1.0) -> Iterator[GarbageCollector]:
    """Collect garbage from a GUI-thread timer for the duration of the block.

    Call from the GUI thread once a ``QApplication`` exists. On exit the timer stops, one full
    collection runs here, and automatic collection is restored as it was.

    Parameters
    ----------
    interval_s : float
        Seconds between collection checks.
    """
    was_enabled = gc.isenabled()
    collector = GarbageCollector(interval=interval_s)
    try:
        yield collector
    finally:
        collector.timer.stop()
        gc.collect()
        if was_enabled:
            gc.enable()
