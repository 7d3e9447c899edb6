"""``effortface motion attach SESSION CLIP [--offset S | --sync]``: put a mocap clip on a session's clock.

The clip is copied into ``SESSION/motion/`` and ``motion.json`` records its offset and how it was
aligned (:mod:`effortface.synth.attach`); one line on stdout reports the offset and the residual.
"""

from __future__ import annotations

import argparse
import math

from effortface.core.docs import DESIGN
from effortface.core.errors import UserError
from effortface.synth.attach import CLIP_FORMATS, attach_clip


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``motion attach`` and its options."""
    sub = parser.add_subparsers(dest="action", required=True, metavar="attach")
    attach = sub.add_parser("attach", help="copy a clip into SESSION/motion/ and align it")
    attach.error = parser.error  # type: ignore[method-assign]  # one-line errors, exit 2
    attach.add_argument("session", metavar="SESSION", help="the session folder")
    attach.add_argument("clip", metavar="CLIP", help=f"a mocap clip ({', '.join(CLIP_FORMATS)})")
    how = attach.add_mutually_exclusive_group(required=True)
    how.add_argument("--offset", type=float, metavar="S", help="session time of the clip's first frame")
    how.add_argument("--sync", nargs="?", const="auto", metavar="T",
                     help="align the clip's first jump to the session's 'sync,jump' event (the one nearest "
                          "session time T when several fit)")
    attach.add_argument("--mapping", default=None, metavar="JSON",
                        help="joint-to-segment mapping for this clip, kept in motion.json for 'effortface work'")


def _seconds(option: str, text: str) -> float:
    """``text`` as a finite number of seconds (UserError naming the option)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise UserError(f"{option}: expected a session time in seconds, found {text!r}")
    return value


def run(args: argparse.Namespace) -> int:
    """Attach the clip; print where it went and how it was aligned."""
    near = None if args.sync in (None, "auto") else _seconds("--sync", args.sync)
    alignment = attach_clip(args.session, args.clip, offset_s=args.offset, sync=args.sync is not None,
                            sync_near_s=near, mapping=args.mapping)
    print(f"{args.clip} -> {args.session}/motion: {alignment.describe()}")
    return 0
