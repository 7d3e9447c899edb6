"""Rate every recorded frame of a session with the machine rater (``effortface preannotate``).

:func:`preannotate_session` decodes the session's ``video.avi`` frame by frame in order, runs
:class:`~effortface.annotate.machine.landmarker.FaceLandmarker` (MediaPipe's VIDEO mode: tracked from
frame to frame), maps the 52 scores to our four blendshapes (the effort mapping,
:mod:`effortface.annotate.machine.effort`, and the learned one where it wins held out,
:mod:`effortface.annotate.machine.learned`), calibrates them on the participant's human key-frames
where there are some (:mod:`effortface.annotate.machine.mapping`) and writes
``machine/face_landmarker.csv`` with its sidecar (:mod:`effortface.annotate.machine.track`).
Nothing is written until every frame is rated: a cancel, an error or Ctrl-C leaves the session as it was.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from effortface.annotate.machine.landmarker import DEFAULT_MODEL, FaceLandmarker, file_sha256
from effortface.annotate.machine.learned import Mapper, lab_mapping
from effortface.annotate.machine.mapping import Calibration, calibration_pairs, fit_calibration
from effortface.annotate.machine.track import (FOUR, SIDECAR_VERSION, MachineTrack, machine_paths, read_machine_track,
                                               write_machine_track)
from effortface.core.session.folder import (SESSION_JSON, VIDEO_AVI, VIDEO_FRAMES_CSV, check_not_recording,
                                             check_session, read_session_info)
from effortface.core.errors import UserError
from effortface.core.fileio import json_text
from effortface.core.jobs import Cancelled
from effortface.core.version import __version__

ENGINE = ("effortface's re-implementation of MediaPipe's Face Landmarker (VIDEO mode: one face, tracked) "
          "on the bundle's three .tflite models with ai-edge-litert")


def _cv2() -> Any:
    from effortface.core.opencv import import_cv2

    return import_cv2()


def check_rateable(session_dir: Path, *, force: bool = False) -> list[float]:
    """Refuse a session the rater cannot or must not rate; return its frame times.

    Raises
    ------
    UserError
        One line naming the file: not a session, being recorded, left incomplete, no video, a frame
        table that does not match the video, or a machine rating already there without ``force``.
    """
    folder = Path(session_dir)
    if not (folder / SESSION_JSON).is_file():
        raise UserError(f"{folder}: expected a session folder (with {SESSION_JSON}), found "
                        f"{'a folder without one' if folder.is_dir() else 'a file' if folder.exists() else 'nothing'}")
    check_not_recording(folder, "pre-annotate")
    info = read_session_info(folder)
    if not info.complete:
        raise UserError(f"{folder / SESSION_JSON}: expected a complete session, found complete is false "
                        f"(run 'effortface recover {folder}')")
    for name in (VIDEO_AVI, VIDEO_FRAMES_CSV):
        if not (folder / name).is_file():
            raise UserError(f"{folder / name}: expected the session's video, found nothing")
    session = check_session(folder)
    if not session.frame_times_s:
        raise UserError(f"{folder / VIDEO_FRAMES_CSV}: expected at least one frame, found none")
    csv_path, _ = machine_paths(folder)
    if csv_path.exists() and not force:
        raise UserError(f"{csv_path}: expected no machine rating yet, found one exists (use --force to replace it)")
    return session.frame_times_s


def frame_times_ms(frame_times_s: list[float] | np.ndarray) -> np.ndarray:
    """Whole, strictly increasing milliseconds from frame times (the timestamps of MediaPipe's VIDEO mode)."""
    ms = np.round(np.asarray(frame_times_s, dtype=float) * 1000.0).astype(np.int64)
    for i in range(1, len(ms)):
        ms[i] = max(ms[i], ms[i - 1] + 1)
    return ms


def rate_video(video: Path, frame_times_s: list[float] | np.ndarray, landmarker: FaceLandmarker, *,
               progress: Callable[[int, int], None] | None = None,
               cancel: Callable[[], bool] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rate the frames of a video in order, one per frame time (``video_frames.csv``).

    Returns
    -------
    face : numpy.ndarray
        (n,) bool.
    scores : numpy.ndarray
        (n, 52), NaN where no face.

    Raises
    ------
    UserError
        When the video cannot be opened or a frame does not decode (naming the file and the frame).
    Cancelled
        When ``cancel()`` turns true.
    """
    cv2 = _cv2()
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise UserError(f"{video}: expected an MJPG video OpenCV can decode, found an unreadable file")
    timestamps_ms = frame_times_ms(frame_times_s)
    n_frames = len(timestamps_ms)
    face = np.zeros(n_frames, dtype=bool)
    scores = np.full((n_frames, 52), np.nan)
    landmarker.reset()
    try:
        for i in range(n_frames):
            if cancel is not None and cancel():
                raise Cancelled(f"{video}: pre-annotation cancelled at frame {i}")
            ok, bgr = cap.read()
            if not ok or bgr is None:
                raise UserError(f"{video}: expected {n_frames} frames (video_frames.csv), found frame {i} does not "
                                f"decode (a damaged video)")
            result = landmarker.process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), float(timestamps_ms[i]))
            if result.face and result.scores is not None:
                face[i] = True
                scores[i] = result.scores
            if progress is not None:
                progress(i + 1, n_frames)
    finally:
        cap.release()
    return face, scores


def _versions() -> dict[str, str]:
    out = {"effortface": __version__}
    for dist in ("ai-edge-litert", "numpy", "opencv-contrib-python-headless", "scikit-learn"):
        try:
            out[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def _runs(frames: np.ndarray) -> list[list[int]]:
    """Consecutive frame numbers as inclusive [first, last] runs."""
    runs: list[list[int]] = []
    for f in (int(x) for x in frames):
        if runs and f == runs[-1][1] + 1:
            runs[-1][1] = f
        else:
            runs.append([f, f])
    return runs


def _sibling_tracks(session_dir: Path, participant: str, mapper: Mapper) -> list[tuple[Path, np.ndarray, np.ndarray]]:
    """(folder, frames, raw mapped scores) of the participant's other sessions already rated by the machine."""
    from effortface.annotate.machine.learned import lab_tracks

    return [(other, track.frame, mapper(other, track.scores, track.t_s))
            for other, code, track in lab_tracks(session_dir) if code == participant]


def calibrate(session_dir: Path, participant: str, frames: np.ndarray, raw: np.ndarray,
              mapper: Mapper) -> Calibration:
    """The participant's calibration from this session's keys and those of their other machine-rated sessions."""
    sessions = [(session_dir, frames, raw), *_sibling_tracks(session_dir, participant, mapper)]
    x, y = calibration_pairs(sessions, FOUR)
    return fit_calibration(participant, x, y, FOUR)


def mapped_weights(session_dir: Path, frames: np.ndarray, t_s: np.ndarray,
                   scores: np.ndarray) -> tuple[np.ndarray, dict[str, Any], Calibration]:
    """A session's four weights from its 52 scores: the lab's mapping, then the participant's calibration.

    Both look at the lab's other machine tracks as they are on disk now (:func:`lab_mapping`, :func:`calibrate`).

    Returns
    -------
    weights : numpy.ndarray
        (n, 4) in :data:`FOUR` order, NaN where no face.
    mapping : dict
        The sidecar's ``mapping`` block.
    calibration : Calibration
        The participant's calibration (the sidecar's ``calibration`` block is its ``to_dict()``).
    """
    participant = read_session_info(session_dir).participant.code
    raw, mapping, mapper = lab_mapping(Path(session_dir), participant, scores, t_s)
    calibration = calibrate(Path(session_dir), participant, frames, raw, mapper)
    return calibration.apply(raw, FOUR), mapping, calibration


def remap_session(session_dir: Path) -> bool:
    """Map and calibrate a machine-rated session again from its stored scores; True when that changed it.

    A session rated before the others of the same run did not see their tracks: its learned mapping and
    its participant's calibration are fitted again with every track now beside it (what a second
    ``preannotate --force`` gives, without rating the video again; the scores are those of the CSV, to
    6 significant digits). The track is rewritten (both files together) only when its ``mapping`` or
    ``calibration`` block changes; the rest of its sidecar is kept.

    Raises
    ------
    UserError
        When the session has no machine track, or it cannot be read (one line naming the file).
    """
    folder = Path(session_dir)
    track = read_machine_track(folder)
    if track is None:
        raise UserError(f"{machine_paths(folder)[0]}: expected a machine rating to map again, found none")
    weights, mapping, calibration = mapped_weights(folder, track.frame, track.t_s, track.scores)
    new = {**track.sidecar, "mapping": mapping, "calibration": calibration.to_dict()}
    if _as_json(new) == _as_json(track.sidecar):
        return False
    write_machine_track(folder, dataclasses.replace(track, weights=weights, sidecar=new), force=True)
    return True


def _as_json(value: Any) -> str:
    """``value`` as the sidecar file holds it (tuples as lists, keys sorted), numbers to 4 decimals: for
    comparing (the scores read back from the CSV have 6 significant digits)."""
    def rounded(v: Any) -> Any:
        if isinstance(v, float):
            return round(v, 4)
        if isinstance(v, dict):
            return {k: rounded(x) for k, x in v.items()}
        return [rounded(x) for x in v] if isinstance(v, list) else v
    return json.dumps(rounded(json.loads(json_text(value))), sort_keys=True)


def preannotate_session(session_dir: Path, *, model_path: Path | None = None, force: bool = False,
                        progress: Callable[[int, int], None] | None = None,
                        cancel: Callable[[], bool] | None = None, num_threads: int | None = None) -> Path:
    """Rate every frame of ``video_frames.csv`` and write ``machine/face_landmarker.csv``; return its path.

    Parameters
    ----------
    session_dir : Path
        A complete session with video, not being recorded.
    model_path : Path, optional
        A ``face_landmarker.task`` bundle; the shipped one when None.
    force : bool
        Replace an existing machine rating.
    progress : callable, optional
        ``progress(frames_done, frames_total)`` after each frame.
    cancel : callable, optional
        Polled before each frame; when it returns True the rating stops and nothing is written.
    num_threads : int, optional
        Interpreter threads; by default the machine's cores (up to 4). Sessions rated in parallel
        processes share the cores out instead.

    Raises
    ------
    UserError
        One line naming the file (see :func:`check_rateable`, :func:`rate_video`).
    Cancelled
        When ``cancel()`` turned true (nothing written).
    """
    folder = Path(session_dir)
    frame_times_s = check_rateable(folder, force=force)
    model = Path(model_path) if model_path is not None else DEFAULT_MODEL
    started = time.perf_counter()
    threads = num_threads if num_threads is not None else max(1, min(4, os.cpu_count() or 1))
    landmarker = FaceLandmarker(model, num_threads=threads)
    face, scores = rate_video(folder / VIDEO_AVI, frame_times_s, landmarker, progress=progress, cancel=cancel)
    taken_s = time.perf_counter() - started
    frames = np.arange(len(frame_times_s))
    weights, mapping, calibration = mapped_weights(folder, frames, np.asarray(frame_times_s, dtype=float), scores)
    sidecar = {
        "format_version": SIDECAR_VERSION,
        "rater": "machine (MediaPipe Face Landmarker)",
        "engine": ENGINE,
        "model": {"file": model.name, "sha256": file_sha256(model), "shipped": model.resolve() == DEFAULT_MODEL,
                  "licence": "Apache-2.0 (Google MediaPipe)"},
        "software": _versions(),
        "mapping": mapping,
        "calibration": calibration.to_dict(),
        "frames": int(len(frames)),
        "frames_with_face": int(face.sum()),
        "frames_without_face": int((~face).sum()),
        "frames_without_face_runs": _runs(frames[~face]),
        "interpreter_threads": threads,
        "time_taken_s": round(taken_s, 3),
        "frames_per_s": round(len(frames) / taken_s, 1) if taken_s > 0 else None,
    }
    track = MachineTrack(frame=frames, t_s=np.asarray(frame_times_s, dtype=float), face=face, weights=weights,
                         scores=scores, sidecar=sidecar)
    if cancel is not None and cancel():
        raise Cancelled(f"{folder}: pre-annotation cancelled before writing")
    return write_machine_track(folder, track, force=force)


__all__ = ["preannotate_session", "check_rateable", "rate_video", "calibrate", "mapped_weights", "remap_session"]
