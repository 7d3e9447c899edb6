"""Change notification for the stage models: one Qt-free signal type (napari's model/view split).

A stage model (``CaptureSession``, ``AnnotateSession``, ``TrainSession``, ``SynthSession``; the
convention is in :mod:`effortface.core`) owns one :class:`Emitter` per thing that changes, named
``<thing>_changed``; its Qt view connects to them in ``__init__`` and writes back only through model
methods (the rule: a view writes back only through model methods and keeps widget state only).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


class Emitter:
    """A Qt-free signal: ``connect(fn)`` then ``emit(*args)`` calls every connected function."""

    def __init__(self) -> None:
        self._slots: list[Callable[..., Any]] = []

    def connect(self, fn: Callable[..., Any]) -> None:
        """Call ``fn(*args)`` on every :meth:`emit`."""
        self._slots.append(fn)

    def disconnect(self, fn: Callable[..., Any]) -> None:
        """Stop calling ``fn`` (no error if it was not connected)."""
        if fn in self._slots:
            self._slots.remove(fn)

    def disconnect_all(self) -> None:
        """Stop calling every connected function (a view that goes away)."""
        self._slots.clear()

    def emit(self, *args: Any) -> None:
        """Call the connected functions in order."""
        for fn in list(self._slots):
            fn(*args)
