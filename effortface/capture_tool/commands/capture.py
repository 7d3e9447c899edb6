"""``effortface capture``: record a strap (and video) into a new session folder, headless.

Runs until ``--duration`` (by default the end of ``--plan``) or Ctrl-C / SIGTERM, then stops cleanly
(``complete: true``). The first stdout line is the session folder (flushed at once); with ``--plan``
the phases' countdown follows on stdout (:mod:`effortface.capture_tool.plan`); a status line follows
every few seconds on stderr. Demographics come from the options or the lab's ``participants.tsv`` in
``--out`` (:mod:`effortface.capture_tool.participants`; without one, from the lab's own sessions); a
code alone takes the lab's record, options that differ from it are refused (one line naming every
differing field, exit 2, nothing written) unless ``--update-participant`` changes the record on
purpose (the previous record kept, dated, in ``participants_history.tsv``). A new participant, or a
changed record, is saved once the recording has started. A capture that received no heart-rate sample ends with a warning and exit
status 1. A fault (a file that cannot be written: disk full, file-size limit) is one line on stderr
naming the file as soon as it happens; a failed write stops the capture, which then leaves the
session incomplete for ``effortface recover`` and exits with status 2 (the video stopping early
on a nearly full disk only degrades it: the heart rate goes on). With video, the face's framing for
the machine rater is checked about twice a second off the recording path
(:mod:`effortface.capture_tool.framing_sampler`): a ``camera:`` line on stderr at the first look and
whenever it changes ("move the camera closer: the face is 14 % of the frame; the rater needs 25 %").
A ``--video`` file is recorded from its first frame, every frame; one that cannot be replayed in real
time ends with a warning counting the frames it dropped.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

from effortface.core.docs import DESIGN
from effortface.core.errors import UserError
from effortface.core.framing import Framing
from effortface.capture_tool.participants import HISTORY_TSV, REGISTRY_TSV, participant_options, resolve_participant, save_participant
from effortface.capture_tool.plan import PlanRunner, read_plan
from effortface.capture_tool.protocols import PROTOCOLS, check_protocol
from effortface.capture_tool.recorder import Recorder
from effortface.core.session.folder import Participant, id_taken_note

STATUS_INTERVAL_S = 5.0


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of DESIGN.md's capture line."""
    strap = parser.add_mutually_exclusive_group(required=True)
    strap.add_argument("--port", help="serial port, e.g. /dev/ttyUSB0, or a pyserial URL (with --protocol)")
    strap.add_argument("--ble", metavar="ADDRESS|NAME|replay://LOG",
                       help="a Bluetooth Low Energy heart-rate strap (Heart Rate Service 0x180D) by address or a part "
                            "of its name ('effortface ports' lists them), or replay://LOG of one recorded before; "
                            "protocol ble_hrm")
    parser.add_argument("--protocol", help=f"with --port: one of {', '.join(sorted(PROTOCOLS))}")
    video = parser.add_mutually_exclusive_group()
    video.add_argument("--camera", type=int, metavar="N", help="camera index")
    video.add_argument("--video", metavar="FILE", help="a video file played at its real rate, every frame from the first (tests, demos)")
    video.add_argument("--no-video", action="store_true", help="record the strap only")
    parser.add_argument("--participant", required=True, metavar="CODE", help="participant code such as P01 (never a name)")
    parser.add_argument("--age", type=float)
    parser.add_argument("--sex", help="female or male")
    parser.add_argument("--height", type=float, metavar="M", help="height in metres")
    parser.add_argument("--mass", type=float, metavar="KG", help="mass in kilograms")
    parser.add_argument("--training-level", type=float, metavar="TL", help="training level 0-10")
    parser.add_argument("--update-participant", action="store_true",
                        help=f"options that differ from the lab's record of --participant change that record on "
                             f"purpose (the previous one kept, dated, in {HISTORY_TSV}; earlier sessions keep "
                             f"theirs); without it they are refused")
    parser.add_argument("--plan", metavar="PLAN.csv",
                        help="timed phases to step through and log (start_s,end_s,exercise[,parameters])")
    parser.add_argument("--label", help="appended to the session folder name")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop after S seconds (default: the end of --plan, else Ctrl-C)")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help=f"lab folder: receives the session folder; holds {REGISTRY_TSV}")
    parser.add_argument("--lsl", action="store_true",
                        help="also publish the strap (LSL type HeartRate) and the events (Markers) on the "
                             "Lab Streaming Layer, for LabRecorder")


def _participant(args: argparse.Namespace) -> tuple[Participant, bool]:
    """The participant from the options and the lab's registry, and whether it is new there."""
    code, options = participant_options(args)
    return resolve_participant(code, options, Path(args.out) / REGISTRY_TSV,
                               update=bool(getattr(args, "update_participant", False)))


