"""``effortface capture``: record a strap (and video) into a new session folder, headless.

Runs until ``--duration`` or Ctrl-C / SIGTERM, then stops cleanly (``complete: true``). The first
stdout line is the session folder (flushed at once); a status line follows every few seconds on
stderr.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

from effortface.core.errors import UserError
from effortface.capture_tool.protocols import PROTOCOLS, check_protocol
from effortface.capture_tool.recorder import Recorder
from effortface.capture_tool.session import Participant

STATUS_INTERVAL_S = 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's capture line."""
    parser.add_argument("--port", required=True, help="serial port, e.g. /dev/ttyUSB0, or a pyserial URL")
    parser.add_argument("--protocol", required=True, help=f"one of {', '.join(sorted(PROTOCOLS))}")
    video = parser.add_mutually_exclusive_group()
    video.add_argument("--camera", type=int, metavar="N", help="camera index")
    video.add_argument("--video", metavar="FILE", help="a video file played at its real rate (tests, demos)")
    video.add_argument("--no-video", action="store_true", help="record the strap only")
    parser.add_argument("--participant", required=True, metavar="CODE", help="participant code such as P01 (never a name)")
    parser.add_argument("--age", type=float)
    parser.add_argument("--sex", help="female or male")
    parser.add_argument("--height", type=float, metavar="M", help="height in metres")
    parser.add_argument("--mass", type=float, metavar="KG", help="mass in kilograms")
    parser.add_argument("--training-level", type=float, metavar="TL", help="training level 0-10")
    parser.add_argument("--label", help="appended to the session folder name")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    parser.add_argument("--out", required=True, metavar="DIR", help="folder that receives the session folder")
    parser.add_argument("--lsl", action="store_true",
                        help="also publish the strap (LSL type HeartRate) and the events (Markers) on the "
                             "Lab Streaming Layer, for LabRecorder")


def _participant(args: argparse.Namespace) -> Participant:
    try:
        return Participant(code=args.participant, sex=args.sex, age=args.age, height_m=args.height,
                           mass_kg=args.mass, training_level=args.training_level)
    except UserError as exc:
        raise UserError(f"--participant / body options: {exc}") from None


def _video_source(args: argparse.Namespace) -> int | str | None:
    if args.camera is not None:
        return args.camera
    if args.video is not None:
        return args.video
    return None


def run(args: argparse.Namespace) -> int:
    """Record until the duration or a stop signal; print the session folder."""
    if args.duration is not None and not args.duration > 0:
        raise UserError(f"--duration: expected seconds above 0, found {args.duration}")
    check_protocol(args.protocol)
    if args.camera is not None and args.camera < 0:
        raise UserError(f"--camera: expected a camera index >= 0, found {args.camera}")
    recorder = Recorder(args.out, _participant(args), args.port, args.protocol, _video_source(args), label=args.label,
                        lsl=args.lsl)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    path = _start(recorder, args.out)
    print(path, flush=True)
    if recorder.lsl is not None:
        print(f"LSL: publishing HeartRate and Markers streams, source id {recorder.lsl.source_id}",
              file=sys.stderr, flush=True)
    try:
        _wait(recorder, stop, args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        recorder.stop()
    st = recorder.status()
    print(f"complete: {st.samples} heart-rate samples, {st.frames} frames ({st.dropped_frames} dropped) in {path}",
          file=sys.stderr)
    return 0


def _start(recorder: Recorder, out: str) -> Path:
    """Start ``recorder``; a session folder that cannot be created in ``out`` is a UserError naming --out.

    Parameters
    ----------
    recorder : Recorder
        The recorder to start.
    out : str
        The --out folder.

    Returns
    -------
    Path
        The new session folder.
    """
    if os.path.exists(out) and not os.path.isdir(out):
        raise UserError(f"--out {out}: expected a folder, found a file")
    try:
        return recorder.start()
    except FileExistsError as exc:
        raise UserError(f"--out {out}: expected a new session folder, found one of that name ({exc.filename})") from None
    except OSError as exc:
        if exc.filename is None or not _is_under(exc.filename, out):
            raise
        raise UserError(f"--out {out}: expected a folder where a session folder can be created, "
                        f"found {exc.strerror or type(exc).__name__} ({exc.filename})") from None


def _is_under(path: str | os.PathLike, folder: str) -> bool:
    """True if ``path`` is ``folder`` or inside it, or one of its parent folders (lexically)."""
    path, folder_path = Path(os.path.abspath(path)), Path(os.path.abspath(folder))
    return path == folder_path or folder_path in path.parents or path in folder_path.parents


def _wait(recorder: Recorder, stop: threading.Event, duration_s: float | None) -> None:
    """Sleep until the duration is over or ``stop`` is set, printing a status line now and then."""
    deadline = None if duration_s is None else time.monotonic() + duration_s
    next_status = time.monotonic() + STATUS_INTERVAL_S
    while not stop.is_set():
        now = time.monotonic()
        if deadline is not None and now >= deadline:
            return
        if now >= next_status:
            s = recorder.status()
            print(f"{s.elapsed_s:7.1f} s  HR {s.hr_bpm or '-'}  samples {s.samples}  frames {s.frames} "
                  f"dropped {s.dropped_frames}  link {s.link_state}", file=sys.stderr, flush=True)
            next_status = now + STATUS_INTERVAL_S
        stop.wait(0.1 if deadline is None else min(0.1, max(0.0, deadline - now)))
