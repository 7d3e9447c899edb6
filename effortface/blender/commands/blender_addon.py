"""``effortface blender-addon --out FILE.zip``: build the Blender add-on's installable zip.

On success it prints one line: the file written and how many files it holds. An existing ``--out``
is never replaced without ``--force``. Install it in Blender 4.2+ with *Edit > Preferences > Get
Extensions > Install from Disk* (docs/guide/blender.md).
"""

from __future__ import annotations

import argparse

from effortface.blender.package import build_zip
from effortface.core.docs import DESIGN

#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's blender-addon line."""
    parser.add_argument("--out", required=True, metavar="FILE.zip", help="the add-on zip to write")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")


def run(args: argparse.Namespace) -> int:
    """Build the zip; return 0."""
    path, n = build_zip(args.out, args.force)
    print(f"{path}: Blender add-on, {n} files (install: Preferences > Get Extensions > Install from Disk)")
    return 0
