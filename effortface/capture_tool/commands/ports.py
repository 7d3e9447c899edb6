"""``effortface ports``: the serial ports and cameras this machine has, as tables with column headers."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from effortface.capture_tool.camera import list_cameras
from effortface.capture_tool.serial_link import list_ports

PORT_COLUMNS = ("DEVICE", "DESCRIPTION", "HARDWARE ID")
CAMERA_COLUMNS = ("DEVICE", "OPTION")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No options."""


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
    cams = list_cameras()
    print(f"cameras ({len(cams)}):")
    cam_rows = [(dev, f"--camera {dev.removeprefix('/dev/video') or index}") for index, dev in enumerate(cams)]
    for line in table(CAMERA_COLUMNS, cam_rows):
        print(line)
    print("simulated ports: 'effortface replay LOG' prints a pseudo-terminal path; replay://LOG in Python")
    return 0
