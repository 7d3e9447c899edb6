"""``effortface work SESSION... [--force]``: write each session's work.csv from motion/ and the log.

Every session is derived and checked before anything is written, so a refusal (a hand-made
work.csv without ``--force``, a session with neither motion nor exercise phases, an unknown
exercise) writes nothing. One line per session on stdout says where its seconds came from.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from effortface.core.docs import DESIGN, SCIENCE_NOTES
from effortface.synth.read_options import add_motion_read_arguments, read_options_from_args
from effortface.synth.work import WorkTable, work_folders, write_works


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN, SCIENCE_NOTES)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface work``."""
    parser.add_argument("sessions", nargs="+", metavar="SESSION", help="session folders (or folders of sessions)")
    parser.add_argument("--force", action="store_true", help="replace an existing (maybe hand-made) work.csv")
    add_motion_read_arguments(parser, what="clips attached without one")


def summary(table: WorkTable) -> str:
    """``N s: motion A s, log B s, none C s; mean w X W/kg``."""
    src = np.array([s.split(":", 1)[0] for s in table.source])
    counts = {k: int((src == k).sum()) for k in ("motion", "log", "")}
    mean = np.nanmean(table.w_per_kg) if np.isfinite(table.w_per_kg).any() else float("nan")
    return (f"{len(table.t_s)} s: motion {counts['motion']} s, log {counts['log']} s, none {counts['']} s; "
            f"mean w {mean:.2f} W/kg")


def run(args: argparse.Namespace) -> int:
    """Derive every session's work, then write the work.csv files (one line each on stdout)."""
    read = read_options_from_args(args)
    for target, table in write_works(work_folders(args.sessions), force=args.force, mapping=args.mapping,
                                     read=read):
        print(f"{target}: {summary(table)}", file=sys.stdout)
    return 0
