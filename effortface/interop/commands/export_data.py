"""``effortface export bids SESSIONS --out DIR``: session folders -> a BIDS dataset
(:mod:`effortface.interop.bids`). Prints the dataset folder."""

from __future__ import annotations

import argparse

from effortface.interop.bids import export_bids


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Format, sessions folder, output."""
    parser.add_argument("format", choices=("bids",), help="the output format")
    parser.add_argument("sessions", metavar="SESSIONS", help="folder of session folders")
    parser.add_argument("--out", required=True, metavar="DIR", help="new or empty dataset folder")
    parser.add_argument("--name", default=None,
                        help="dataset name (default: Name of SESSIONS/dataset_description.json, the lab's own "
                             "description, else 'effortface sessions')")


def run(args: argparse.Namespace) -> int:
    """Export and print the dataset folder."""
    print(export_bids(args.sessions, args.out, name=args.name))
    return 0
