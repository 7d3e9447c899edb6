"""Write an imported heart-rate recording as a session folder, like a capture's.

``heart_rate.csv`` through :class:`~effortface.core.session.folder.HrWriter` (time 0 = the file's
first sample), ``session.json`` with ``devices.heart_rate`` = the device and producer named in the
file (``protocol`` = the file's kind, ``port`` = the file) and ``import`` = the file's name,
SHA-256, absolute start time and what it keeps (R-R or not), and an optional video with
``video_frames.csv``: frame k at ``video_offset_s + k / fps`` session seconds. The session is written
into a hidden folder beside its place and renamed into place at the end, so a failed import leaves
no session.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import secrets
import shutil
from pathlib import Path

from collections.abc import Mapping, Sequence

from effortface.capture_tool.importers.recording import HrImportError, HrRecording, to_samples
from effortface.core.opencv import import_cv2, index_video
from effortface.core.session.folder import (EVENTS_CSV, HEART_RATE_CSV, VIDEO_AVI, VIDEO_FRAMES_CSV, EventWriter,
                                             FrameTimeWriter, HrWriter, Participant, SessionInfo, create_session,
                                             make_session_id, utc_now_iso)
from effortface.core.fileio import file_sha256, fsync_folder
from effortface.core.version import __version__


def start_text(when: dt.datetime | None) -> str | None:
    """ISO 8601 of the start: ``...Z`` when the file's times are UTC, no zone when they are a watch's local time."""
    if when is None:
        return None
    if when.tzinfo is None:
        return when.isoformat(timespec="milliseconds")
    return when.astimezone(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def check_video(video: Path | None, video_offset_s: float | None) -> None:
    """HrImportError unless the video options make sense (checked before anything is read or written)."""
    if video is None:
        if video_offset_s is not None:
            raise HrImportError("--video-offset: expected --video FILE with it, found no --video")
        return
    if not video.is_file():
        raise HrImportError(f"--video {video}: expected a video file, found no such file")
    if video_offset_s is not None and not (math.isfinite(video_offset_s) and abs(video_offset_s) <= 86400):
        raise HrImportError(f"--video-offset: expected seconds within a day of the heart-rate start, "
                            f"found {video_offset_s:g}")


def copy_video(src: Path, dst: Path) -> None:
    """An AVI is copied as is; another container is re-encoded to MJPG AVI with OpenCV."""
    if src.suffix.lower() == ".avi":
        shutil.copyfile(src, dst)
        return
    cv2 = import_cv2()
    cap = cv2.VideoCapture(str(src))
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    writer = None
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        if writer is None:
            writer = cv2.VideoWriter(str(dst), cv2.VideoWriter.fourcc(*"MJPG"), fps, frame.shape[1::-1])
        writer.write(frame)
    cap.release()
    if writer is not None:
        writer.release()


def video_fps(video: Path) -> float:
    """The frame rate a video declares (HrImportError when it declares none)."""
    cv2 = import_cv2()
    cap = cv2.VideoCapture(str(video))
    fps = float(cap.get(cv2.CAP_PROP_FPS))
    cap.release()
    if not (math.isfinite(fps) and fps > 0):
        raise HrImportError(f"--video {video}: expected a video with a frame rate, found {fps:g}")
    return fps


def flash_offset(video: Path, flash_at_s: float) -> float:
    """``--video-offset`` from a flash: the first bright frame (:func:`first_flash_frame`) is at ``flash_at_s``.

    Raises
    ------
    HrImportError
        No frame brightens (one line naming the video).
    """
    from effortface.capture_tool.sync import MIN_STEP, first_flash_frame, video_brightness

    fps = video_fps(video)
    frame = first_flash_frame(video_brightness(video, 0, 10**7), fps)
    if frame is None:
        raise HrImportError(f"--video {video}: expected a flash (a frame {MIN_STEP:g} grey levels brighter than the "
                            "second before it) for --video-flash-at, found none")
    return flash_at_s - frame / fps


def import_info(rec: HrRecording) -> dict[str, object]:
    """The ``import`` block of ``session.json``."""
    return {"file": rec.path.name, "format": rec.kind, "sha256": file_sha256(rec.path),
            "start_time": start_text(rec.start_utc),
            "start_time_zone": "UTC" if rec.start_utc is not None and rec.start_utc.tzinfo else "unknown (device local time)",
            "samples": len(rec.t_s), "rr_kept": rec.has_rr, "laps": rec.laps}


def session_id_for(rec: HrRecording, code: str, label: str | None) -> str:
    """The session id of an imported file: the participant and the file's start (now, when it has none)."""
    stamp = rec.start_utc.replace(tzinfo=None) if rec.start_utc is not None else dt.datetime.now()
    return make_session_id(code, stamp, label)


