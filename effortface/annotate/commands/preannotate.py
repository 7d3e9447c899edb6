"""``effortface preannotate SESSION [SESSION ...]``: the machine rater on every recorded frame.

Writes ``SESSION/machine/face_landmarker.csv`` (one row per row of ``video_frames.csv``: ``frame,t_s,face``,
our four blendshapes, then MediaPipe's 52 ARKit-named scores; empty cells where no face was found) and
``face_landmarker.json`` beside it (model sha256, software versions, mapping, calibration, frames without
a face, time taken). The model is the shipped MediaPipe Face Landmarker bundle, or ``--model FILE``;
nothing is downloaded. Every session is checked before any is rated: one that is being recorded, left
incomplete, has no video or already has a machine rating (without ``--force``) is refused in one line
(exit 2). Several sessions are rated in parallel with ``--workers N``. Nothing is written for a session
until all its frames are rated, so Ctrl-C leaves no half-written file. A session with a face on fewer
than half its frames ends with a warning line naming the likely cause (the face too small, the video
too dark, or no face) and exit status 1. When several sessions are rated, those rated before the others
are mapped and calibrated again at the end from their stored scores, so that each sees every track of the
run (the learned mapping and the calibration use the lab's other tracks). See docs/guide/machine-rater.md.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing
import os
import sys
from pathlib import Path

from effortface.core.docs import SCIENCE
from effortface.core.errors import UserError
from effortface.core.progress import ProgressBar

#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (SCIENCE,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """SESSION..., --model, --force, --workers."""
    parser.add_argument("sessions", nargs="+", metavar="SESSION", help="session folders with video")
    parser.add_argument("--model", metavar="FILE",
                        help="a MediaPipe face_landmarker.task bundle (default: the one shipped with effortface)")
    parser.add_argument("--force", action="store_true", help="replace an existing machine rating")
    parser.add_argument("--workers", type=int, default=1, metavar="N",
                        help="sessions rated at once, each in its own process (default 1)")


def _check_args(args: argparse.Namespace) -> tuple[list[Path], Path | None]:
    """The sessions (each checked, before any work) and the model path."""
    from effortface.annotate.machine.landmarker import FaceLandmarker, litert_interpreter
    from effortface.annotate.machine.preannotate import check_rateable

    if args.workers < 1:
        raise UserError(f"--workers: expected a whole number of at least 1, found {args.workers}")
    litert_interpreter()  # one line where ai-edge-litert has no wheel
    model = Path(args.model) if args.model is not None else None
    if model is not None:
        FaceLandmarker(model)  # the bundle read and its three models loaded: one line before any work
    sessions = [Path(s) for s in args.sessions]
    seen: set[Path] = set()
    for s in sessions:
        if s.resolve() in seen:
            raise UserError(f"{s}: expected each session once, found it given twice")
        seen.add(s.resolve())
        check_rateable(s, force=args.force)
    return sessions, model


def _rate_one(task: tuple[Path, Path | None, bool, int]) -> tuple[bool, str]:
    """Worker: rate one session; (True, the line to print) or (False, the error's line)."""
    from effortface.annotate.machine.preannotate import preannotate_session
    from effortface.annotate.machine.track import read_machine_track

    session, model, force, threads = task
    try:
        out = preannotate_session(session, model_path=model, force=force, num_threads=threads)
        track = read_machine_track(session)
    except UserError as exc:
        return False, str(exc)
    n = 0 if track is None else len(track.frame)
    found = 0 if track is None else int(track.face.sum())
    taken = None if track is None else track.sidecar.get("time_taken_s")
    return True, f"wrote {out}: {n} frames, a face on {found} ({taken} s)"


def run(args: argparse.Namespace) -> int:
    """Check every session, rate them, print one line each; 2 when one failed, else 1 when one has a
    face on fewer than half its frames (a warning line each), else 0."""
    sessions, model = _check_args(args)
    if len(sessions) == 1 or args.workers == 1:
        return _run_serial(sessions, model, args.force)
    return _run_parallel(sessions, model, args.force, min(args.workers, len(sessions)))


def _run_serial(sessions: list[Path], model: Path | None, force: bool) -> int:
    """One session after the other, a frame progress bar each (plain lines when stderr is a log)."""
    from effortface.annotate.machine.preannotate import preannotate_session
    from effortface.annotate.machine.track import read_machine_track

    failed = 0
    rated: list[Path] = []
    for session in sessions:
        error: UserError | None = None
        with ProgressBar(session.name[:32]) as bar:
            def progress(done: int, total: int) -> None:
                bar(done / total if total else 0.0, "frames rated")
            try:
                out = preannotate_session(session, model_path=model, force=force, progress=progress)
            except UserError as exc:
                error = exc
        if error is not None:  # after the bar has cleared its line
            print(f"effortface preannotate: error: {error}", file=sys.stderr)
            failed += 1
            continue
        track = read_machine_track(session)
        assert track is not None
        print(f"wrote {out}: {len(track.frame)} frames, a face on {int(track.face.sum())} "
              f"({track.sidecar.get('time_taken_s')} s)")
        rated.append(session)
    failed += _map_again(rated[:-1])  # the last one rated saw every track of the run
    warned = _warn_coverage(rated)
    return 2 if failed else warned


def _map_again(sessions: list[Path]) -> int:
    """Map and calibrate ``sessions`` again now that every track of the run is on disk (a session rated
    before the others did not see them: :func:`~effortface.annotate.machine.preannotate.remap_session`);
    a line for each one that changed; returns the number that failed (one line each)."""
    from effortface.annotate.machine.preannotate import remap_session

    lines, failed = [], 0
    if not sessions:
        return 0
    with ProgressBar("mapping again") as bar:
        for done, session in enumerate(sessions, start=1):
            try:
                if remap_session(session):
                    lines.append(f"mapped again: {session}: its mapping and calibration now see every track of this run")
            except UserError as exc:
                lines.append(f"effortface preannotate: error: {exc}")
                failed += 1
            bar(done / len(sessions), "sessions mapped with the run's tracks")
    for line in lines:
        print(line, file=sys.stderr if line.startswith("effortface preannotate: error") else sys.stdout)
    return failed


def _warn_coverage(sessions: list[Path]) -> int:
    """A warning line for each rated session with a face on fewer than half its frames, naming the
    likely cause (:mod:`effortface.annotate.machine.face_coverage`); 1 when there was one, else 0."""
    from effortface.annotate.machine.face_coverage import coverage_warning
    from effortface.annotate.machine.track import read_machine_track

    warned = 0
    for session in sessions:
        track = read_machine_track(session)
        line = None if track is None else coverage_warning(session, track)
        if line is not None:
            print(f"warning: {line}", file=sys.stderr)
            warned += 1
    return 1 if warned else 0


def _run_parallel(sessions: list[Path], model: Path | None, force: bool, workers: int) -> int:
    """Sessions in worker processes (spawned: no fork of the interpreters' threads), a bar over sessions.

    A stop (Ctrl-C, SIGTERM) ends the workers before the command returns (each worker's unfinished
    session is left as it was: its files are written together at its end, or not at all).
    """
    from effortface.core.stops import ignore_stops_in_worker

    failed = 0
    rated: list[Path] = []
    threads = max(1, (os.cpu_count() or 1) // workers)
    pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=ignore_stops_in_worker)
    try:
        with ProgressBar("preannotate") as bar:
            futures = {pool.submit(_rate_one, (s, model, force, threads)): s for s in sessions}
            for done, future in enumerate(cf.as_completed(futures), start=1):
                bar(done / len(sessions), "sessions rated")
                ok, line = future.result()
                print(line if ok else f"effortface preannotate: error: {line}", file=sys.stdout if ok else sys.stderr)
                failed += not ok
                if ok:
                    rated.append(futures[future])
    except BaseException:
        _end_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True)
    failed += _map_again(rated)  # rated side by side: none saw the tracks written after it started
    warned = _warn_coverage(rated)
    return 2 if failed else warned


def _end_workers(pool: cf.ProcessPoolExecutor) -> None:
    """SIGTERM to every worker (each removes its temporary files and exits), the sessions not started
    cancelled; :meth:`~concurrent.futures.ProcessPoolExecutor.shutdown` then waits for them."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):  # terminate_workers() in 3.14
        if process.is_alive():
            process.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
