"""``effortface app [DIR]``: the Qt application."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``effortface app``."""
    parser.add_argument("dir", nargs="?", default="sample_sessions", help="sessions folder")
    parser.add_argument("--screenshot", metavar="PATH", help="render offscreen to a PNG and exit")
    parser.add_argument("--stage", default="capture", help="stage to show (with --screenshot)")


def run(args: argparse.Namespace) -> int:
    """Open the main window (imports Qt only here)."""
    from effortface.app import main

    return main(args)
