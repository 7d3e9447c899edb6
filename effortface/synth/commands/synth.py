"""``effortface synth``: a motion clip + a character -> per-frame face curves (CSV or Live Link Face).

On success it prints one line on stdout: the file written, its frames and the clip's duration.

``MODEL_DIR`` is a model bundle folder or ``default`` (the built-in rule model). The file formats
(the per-frame CSV, ``--format livelink`` for the Live Link Face CSV) are
:mod:`effortface.synth.curves_io`'s. An existing ``--out`` is never replaced without ``--force``.
One clip is synthesized and written a minute of motion at a time (:mod:`effortface.synth.chunked`):
the memory does not grow with the clip (an hour of 120 Hz BVH motion within 1 GB).

``MOTION`` may be a folder of clips: then ``--out`` is a folder and every clip gives one file
(:mod:`effortface.synth.batch_synth`, on Dask with ``--workers N`` or ``--scheduler ADDRESS``), with
a progress bar and a summary; exit status 1 when some clips failed (they are named and skipped).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from effortface.core.docs import DESIGN, SCIENCE
from effortface.core.errors import UserError
from effortface.core.progress import ProgressBar
from effortface.core.fileio import check_apart
from effortface.synth.c3d_motion import window_line
from effortface.synth.character_options import add_character_arguments, character_from_args
from effortface.synth.chunked import synthesize_chunks
from effortface.synth.curves_io import CURVE_FORMATS, check_output, units_path, write_curve_chunks
from effortface.synth.motion import Motion
from effortface.synth.plausibility import read_checked_blocks, reading_record
from effortface.synth.read_options import add_motion_read_arguments, read_options_from_args
from effortface.synth.parallel import ComputeSettings, add_compute_arguments
from effortface.synth.runtime import REFERENCE_FRAMES, load_model

if TYPE_CHECKING:  # a folder of clips only: one clip does not pay for its imports
    from effortface.synth.batch_synth import BatchSummary, SynthOptions

#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN, SCIENCE)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's synth line."""
    parser.add_argument("model_dir", metavar="MODEL_DIR", help="model bundle folder, or 'default'")
    parser.add_argument("motion", metavar="MOTION|CLIPS_DIR",
                        help="motion clip (.bvh, .npz, joint-positions .csv or .c3d), or a folder of clips")
    parser.add_argument("--out", required=True, metavar="CSV|OUT_DIR",
                        help="output CSV file (a folder, one file per clip, for a folder of clips)")
    parser.add_argument("--format", choices=CURVE_FORMATS, default="csv",
                        help="per-frame curves (default) or a Live Link Face CSV (one row per frame of its "
                             "60 fps timecode)")
    parser.add_argument("--every-frame", action="store_true",
                        help="with --format livelink: one row per motion frame instead of resampling to 60 fps")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    add_character_arguments(parser)
    add_motion_read_arguments(parser, what="the clip (every clip of a folder)")
    parser.add_argument("--filter-tau-s", type=float, default=None, metavar="S",
                        help="output filter time constant on the weights, seconds (default: the "
                             "model's, 0.15; 0 writes the raw, unfiltered weights)")
    add_compute_arguments(parser, "a folder of clips")


def run(args: argparse.Namespace) -> int:
    """Synthesize and write the curves; return 0 (1 when some clips of a folder failed)."""
    out = Path(args.out)
    batch = Path(args.motion).is_dir()
    compute = ComputeSettings(args.workers, args.scheduler)
    model_dir = None if args.model_dir == "default" else args.model_dir
    check_apart("--out", out, [model_dir, args.motion, args.mapping])
    if not batch:
        check_output(out, args.force, args.format)  # fail before the work
    reading = read_options_from_args(args)
    model = load_model(args.model_dir)
    character = character_from_args(args, model)
    try:
        taus = model.filter_taus(args.filter_tau_s)
    except UserError as exc:
        raise UserError(f"--filter-tau-s: {exc}") from None
    if batch:
        from effortface.synth.batch_synth import SynthOptions

        options = SynthOptions(args.model_dir, character, args.format, args.force, args.mapping,
                               args.unit_m, taus, reading.up, reading.trust_skeleton)
        return _run_batch(Path(args.motion), out, options, compute)
    motion, body = read_checked_blocks(args.motion, reading, reference_frames=REFERENCE_FRAMES)
    chunks = synthesize_chunks(model, motion, character, mapping=args.mapping, filter_tau_s=taus)
    n_frames, duration_s = write_curve_chunks(out, chunks, model, fmt=args.format, force=args.force,
                                              provenance=motion.skeleton.source, every_frame=args.every_frame,
                                              reading=reading_record(motion.skeleton, body))
    print(written_line(out, n_frames, duration_s, args.format))
    print(read_line(motion.skeleton, body))
    if line := window_line(motion.skeleton.reading, args.motion):  # a trial read over its longest complete window
        print(line, file=sys.stderr)
    return 0


def read_line(motion: Motion, body: dict[str, Any]) -> str:
    """How the clip was read, one line: ``read as centimetre (rest pose ...), up y (gravity ...);
    standing height 1.62 m``."""
    r = motion.reading
    unit = f"unit {r['unit_m']:g} m ({r.get('unit_from', '?')})" if "unit_m" in r else "unit: the file's"
    up = f"up {r['up_axis']} ({r.get('up_from', '?')})" if "up_axis" in r else "up: the file's"
    trusted = " (outside the human ranges: --trust-skeleton)" if body.get("trusted") else ""
    return f"read {motion.source}: {unit}, {up}; standing height {body['height_m']:.2f} m{trusted}"


def written_line(out: Path, n_frames: int, duration_s: float, fmt: str) -> str:
    """What ``synth`` wrote: the file, its frames and the clip's duration (and the units sidecar)."""
    units = f", units in {units_path(out)}" if fmt == "csv" else ""
    return f"wrote {out}: {n_frames} frames, {duration_s:.2f} s of motion{units}"


def _run_batch(clips_dir: Path, out: Path, options: SynthOptions, compute: ComputeSettings) -> int:
    """A folder of clips with a progress bar on stderr and a summary; 1 when some failed."""
    from effortface.synth.batch_synth import list_clips, synth_batch

    n_clips = len(list_clips(clips_dir))  # no clips: the one error line, before any bar
    done = [0]

    def advance(_: object) -> None:
        done[0] += 1
        bar(done[0] / n_clips, "clips synthesized")

    with ProgressBar("synth") as bar:
        summary = synth_batch(clips_dir, out, options, compute, on_result=advance)
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
