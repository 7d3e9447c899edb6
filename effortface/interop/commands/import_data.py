"""``effortface import xdf FILE.xdf --out SESSIONS``: a LabRecorder recording -> a session folder
(:mod:`effortface.interop.xdf_import`). Prints the new session folder."""

from __future__ import annotations

import argparse

from effortface.core.session.folder import Participant
from effortface.core.errors import UserError
from effortface.interop.xdf_import import import_xdf


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Format, file, streams, video, participant."""
    parser.add_argument("format", choices=("xdf",), help="the recording's format")
    parser.add_argument("file", metavar="FILE", help="the .xdf file")
    parser.add_argument("--out", required=True, metavar="SESSIONS", help="folder that receives the session")
    parser.add_argument("--hr-stream", metavar="NAME|TYPE", help="heart-rate stream (default: the one typed HeartRate, else named, typed or with a channel "
                             "labelled HR/HeartRate/RR or in bpm; R-R in ms becomes heart rate; units and 25-250 bpm "
                             "checked)")
    parser.add_argument("--marker-stream", action="append", default=[], metavar="NAME|TYPE",
                        help="marker stream (repeatable; default: every stream of type Markers or StringMarker)")
    parser.add_argument("--work-stream", metavar="NAME|TYPE", help="EffortWork stream -> work.csv")
    parser.add_argument("--mocap-stream", metavar="NAME|TYPE", help="mocap stream -> motion/mocap.csv")
    parser.add_argument("--video", metavar="FILE", help="the video recorded beside it")
    parser.add_argument("--video-stream", metavar="NAME|TYPE", help="stream with one sample per video frame")
    parser.add_argument("--video-offset", type=float, metavar="S", help="LSL time of the video's first frame")
    parser.add_argument("--participant", required=True, metavar="CODE", help="participant code (never a name)")
    parser.add_argument("--age", type=float)
    parser.add_argument("--sex", help="female or male")
    parser.add_argument("--height", type=float, metavar="M")
    parser.add_argument("--mass", type=float, metavar="KG")
    parser.add_argument("--training-level", type=float, metavar="TL")
    parser.add_argument("--label", help="appended to the session folder name")


def run(args: argparse.Namespace) -> int:
    """Import and print the session folder."""
    try:
        participant = Participant(code=args.participant, sex=args.sex, age=args.age, height_m=args.height,
                                  mass_kg=args.mass, training_level=args.training_level)
    except UserError as exc:
        raise UserError(f"--participant / body options: {exc}") from None
    folder = import_xdf(args.file, args.out, participant, hr_stream=args.hr_stream,
                        marker_streams=args.marker_stream, work_stream=args.work_stream,
                        mocap_stream=args.mocap_stream, video=args.video, video_stream=args.video_stream,
                        video_offset_s=args.video_offset, label=args.label)
    print(folder)
    return 0
