"""effortface.core.events.Emitter: the one change notification of the stage models (Qt-free)."""

from __future__ import annotations

from effortface.core.events import Emitter


def test_emit_calls_every_connected_function_in_order_with_the_arguments() -> None:
    changed, log = Emitter(), []
    changed.connect(lambda *args: log.append(("a", args)))
    changed.connect(lambda *args: log.append(("b", args)))
    changed.emit(3, "text")
    assert log == [("a", (3, "text")), ("b", (3, "text"))]


def test_disconnect_one_or_all() -> None:
    changed, log = Emitter(), []
    first, second = (lambda: log.append(1)), (lambda: log.append(2))
    changed.connect(first)
    changed.connect(second)
    changed.disconnect(first)
    changed.disconnect(first)  # not connected any more: no error
    changed.emit()
    changed.disconnect_all()
    changed.emit()
    assert log == [2]


def test_a_slot_that_disconnects_itself_does_not_skip_the_next() -> None:
    changed, log = Emitter(), []

    def once() -> None:
        log.append("once")
        changed.disconnect(once)

    changed.connect(once)
    changed.connect(lambda: log.append("always"))
    changed.emit()
    changed.emit()
    assert log == ["once", "always", "always"]
