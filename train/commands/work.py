"""``effortface work SESSION... [--force]``: write each session's work.csv from motion/ and the log.

Every session is derived and checked before anything is written, so a refusal (a hand-made
work.csv without ``--force``, a session with neither motion nor exercise phases, an unknown
exercise) writes nothing. One line per session on stdout says where its seconds came from.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from effortface.core.docs import DESIGN, SCIENCE_NOTES
from effortface.capture_tool.session import SESSION_JSON, list_sessions, read_session
from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text
from effortface.train.work import WORK_CSV, WorkError, WorkTable, derive_work


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN, SCIENCE_NOTES)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface work``."""
    parser.add_argument("sessions", nargs="+", metavar="SESSION", help="session folders (or folders of sessions)")
    parser.add_argument("--force", action="store_true", help="replace an existing (maybe hand-made) work.csv")


def _folders(paths: list[str]) -> list[Path]:
    """Session folders from sessions and folders of sessions."""
    out: list[Path] = []
    for p in map(Path, paths):
        out.extend([p] if (p / SESSION_JSON).is_file() or not p.is_dir() else list_sessions(p))
    if not out:
        raise UserError(f"{', '.join(paths)}: expected session folders, found none")
    return out


def summary(table: WorkTable) -> str:
    """``N s: motion A s, log B s, none C s; mean w X W/kg``."""
    src = np.array([s.split(":", 1)[0] for s in table.source])
    counts = {k: int((src == k).sum()) for k in ("motion", "log", "")}
    mean = np.nanmean(table.w_per_kg) if np.isfinite(table.w_per_kg).any() else float("nan")
    return (f"{len(table.t_s)} s: motion {counts['motion']} s, log {counts['log']} s, none {counts['']} s; "
            f"mean w {mean:.2f} W/kg")


def run(args: argparse.Namespace) -> int:
    """Derive every session's work, then write the work.csv files."""
    planned = []
    for folder in _folders(args.sessions):
        session = read_session(folder)
        target = session.path / WORK_CSV
        if target.exists() and not args.force:
            raise WorkError(f"{target}: expected no work.csv (it may be hand-made), found one; "
                            f"use --force to replace it")
        planned.append((target, derive_work(session)))
    for target, table in planned:
        atomic_write_text(target, table.to_csv())
        print(f"{target}: {summary(table)}", file=sys.stdout)
    return 0
