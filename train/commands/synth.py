"""``effortface synth``: a motion clip + a character -> per-frame face curves (CSV or Live Link Face).

``MODEL_DIR`` is a model bundle folder or ``default`` (the built-in rule model). The file formats
(the per-frame CSV, ``--format livelink`` for the Live Link Face CSV) are
:mod:`effortface.train.curves_io`'s. An existing ``--out`` is never replaced without ``--force``.

``MOTION`` may be a folder of clips: then ``--out`` is a folder and every clip gives one file
(:mod:`effortface.train.batch_synth`, on Dask with ``--workers N`` or ``--scheduler ADDRESS``), with
a progress bar and a summary; exit status 1 when some clips failed (they are named and skipped).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from effortface.core.errors import UserError
from effortface.train.curves_io import CURVE_FORMATS, check_output, write_curves
from effortface.train.batch_synth import BatchSummary, SynthOptions, list_clips, synth_batch
from effortface.train.motion import read_motion
from effortface.train.parallel import ComputeSettings, add_compute_arguments
from effortface.train.runtime import Character, FaceModel, load_model


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's synth line."""
    parser.add_argument("model_dir", metavar="MODEL_DIR", help="model bundle folder, or 'default'")
    parser.add_argument("motion", metavar="MOTION|CLIPS_DIR",
                        help="motion clip (.bvh, .npz, joint-positions .csv or .c3d), or a folder of clips")
    parser.add_argument("--out", required=True, metavar="CSV|OUT_DIR",
                        help="output CSV file (a folder, one file per clip, for a folder of clips)")
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
    add_compute_arguments(parser, "a folder of clips")


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
    """Synthesize and write the curves; return 0 (1 when some clips of a folder failed)."""
    out = Path(args.out)
    batch = Path(args.motion).is_dir()
    compute = ComputeSettings(args.workers, args.scheduler)
    if not batch:
        check_output(out, args.force)  # fail before the work
    model = load_model(args.model_dir)
    character = _character(args, model)
    if args.unit_m is not None and not (math.isfinite(args.unit_m) and args.unit_m > 0):
        raise UserError(f"--unit-m: expected a length in metres above 0, found {args.unit_m:g}")
    try:
        taus = model.filter_taus(args.filter_tau_s)
    except UserError as exc:
        raise UserError(f"--filter-tau-s: {exc}") from None
    if batch:
        options = SynthOptions(args.model_dir, character, args.format, args.force, args.mapping,
                               args.unit_m, taus)
        return _run_batch(Path(args.motion), out, options, compute)
    motion = read_motion(args.motion, unit_m=args.unit_m)
    curves = model.synthesize(motion, character, mapping=args.mapping, filter_tau_s=taus)
    write_curves(out, curves, model, fmt=args.format, force=args.force)
    return 0


def _run_batch(clips_dir: Path, out: Path, options: SynthOptions, compute: ComputeSettings) -> int:
    """A folder of clips with a progress bar on stderr and a summary; 1 when some failed."""
    from tqdm import tqdm

    n_clips = len(list_clips(clips_dir))  # no clips: the one error line, before any bar
    with tqdm(total=n_clips, desc="synth", unit="clip", file=sys.stderr) as bar:
        summary = synth_batch(clips_dir, out, options, compute, on_result=lambda _: bar.update(1))
    return _report(summary, out)


def _report(summary: BatchSummary, out: Path) -> int:
    """Print the summary (stdout) and the failures (stderr); the exit status."""
    n, failed = len(summary.results), summary.failed
    rate = summary.n_frames / summary.elapsed_s if summary.elapsed_s > 0 else float("nan")
    print(f"synthesized {n - len(failed)} of {n} clips into {out} ({summary.n_frames} frames, "
          f"{summary.elapsed_s:.1f} s, {rate:.0f} frames/s)")
    for r in failed:
        print(f"effortface synth: failed: {r.clip}: {r.error}", file=sys.stderr)
    if failed:
        print(f"effortface synth: {len(failed)} of {n} clips failed (skipped)", file=sys.stderr)
        return 1
    return 0