def write_hr_session(rec: HrRecording, out_dir: str | os.PathLike, participant: Participant, *,
                     video: Path | None = None, video_offset_s: float | None = None,
                     label: str | None = None) -> Path:
    """Write ``rec`` as a new session folder in ``out_dir``; return it.

    Parameters
    ----------
    rec : HrRecording
        A recording read by :func:`effortface.capture_tool.importers.read_hr_file`.
    out_dir : path-like
        The lab folder.
    participant : Participant
        Who wore the device (resolved against the lab's registry by the caller).
    video : Path, optional
        A video recorded beside it; its frame k is at ``video_offset_s + k / fps`` seconds of the
        heart-rate file's time (default offset 0: the video started with the first sample).
    label : str, optional
        Appended to the session id.

    Raises
    ------
    HrImportError
        The session folder exists already (import again with ``--label``).
    """
    device = rec.device or rec.kind
    rows = to_samples(rec, device)
    info = SessionInfo(session_id=session_id_for(rec, participant.code, label), participant=participant,
                       devices={"heart_rate": {"protocol": rec.kind, "port": str(rec.path), "device": device,
                                               "producer": rec.producer}},
                       complete=False, created_utc=utc_now_iso(),
                       software={"name": "effortface", "version": __version__},
                       extra={"import": import_info(rec)})
    final = Path(out_dir) / info.session_id
    if final.exists():
        raise HrImportError(f"{rec.path}: expected a new session folder, found {final} (import it again with "
                            "--label)")
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    staging = Path(out_dir) / f".import-{secrets.token_hex(6)}.tmp"
    try:
        folder = create_session(staging, info)
        writer = HrWriter(folder / HEART_RATE_CSV)
        for row in rows:
            writer.write(row)
        writer.close()
        EventWriter(folder / EVENTS_CSV).close()
        if video is not None:
            _write_video(folder, video, video_offset_s or 0.0, info)
        info.complete = True
        info.save(folder, overwrite=True)
        os.rename(folder, final)
        fsync_folder(out_dir)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return final


def _write_video(folder: Path, video: Path, offset_s: float, info: SessionInfo) -> None:
    """Copy the video and write one frame time per decodable frame."""
    fps = video_fps(video)
    copy_video(video, folder / VIDEO_AVI)
    n_frames = index_video(folder / VIDEO_AVI)
    if n_frames == 0:
        raise HrImportError(f"--video {video}: expected a readable video, found no frame that decodes")
    writer = FrameTimeWriter(folder / VIDEO_FRAMES_CSV)
    for k in range(n_frames):
        writer.write(k, offset_s + k / fps)
    writer.close()
    info.devices["camera"] = {"source": str(video), "fps": fps, "offset_s": offset_s, "frames": n_frames}


def import_hr_files(paths: Sequence[str | os.PathLike], out_dir: str | os.PathLike, code: str,
                    options: Mapping[str, object], *, update: bool = False, label: str | None = None,
                    video: Path | None = None, video_offset_s: float | None = None,
                    video_flash_at_s: float | None = None, time_col: str | None = None,
                    hr_col: str | None = None, rr_col: str | None = None,
                    hint: str | None = None) -> list[Path]:
    """Import heart-rate files into the lab ``out_dir``, one session each (``import hr``, *Import heart rate...*).

    The participant is resolved as ``capture`` resolves it (the options completed from the lab's
    registry, a contradiction refused unless ``update``); every file is read and checked before any
    session is written; a new or changed participant is saved to the registry at the end.

    Parameters
    ----------
    paths : sequence of path-like
        The files.
    out_dir : path-like
        The lab folder.
    code : str
        Participant code.
    options : mapping
        Participant fields given (None: not given), as :func:`resolve_participant` takes them.
    update, label, video, video_offset_s, video_flash_at_s, time_col, hr_col, rr_col, hint
        As the command's options (``hint``: what a refusal tells the user to do; ``video_flash_at_s``:
        the heart-rate file's time of a flash filmed by the video, which then gives the offset).

    Returns
    -------
    list of Path
        The new session folders.

    Raises
    ------
    UserError
        One line: a bad file, a bad option, a participant refused.
    """
    from effortface.capture_tool.importers import read_hr_file
    from effortface.capture_tool.participants import REGISTRY_TSV, UPDATE_HINT, resolve_participant, save_participant

    check_video(video, video_offset_s)
    if video_flash_at_s is not None:
        if video is None or video_offset_s is not None:
            raise HrImportError("--video-flash-at: expected --video FILE and no --video-offset with it, found "
                                f"{'no --video' if video is None else '--video-offset too'}")
        if not (math.isfinite(video_flash_at_s) and abs(video_flash_at_s) <= 86400):
            raise HrImportError(f"--video-flash-at: expected seconds within a day of the heart-rate start, found "
                                f"{video_flash_at_s:g}")
    if video is not None and len(paths) != 1:
        raise HrImportError(f"--video: expected one heart-rate file with it, found {len(paths)}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise HrImportError(f"--out {out}: expected a lab folder, found a file")
    participant, new = resolve_participant(code, options, out / REGISTRY_TSV, update=update,
                                           hint=hint or UPDATE_HINT)
    recordings = [read_hr_file(p, time_col=time_col, hr_col=hr_col, rr_col=rr_col) for p in paths]
    if video is not None and video_flash_at_s is not None:
        video_offset_s = flash_offset(video, video_flash_at_s)
    ids = [session_id_for(rec, participant.code, label) for rec in recordings]
    for rec, sid in zip(recordings, ids):
        if ids.count(sid) > 1 or (out / sid).exists():
            raise HrImportError(f"{rec.path}: expected a new session folder, found {out / sid} "
                                f"{'already there' if (out / sid).exists() else 'named by another file too'} "
                                "(import it again with --label)")
    folders = [write_hr_session(rec, out, participant, video=video, video_offset_s=video_offset_s, label=label)
               for rec in recordings]
    if new:
        save_participant(out / REGISTRY_TSV, participant)
    return folders
