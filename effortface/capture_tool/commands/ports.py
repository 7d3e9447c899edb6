"""``effortface ports``: the serial ports, Bluetooth Low Energy heart-rate straps in range and cameras
this machine has, as tables with column headers (no Bluetooth adapter: one line saying so)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from effortface.capture_tool.camera import list_cameras
from effortface.capture_tool.serial_link import list_ports

PORT_COLUMNS = ("DEVICE", "DESCRIPTION", "HARDWARE ID")
CAMERA_COLUMNS = ("DEVICE", "OPTION")
BLE_COLUMNS = ("NAME", "ADDRESS", "RSSI", "OPTION")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """How long to scan for BLE straps."""
    parser.add_argument("--ble-scan", type=float, default=5.0, metavar="S",
                        help="seconds to scan for Bluetooth LE heart-rate straps (0: do not scan)")


def ble_lines(scan_s: float) -> list[str]:
    """The BLE heart-rate straps in range as a table, or one line saying why there are none."""
    from effortface.capture_tool.ble_link import BleUnavailable, scan_heart_rate_devices

    if not scan_s > 0:
        return ["Bluetooth LE heart-rate straps: not scanned (--ble-scan 0)"]
    try:
        devices = scan_heart_rate_devices(scan_s)
    except BleUnavailable as exc:
        return [f"Bluetooth LE heart-rate straps: none listed: {exc}"]
    rows = [(d["name"] or "?", d["address"], f"{d['rssi']} dBm" if d["rssi"] is not None else "",
             f"--ble {d['address']}") for d in devices]
    return [f"Bluetooth LE heart-rate straps ({len(rows)}):", *table(BLE_COLUMNS, rows)]


def table(columns: Sequence[str], rows: Sequence[Sequence[str]], indent: str = "  ") -> list[str]:
    """Lines of a left-aligned table: the header, then one line per row (header only if rows)."""
    if not rows:
        return []
    widths = [max(len(str(r[i])) for r in [columns, *rows]) for i in range(len(columns))]
    return [indent + "  ".join(str(v).ljust(w) for v, w in zip(r, widths)).rstrip()
            for r in [columns, *rows]]


def run(args: argparse.Namespace) -> int:
    """Print the serial ports and the cameras, each a table with column headers."""
    ports = list_ports()
    print(f"serial ports ({len(ports)}):")
    for line in table(PORT_COLUMNS, [(p["device"], p["description"], p["hwid"]) for p in ports]):
        print(line)
    for line in ble_lines(args.ble_scan):
        print(line)
    cams = list_cameras()
    print(f"cameras ({len(cams)}):")
    cam_rows = [(dev, f"--camera {dev.removeprefix('/dev/video') or index}") for index, dev in enumerate(cams)]
    for line in table(CAMERA_COLUMNS, cam_rows):
        print(line)
    print("simulated ports: 'effortface replay LOG' prints a pseudo-terminal path; replay://LOG in Python")
    return 0
