"""``effortface app [DIR]``: the Qt application."""

from __future__ import annotations

import argparse
from pathlib import Path

from effortface.core.errors import UserError

#: the folder opened when no DIR is given, if the current directory has one (see :func:`default_dir`)
DEFAULT_DIR = "sample_sessions"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``effortface app``."""
    parser.add_argument("dir", nargs="?", default=None,
                        help=f"sessions folder (default: ./{DEFAULT_DIR} if there is one, else your copy "
                             "of the sample lab in the user data folder)")
    parser.add_argument("--screenshot", metavar="PATH", help="render offscreen to a PNG and exit")
    parser.add_argument("--stage", default="capture", help="stage to show (with --screenshot)")
    parser.add_argument("--size", default=None, metavar="WxH",
                        help="window size of the screenshot in pixels (default 1400x900)")


def default_dir() -> str:
    """``sample_sessions`` in the current directory, else the user's copy of the sample lab.

    Never the repository's or site-packages' folder when run elsewhere: the app writes key-frames
    and recordings into the folder it opens (see :func:`effortface.samplelab.app_default_dir`).
    """
    if Path(DEFAULT_DIR).is_dir():
        return DEFAULT_DIR
    from effortface.samplelab import app_default_dir

    return str(app_default_dir())


def run(args: argparse.Namespace) -> int:
    """Open the main window (imports Qt only here); no display: refused before the sample lab is copied."""
    from effortface.app import check_display, main

    if args.dir is not None and not Path(args.dir).exists():
        raise UserError(f"DIR {args.dir}: expected a folder of sessions, found nothing")
    check_display(bool(getattr(args, "screenshot", None)))
    if args.dir is None:
        args.dir = default_dir()

    return main(args)
