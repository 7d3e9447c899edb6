"""A guard against a reference-count bug of PySide6 6.12.0 on CPython 3.11.

Measured here (PySide6-Essentials 6.12.0, shiboken6 6.12.0, CPython 3.11.7): every call of a Qt
method that returns nothing (``QLabel.setText``, ``QCoreApplication.processEvents``...) drops one
reference to ``None`` that it never took (and some calls do the same with ``True``). CPython 3.12+ makes ``None`` immortal, so nothing happens
there; on 3.11 the count reaches zero and the process dies with "Fatal Python error: none_dealloc".
One arrow-key step of the Annotate stage makes about 32 such calls, so with the ~19 000 references
a session starts with, an annotator would crash after about 600 steps, and playback in seconds.

:func:`guard_none_refcount` detects the bug with a probe and, only if it is there, gives ``None``,
the booleans and the other shared constants a very large reference count (2**40), which the leak
cannot exhaust in any realistic run. It is a
no-op on CPython 3.12+ and on a fixed PySide6.
"""

from __future__ import annotations

import sys

from PySide6 import QtCore

_BALLAST = 1 << 40
#: objects CPython 3.11 shares and never frees, whose references Qt returns: None and the booleans
#: leak measurably (about 32 and 2 per arrow step), small ints rarely; all get the ballast
_SINGLETONS = (None, True, False, (), "", b"", Ellipsis, NotImplemented, *range(-5, 257))
_applied = False


def pyside_leaks_none(calls: int = 64) -> bool:
    """Whether ``calls`` void Qt calls lower the reference count of None (the bug is present)."""
    if sys.version_info >= (3, 12):
        return False  # None is immortal: its count is not tracked
    probe = QtCore.QObject()
    before = sys.getrefcount(None)
    for _ in range(calls):
        probe.setObjectName("probe")
    return sys.getrefcount(None) < before - calls // 2


def guard_none_refcount() -> bool:
    """Protect the process from the leak if this PySide6 has it; return whether the guard is on.

    Idempotent. Call it once after importing PySide6 (the Annotate stage does in its constructor).
    """
    global _applied
    if _applied:
        return True
    if not pyside_leaks_none():
        return False
    import ctypes

    for obj in _SINGLETONS:
        refcount = ctypes.c_ssize_t.from_address(id(obj))  # ob_refcnt is the first field of every object
        refcount.value += _BALLAST
    _applied = True
    return True
