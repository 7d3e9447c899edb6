"""``effortface motion attach SESSION CLIP [--offset S | --sync]`` and ``effortface motion inspect FILE``.

``attach`` puts a mocap clip on a session's clock: the clip is read and mapped (with ``--unit-m``,
``--up``, ``--mapping``) before it is copied into ``SESSION/motion/``, and ``motion.json`` records
its offset, how it was aligned and how it is read (:mod:`effortface.synth.attach`); one line on
stdout reports the offset and the residual. ``inspect`` says what a motion file holds and how
effortface reads it (:mod:`effortface.synth.inspect`): a text report, or one JSON object with ``--json``.
"""

from __future__ import annotations

import argparse
import json
import math

from effortface.core.docs import DESIGN
from effortface.core.errors import UserError
from effortface.synth.attach import CLIP_FORMATS, attach_clip
from effortface.synth.read_options import add_motion_read_arguments, read_options_from_args


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``motion attach`` and its options."""
    sub = parser.add_subparsers(dest="action", required=True, metavar="{attach,inspect}")
    attach = sub.add_parser("attach", help="copy a clip into SESSION/motion/ and align it")
    attach.error = parser.error  # type: ignore[method-assign]  # one-line errors, exit 2
    attach.add_argument("session", metavar="SESSION", help="the session folder")
    attach.add_argument("clip", metavar="CLIP", help=f"a mocap clip ({', '.join(CLIP_FORMATS)})")
    how = attach.add_mutually_exclusive_group(required=True)
    how.add_argument("--offset", type=float, metavar="S", help="session time of the clip's first frame")
    how.add_argument("--sync", nargs="?", const="auto", metavar="T",
                     help="align the clip's first jump to the session's 'sync,jump' event (the one nearest "
                          "session time T when several fit)")
    add_motion_read_arguments(attach, what="the clip")  # kept in motion.json for 'effortface work'
    inspect = sub.add_parser("inspect", help="what a motion file holds and how effortface reads it")
    inspect.error = parser.error  # type: ignore[method-assign]  # one-line errors, exit 2
    inspect.add_argument("file", metavar="FILE", help="a motion file (.bvh, .c3d, .csv, .npz)")
    add_motion_read_arguments(inspect, what="the file")
    inspect.add_argument("--json", action="store_true", help="one JSON object on stdout instead of the text report")
    inspect.add_argument("--mapping-template", default=None, metavar="OUT.json",
                         help="also write a complete mapping file (version 2) with this file's names filled where "
                              "found and '<...>' placeholders where not")
    inspect.add_argument("--force", action="store_true", help="replace an existing --mapping-template file")


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
    """``attach``: attach the clip, print where it went and how it was aligned; ``inspect``: report the file."""
    if args.action == "inspect":
        return _inspect(args)
    options = read_options_from_args(args)
    near = None if args.sync in (None, "auto") else _seconds("--sync", args.sync)
    alignment = attach_clip(args.session, args.clip, offset_s=args.offset, sync=args.sync is not None,
                            sync_near_s=near, mapping=args.mapping, unit_m=options.unit_m, up=options.up,
                            trust_skeleton=options.trust_skeleton)
    print(f"{args.clip} -> {args.session}/motion: {alignment.describe()}")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    """Print the inspection of one file (text or ``--json``); write the mapping template when asked."""
    from effortface.synth.inspect import inspect_motion, write_mapping_template

    found = inspect_motion(args.file, read_options_from_args(args))
    if args.mapping_template is not None:
        write_mapping_template(found, args.mapping_template, force=args.force)
    if args.json:
        print(json.dumps(found.to_json()))
    else:
        print("\n".join(found.lines()))
        if args.mapping_template is not None:
            print(f"mapping template written to {args.mapping_template}")
    return 0
