"""``effortface synth``: a motion clip + a character -> per-frame face curves (CSV or Live Link Face).

On success it prints one line on stdout: the file written, its frames and the clip's duration.

``MODEL_DIR`` is a model bundle folder or ``default`` (the built-in rule model). The file formats
(the per-frame CSV, ``--format livelink`` for the Live Link Face CSV) are
:mod:`effortface.train.curves_io`'s. An existing ``--out`` is never replaced without ``--force``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from effortface.core import bounds
from effortface.core.docs import DESIGN, SCIENCE
from effortface.core.errors import UserError
from effortface.core.fileio import check_apart
from effortface.train.curves_io import CURVE_FORMATS, check_output, units_path, write_curves
from effortface.train.motion import read_motion
from effortface.train.runtime import Character, FaceModel, load_model


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN, SCIENCE)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's synth line."""
    parser.add_argument("model_dir", metavar="MODEL_DIR", help="model bundle folder, or 'default'")
    parser.add_argument("motion", metavar="MOTION", help="motion clip (.bvh, .npz, joint-positions .csv or .c3d)")
    parser.add_argument("--out", required=True, metavar="CSV", help="output CSV file")
    parser.add_argument("--format", choices=CURVE_FORMATS, default="csv",
                        help="per-frame curves (default) or a Live Link Face CSV")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--age", type=float, default=30.0, help="years (default 30)")
    parser.add_argument("--sex", default="male", help="male or female (default male)")
    parser.add_argument("--height", type=float, default=1.78, metavar="M", help="metres (default 1.78)")
    parser.add_argument("--mass", type=float, default=75.0, metavar="KG", help="kilograms (default 75)")
    parser.add_argument("--training-level", type=float, default=5.0, metavar="TL",
                        help="0-10 (default 5)")
    parser.add_argument("--expressiveness", default=None, metavar="A,B,C,D",
                        help="one factor per blendshape (default all 1)")
    parser.add_argument("--load-left", type=float, default=0.0, metavar="KG", help="left hand")
    parser.add_argument("--load-right", type=float, default=0.0, metavar="KG", help="right hand")
    parser.add_argument("--load-back", type=float, default=0.0, metavar="KG", help="on the back")
    parser.add_argument("--mapping", default=None, metavar="JSON",
                        help="joint-to-segment mapping file (default: built-in conventions)")
    parser.add_argument("--filter-tau-s", type=float, default=None, metavar="S",
                        help="output filter time constant on the weights, seconds (default: the "
                             "model's, 0.15; 0 writes the raw, unfiltered weights)")
    parser.add_argument("--unit-m", type=float, default=None, metavar="M",
                        help="BVH length unit in metres (default: detected from the rest pose; "
                             "CMU cgspeed 0.05644)")


def _expressiveness(text: str | None, n: int) -> tuple[float, ...]:
    if text is None:
        return (1.0,) * n
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--expressiveness: expected {n} comma-separated numbers, found {text!r}") from None


def _character(args: argparse.Namespace, model: FaceModel) -> Character:
    n_blendshapes = len(model.blendshapes)
    try:
        character = Character(age=args.age, sex=args.sex, height_m=args.height, mass_kg=args.mass,
                         training_level=args.training_level,
                         expressiveness=_expressiveness(args.expressiveness, n_blendshapes),
                         load_left_kg=args.load_left, load_right_kg=args.load_right,
                         load_back_kg=args.load_back)
        model.expressiveness(character)
    except UserError as exc:
        raise UserError(f"character options: {exc}") from None
    return character


def run(args: argparse.Namespace) -> int:
    """Synthesize and write the curves; return 0."""
    out = Path(args.out)
    model_dir = None if args.model_dir == "default" else args.model_dir
    check_apart("--out", out, [model_dir, args.motion, args.mapping])
    check_output(out, args.force, args.format)  # fail before the work
    model = load_model(args.model_dir)
    character = _character(args, model)
    if args.unit_m is not None and not (math.isfinite(args.unit_m) and args.unit_m > 0):
        raise UserError(f"--unit-m: expected a length in metres above 0, found {args.unit_m:g}")
    if args.unit_m is not None:
        bounds.check("unit_m", args.unit_m, "--unit-m")
    motion = read_motion(args.motion, unit_m=args.unit_m)
    try:
        taus = model.filter_taus(args.filter_tau_s)
    except UserError as exc:
        raise UserError(f"--filter-tau-s: {exc}") from None
    curves = model.synthesize(motion, character, mapping=args.mapping, filter_tau_s=taus)
    write_curves(out, curves, model, fmt=args.format, force=args.force)
    print(written_line(out, curves["t_s"], args.format))
    return 0


def written_line(out: Path, t_s: np.ndarray, fmt: str) -> str:
    """What ``synth`` wrote: the file, its frames and the clip's duration (and the units sidecar)."""
    n_frames = len(t_s)
    duration_s = float(t_s[-1] - t_s[0]) if n_frames else 0.0
    units = f", units in {units_path(out)}" if fmt == "csv" else ""
    return f"wrote {out}: {n_frames} frames, {duration_s:.2f} s of motion{units}"
