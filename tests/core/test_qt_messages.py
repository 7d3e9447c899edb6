"""Qt's propagateSizeHints() noise is filtered; every other Qt message still reaches the handler before."""

from __future__ import annotations

from PySide6 import QtCore

from effortface.core.gui import qt_messages


def test_the_filter_drops_only_the_quiet_messages() -> None:
    assert qt_messages.is_quiet("This plugin does not support propagateSizeHints()")
    assert not qt_messages.is_quiet("QWidget::repaint: Recursive repaint detected")


def test_other_messages_reach_the_previous_handler(monkeypatch) -> None:
    seen: list[str] = []
    before = QtCore.qInstallMessageHandler(lambda mode, context, message: seen.append(message))
    monkeypatch.setattr(qt_messages, "_installed", False)
    try:
        qt_messages.install_message_filter()
        QtCore.qWarning("This plugin does not support propagateSizeHints()")
        QtCore.qWarning("a message the user must read")
    finally:
        QtCore.qInstallMessageHandler(before)
    assert seen == ["a message the user must read"]
