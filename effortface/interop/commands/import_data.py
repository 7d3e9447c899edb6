"""``effortface import xdf FILE.xdf --out SESSIONS``: a LabRecorder recording -> a session folder
(:mod:`effortface.interop.xdf_import`); ``effortface import hr FILE... --out LAB``: heart-rate files
of watches, bike computers and phone apps (FIT, TCX, GPX, Polar HRM, PWX, CSV/TSV) -> one session
folder each (:mod:`effortface.capture_tool.importers`). Prints the new session folders.

``import hr`` takes the participant as ``capture`` does: options completed from the lab's
``participants.tsv`` in ``--out`` (or its sessions), a contradiction refused unless
``--update-participant``, a new participant registered. Every file is read and checked before any
session is written, so one bad file leaves nothing written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from effortface.core.session.folder import Participant, id_taken_note, read_session_info
from effortface.core.errors import UserError
from effortface.interop.xdf_import import MOCAP_TREE_KEY, import_xdf


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Format, files, streams or columns, video, participant."""
    parser.add_argument("format", choices=("xdf", "hr"),
                        help="xdf: a LabRecorder recording; hr: heart-rate files (FIT, TCX, GPX, Polar HRM, PWX, "
                             "CSV/TSV)")
    parser.add_argument("file", metavar="FILE", nargs="+", help="the .xdf file (one), or heart-rate files (hr)")
    parser.add_argument("--out", required=True, metavar="SESSIONS", help="folder that receives the session")
    parser.add_argument("--hr-stream", metavar="NAME|TYPE", help="xdf: heart-rate stream (default: the one typed HeartRate, else named, typed or with a channel "
                             "labelled HR/HeartRate/RR or in bpm; R-R in ms becomes heart rate; units and 25-250 bpm "
                             "checked)")
    parser.add_argument("--marker-stream", action="append", default=[], metavar="NAME|TYPE",
                        help="xdf: marker stream (repeatable; default: every stream of type Markers or StringMarker)")
    parser.add_argument("--work-stream", metavar="NAME|TYPE", help="xdf: EffortWork stream -> work.csv")
    parser.add_argument("--mocap-stream", metavar="NAME|TYPE",
                        help="xdf: mocap stream -> motion/mocap.csv, attached at its own time (motion.json)")
    parser.add_argument("--mocap-skeleton", metavar="JSON",
                        help="xdf: the mocap clip's skeleton tree ({\"joints\": [...], \"parents\": [...]}, the "
                             "stream's joints in order); default: the first joint is the parent of every other one")
    parser.add_argument("--hr-json-key", metavar="PATH",
                        help="xdf: key path of the heart rate (bpm) in a stream of JSON text, e.g. hr or data.hr "
                             "(default: a top-level key named hr, heart_rate, bpm...)")
    parser.add_argument("--rr-json-key", metavar="PATH", help="xdf: key path of the R-R intervals (ms, a number or a "
                                                                "list) in that JSON")
    parser.add_argument("--keep-ecg", action="store_true",
                        help="xdf: copy the ECG stream (a Polar H10's) into the session as ecg.csv; an ECG stream "
                             "is never taken as heart rate")
    parser.add_argument("--time-col", metavar="NAME", help="hr, CSV/TSV: the time column (seconds or ISO 8601)")
    parser.add_argument("--hr-col", metavar="NAME", help="hr, CSV/TSV: the heart-rate column (bpm)")
    parser.add_argument("--rr-col", metavar="NAME", help="hr, CSV/TSV: the R-R interval column (ms, or s)")
    parser.add_argument("--video", metavar="FILE", help="the video recorded beside it")
    parser.add_argument("--video-stream", metavar="NAME|TYPE", help="xdf: stream with one sample per video frame")
    parser.add_argument("--video-offset", type=float, metavar="S",
                        help="xdf: LSL time of the video's first frame; hr: seconds of the video's first frame "
                             "after the file's first heart-rate sample (default 0; negative: the video started first)")
    parser.add_argument("--video-flash-at", type=float, metavar="S",
                        help="hr: instead of --video-offset, the heart-rate file's time (s after its first sample) of "
                             "a flash the video filmed (a phone's torch, a lap pressed with the watch's light): its "
                             "first bright frame is put there")
    parser.add_argument("--participant", required=True, metavar="CODE", help="participant code (never a name)")
    parser.add_argument("--age", type=float)
    parser.add_argument("--sex", help="female or male")
    parser.add_argument("--height", type=float, metavar="M")
    parser.add_argument("--mass", type=float, metavar="KG")
    parser.add_argument("--training-level", type=float, metavar="TL")
    parser.add_argument("--update-participant", action="store_true",
                        help="hr: options that differ from the lab's record of --participant change it on purpose")
    parser.add_argument("--label", help="appended to the session folder name")


