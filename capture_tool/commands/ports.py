"""``effortface ports``: the serial ports and cameras this machine has."""

from __future__ import annotations

import argparse

from effortface.capture_tool.camera import list_cameras
from effortface.capture_tool.serial_link import list_ports


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No options."""


def run(args: argparse.Namespace) -> int:
    """Print one line per serial port and camera device."""
    ports = list_ports()
    print(f"serial ports ({len(ports)}):")
    for p in ports:
        print(f"  {p['device']}\t{p['description']}\t{p['hwid']}")
    cams = list_cameras()
    print(f"cameras ({len(cams)}):")
    for index, dev in enumerate(cams):
        print(f"  {dev}\t(--camera {dev.removeprefix('/dev/video') or index})")
    print("simulated ports: 'effortface replay LOG' prints a pseudo-terminal path; replay://LOG in Python")
    return 0
