"""``effortface export bids SESSIONS --out DIR [--skip-invalid]``: session folders -> a BIDS dataset
(:mod:`effortface.interop.bids`). Prints the dataset folder; what was left out, resampled or renamed
is one ``note:`` line each on stderr (what was left out also in the dataset's README)."""

from __future__ import annotations

import argparse
import sys

from effortface.interop.bids import ExportNotes, export_bids


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Format, sessions folder, output."""
    parser.add_argument("format", choices=("bids",), help="the output format")
    parser.add_argument("sessions", metavar="SESSIONS", help="folder of session folders")
    parser.add_argument("--out", required=True, metavar="DIR", help="new or empty dataset folder")
    parser.add_argument("--name", default=None,
                        help="dataset name (default: Name of SESSIONS/dataset_description.json, the lab's own "
                             "description, else 'effortface sessions')")
    parser.add_argument("--skip-invalid", action="store_true",
                        help="export a session without its part that cannot be read or derived (its work, a "
                             "motion clip) instead of refusing; each part left out is stated on stderr and in "
                             "the dataset's README")


def run(args: argparse.Namespace) -> int:
    """Export, state on stderr what was left out or changed, print the dataset folder."""
    notes = ExportNotes(skip_invalid=args.skip_invalid)
    out = export_bids(args.sessions, args.out, name=args.name, notes=notes)
    for line in notes.omitted + notes.notes:
        print(f"effortface export: note: {line}", file=sys.stderr)
    print(out)
    return 0