def run(args: argparse.Namespace) -> int:
    """Import and print the session folder(s)."""
    if args.format == "hr":
        return _run_hr(args)
    if args.video_flash_at is not None:
        raise UserError("--video-flash-at: only for 'import hr', found with 'import xdf'")
    if len(args.file) != 1:
        raise UserError(f"import xdf: expected one .xdf file, found {len(args.file)}: {' '.join(args.file)}")
    for option in ("time_col", "hr_col", "rr_col"):
        if getattr(args, option) is not None:
            raise UserError(f"--{option.replace('_', '-')}: only for 'import hr', found with 'import xdf'")
    if args.mocap_skeleton is not None and args.mocap_stream is None:
        raise UserError("--mocap-skeleton: expected with --mocap-stream, found without it")
    try:
        participant = Participant(code=args.participant, sex=args.sex, age=args.age, height_m=args.height,
                                  mass_kg=args.mass, training_level=args.training_level)
    except UserError as exc:
        raise UserError(f"--participant / body options: {exc}") from None
    folder = import_xdf(args.file[0], args.out, participant, hr_stream=args.hr_stream,
                        marker_streams=args.marker_stream, work_stream=args.work_stream,
                        mocap_stream=args.mocap_stream, video=args.video, video_stream=args.video_stream,
                        video_offset_s=args.video_offset, label=args.label, hr_json_key=args.hr_json_key,
                        rr_json_key=args.rr_json_key, keep_ecg=args.keep_ecg, mocap_skeleton=args.mocap_skeleton)
    _state_suffix(folder)
    if args.mocap_stream is not None and args.mocap_skeleton is None:
        tree = read_session_info(folder).extra["lsl"][MOCAP_TREE_KEY]
        print(f"effortface import: note: mocap stream {args.mocap_stream!r}: skeleton tree {tree} "
              "(--mocap-skeleton FILE gives the real one)", file=sys.stderr)
    print(folder)
    return 0


def _state_suffix(folder: Path) -> None:
    """Say on stderr that the session got a suffix because its folder name was taken."""
    note = id_taken_note(folder)
    if note is not None:
        print(f"effortface import: {note}", file=sys.stderr)


def _run_hr(args: argparse.Namespace) -> int:
    """``import hr``: read and check every file, resolve the participant, then write one session each."""
    from effortface.capture_tool.participants import participant_options
    from effortface.capture_tool.importers.session import import_hr_files

    for option in ("hr_stream", "work_stream", "mocap_stream", "mocap_skeleton", "video_stream", "hr_json_key",
                   "rr_json_key"):
        if getattr(args, option) is not None:
            raise UserError(f"--{option.replace('_', '-')}: only for 'import xdf', found with 'import hr'")
    if args.keep_ecg:
        raise UserError("--keep-ecg: only for 'import xdf', found with 'import hr'")
    if args.marker_stream:
        raise UserError("--marker-stream: only for 'import xdf', found with 'import hr'")
    code, options = participant_options(args)
    folders = import_hr_files(args.file, args.out, code, options, update=args.update_participant, label=args.label,
                              video=Path(args.video) if args.video is not None else None,
                              video_offset_s=args.video_offset, video_flash_at_s=args.video_flash_at,
                              time_col=args.time_col, hr_col=args.hr_col,
                              rr_col=args.rr_col)
    for folder in folders:
        print(folder)
    return 0