def _strap(args: argparse.Namespace) -> None:
    """``--ble X`` as the port and protocol the recorder opens (``ble://X``, or the replay URL, with ble_hrm);
    ``--port`` needs ``--protocol``."""
    if args.ble is not None:
        if args.protocol not in (None, "ble_hrm"):
            raise UserError(f"--protocol {args.protocol}: a --ble strap speaks ble_hrm, found --protocol with --ble")
        target = args.ble.strip()
        if not target:
            raise UserError("--ble: expected a device address or name, found an empty value")
        args.port = target if target.startswith("replay://") else f"ble://{target}"
        args.protocol = "ble_hrm"
        return
    if args.protocol is None:
        raise UserError(f"--protocol: expected one of {', '.join(sorted(PROTOCOLS))} with --port, found none")
    check_protocol(args.protocol)


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
    _strap(args)
    if args.camera is not None and args.camera < 0:
        raise UserError(f"--camera: expected a camera index >= 0, found {args.camera}")
    _check_out(args.out)
    participant, new = _participant(args)
    phases = read_plan(args.plan) if args.plan else []
    recorder = Recorder(args.out, participant, args.port, args.protocol, _video_source(args), label=args.label,
                        lsl=args.lsl)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    if hasattr(signal, "SIGXFSZ"):  # a file-size limit then fails the write (EFBIG): a fault, not a kill
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    path = _start(recorder, args.out)
    print(path, flush=True)
    if (note := id_taken_note(path)) is not None:
        print(f"effortface capture: {note}", file=sys.stderr, flush=True)
    if recorder.lsl is not None:
        print(f"LSL: publishing HeartRate and Markers streams, source id {recorder.lsl.source_id}",
              file=sys.stderr, flush=True)
    if new:
        save_participant(Path(args.out) / REGISTRY_TSV, participant)
    plan = PlanRunner(phases, recorder.mark, lambda line: print(line, flush=True)) if phases else None
    duration = args.duration if args.duration is not None or plan is None else plan.end_s
    said: list[str] = []  # the faults already printed
    try:
        _wait(recorder, stop, duration, said, plan)
    except KeyboardInterrupt:
        pass
    finally:
        if plan is not None:
            plan.finish()
        recorder.stop()
    return _report(recorder, path, said, args)


def _report(recorder: Recorder, path: Path, said: list[str], args: argparse.Namespace) -> int:
    """The closing lines: faults not yet said, warnings, then what was recorded; the exit status
    (2 after a fault, 1 when no heart-rate sample arrived, else 0)."""
    _say_new_faults(recorder, said)
    for line in recorder.warnings:
        print(f"warning: {line}", file=sys.stderr)
    st = recorder.status()
    counts = f"{st.samples} heart-rate samples, {st.frames} frames ({st.dropped_frames} dropped) in {path}"
    if st.samples == 0:
        print(f"warning: no heart-rate sample received from --port {args.port} (--protocol {args.protocol}): "
              f"{counts}; check the strap's contact, pairing and protocol", file=sys.stderr)
        return 2 if recorder.faults else 1
    complete = recorder.info is not None and recorder.info.complete
    state = "complete" if complete else f"INCOMPLETE (run 'effortface recover {path}')"
    print(f"{state}: {counts}", file=sys.stderr)
    return 2 if recorder.faults else 0


def _face_share(framing: Framing | None) -> str:
    """The status line's face size: ``  face 34 %``, ``  face none``, or nothing before the first look."""
    if framing is None:
        return ""
    return "  face none" if framing.face_share is None else f"  face {100 * framing.face_share:.0f} %"


def _say_framing(recorder: Recorder, said: list[str]) -> None:
    """The camera's framing for the machine rater, one line on stderr at the first look and whenever
    its verdict changes (framed, too small, too dark, no face); ``said`` holds the last verdict."""
    sampler = recorder.framing
    framing = sampler.latest if sampler is not None else None
    if framing is None or (said and said[-1] == framing.cause):
        return
    print(f"camera: {framing.line()}", file=sys.stderr, flush=True)
    said.append(framing.cause)


def _say_new_faults(recorder: Recorder, said: list[str]) -> None:
    """Print each fault not in ``said`` (then add it): one line naming the file, as soon as it appears."""
    for line in recorder.faults:
        if line not in said:
            print(f"capture: {line}", file=sys.stderr, flush=True)
            said.append(line)


def _check_out(out: str) -> None:
    """UserError if ``--out`` is a file (before the registry in it is read)."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise UserError(f"--out {out}: expected a folder, found a file")


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
    _check_out(out)
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


def _wait(recorder: Recorder, stop: threading.Event, duration_s: float | None, said: list[str],
          plan: PlanRunner | None = None) -> None:
    """Sleep until the duration is over, ``stop`` is set or a write failed, stepping the plan and
    printing faults at once and a status line now and then."""
    deadline = None if duration_s is None else time.monotonic() + duration_s
    next_status = time.monotonic() + STATUS_INTERVAL_S
    framing_said: list[str] = []
    while not stop.is_set():
        now = time.monotonic()
        _say_new_faults(recorder, said)
        _say_framing(recorder, framing_said)
        if plan is not None:
            plan.step(recorder.clock())
        if (deadline is not None and now >= deadline) or recorder.failed:
            return
        if now >= next_status:
            s = recorder.status()
            print(f"{s.elapsed_s:7.1f} s  HR {s.hr_bpm or '-'}  samples {s.samples}  frames {s.frames} "
                  f"dropped {s.dropped_frames}  link {s.link_state}" + (" (video stopped)" if recorder.camera and
                  recorder.camera.fault else "") + _face_share(s.framing), file=sys.stderr, flush=True)
            next_status = now + STATUS_INTERVAL_S
        stop.wait(0.1 if deadline is None else min(0.1, max(0.0, deadline - now)))
