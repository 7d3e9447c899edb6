"""One filter for Qt's own messages: those that tell a user nothing they can act on are not printed.

Some platform plugins print "This plugin does not support propagateSizeHints()" whenever a window
resizes; a lab user reads it as an error. :func:`install_message_filter` (called where the
application starts) drops the messages of :data:`QUIET` and passes every other message on to the
handler that was installed before (Qt's own, or pytest-qt's in the tests).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore

#: starts of Qt messages that are not printed
QUIET = ("This plugin does not support propagateSizeHints()",)

_previous: Callable[..., Any] | None = None
_installed = False


def is_quiet(message: str) -> bool:
    """True for a Qt message the filter drops."""
    return message.startswith(QUIET)


def _handler(mode: QtCore.QtMsgType, context: QtCore.QMessageLogContext, message: str) -> None:
    if is_quiet(message):
        return
    if _previous is not None:
        _previous(mode, context, message)
    else:  # Qt's default handler: the message on stderr
        print(message, file=sys.stderr)


def install_message_filter() -> None:
    """Install the filter once, in front of the handler installed before it."""
    global _previous, _installed
    if not _installed:
        _previous = QtCore.qInstallMessageHandler(_handler)
        _installed = True
