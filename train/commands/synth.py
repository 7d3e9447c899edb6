"""``effortface synth``: a motion clip + a character -> per-frame face curves (CSV or Live Link Face).

``MODEL_DIR`` is a model bundle folder or ``default`` (the built-in rule model). The file formats
(the per-frame CSV, ``--format livelink`` for the Live Link Face CSV) are
:mod:`effortface.train.curves_io`'s. An existing ``--out`` is never replaced without ``--force``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from effortface.core.errors import UserError
from effortface.train.character_options import add_character_arguments, character_from_args
from effortface.train.curves_io import CURVE_FORMATS, check_output, write_curves
from effortface.train.motion import read_motion
from effortface.train.runtime import load_model


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's synth line."""
    parser.add_argument("model_dir", metavar="MODEL_DIR", help="model bundle folder, or 'default'")
    parser.add_argument("motion", metavar="MOTION", help="motion clip (.bvh, .npz, .c3d or joint-positions .csv)")
    parser.add_argument("--out", required=True, metavar="CSV", help="output CSV file")
    parser.add_argument("--format", choices=CURVE_FORMATS, default="csv",
                        help="per-frame curves (default) or a Live Link Face CSV")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    add_character_arguments(parser)
    parser.add_argument("--mapping", default=None, metavar="JSON",
                        help="joint-to-segment mapping file (default: built-in conventions)")
    parser.add_argument("--unit-m", type=float, default=None, metavar="M",
                        help="BVH length unit in metres (default: detected from the rest pose; "
                             "CMU cgspeed 0.05644)")


def run(args: argparse.Namespace) -> int:
    """Synthesize and write the curves; return 0."""
    out = Path(args.out)
    check_output(out, args.force)  # fail before the work
    model = load_model(args.model_dir)
    character = character_from_args(args, model)
    if args.unit_m is not None and not (math.isfinite(args.unit_m) and args.unit_m > 0):
        raise UserError(f"--unit-m: expected a length in metres above 0, found {args.unit_m:g}")
    motion = read_motion(args.motion, unit_m=args.unit_m)
    curves = model.synthesize(motion, character, mapping=args.mapping)
    write_curves(out, curves, model, fmt=args.format, force=args.force)
    return 0
