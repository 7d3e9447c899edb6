"""``effortface recover SESSION``: finish a session a crash left incomplete."""

from __future__ import annotations

import argparse

from effortface.core.docs import DESIGN
from effortface.capture_tool.recorder import recover_session


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """SESSION."""
    parser.add_argument("session", metavar="SESSION", help="the session folder")


def run(args: argparse.Namespace) -> int:
    """Recover and print what was done."""
    note = recover_session(args.session)
    print(f"recovered {args.session}")
    for line in note["done"]:
        print(f"  {line}")
    return 0
