"""``ble://ADDRESS`` or ``ble://NAME``: a Bluetooth Low Energy heart-rate strap as a pyserial port
(:class:`effortface.capture_tool.ble_link.BlePort`; pyserial finds ``Serial`` here)."""

from __future__ import annotations

from effortface.capture_tool.ble_link import BlePort as Serial

__all__ = ["Serial"]
