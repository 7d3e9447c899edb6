"""pyserial URL handlers of effortface (``replay://``, ``ble://``), found through ``serial.protocol_handler_packages``."""

from __future__ import annotations

import serial

PACKAGE = "effortface.capture_tool.urlhandler"


def register() -> None:
    """Make ``serial.serial_for_url("replay://...")`` find :mod:`.protocol_replay` (idempotent)."""
    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)
