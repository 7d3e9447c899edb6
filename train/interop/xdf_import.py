"""XDF in: a LabRecorder recording -> a session folder (``effortface import xdf``).

Streams are chosen by type or name (:func:`pick_stream`): the heart-rate stream (default type
``HeartRate``; channels ``hr_bpm`` and ``rr_ms`` by label, or one channel taken as ``hr_bpm``; samples
sharing a time stamp form one ``heart_rate.csv`` row, as ``capture --lsl`` publishes them), every
marker stream (type ``Markers``; effortface's JSON markers keep their kind, label and value, other
strings become ``marker`` events), an optional ``EffortWork`` stream (-> ``work.csv``), an optional
mocap stream (channels ``<joint>_x``, ``_y``, ``_z`` -> ``motion/mocap.csv``, a joint-positions CSV),
and a video file given beside it with its frame times: a stream with one sample per frame
(``--video-stream``), or the LSL time of its first frame (``--video-offset``) and its frame rate.

Session time 0 is the earliest time stamp of the imported streams; ``session.json`` keeps
``lsl.clock_offset_s`` (``lsl_time = t_s + clock_offset_s``) as a capture with ``--lsl`` does.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.capture_tool.protocols import HrSample
from effortface.capture_tool.session import (EVENTS_CSV, HEART_RATE_CSV, VIDEO_AVI, VIDEO_FRAMES_CSV, Event,
                                             EventWriter, FrameTimeWriter, HrWriter, Participant, SessionInfo,
                                             create_session, make_session_id, utc_now_iso)
from effortface.core.errors import UserError
from effortface.core.opencv import import_cv2
from effortface.core.fileio import atomic_write_text
from effortface.core.version import __version__

XdfStream = dict[str, Any]


class XdfImportError(UserError):
    """A stream is missing or ambiguous, or a file cannot be read; the message names it."""


def load_xdf(path: str | os.PathLike) -> list[XdfStream]:
    """The streams of an XDF file (pyxdf, clock offsets applied)."""
    import pyxdf  # lazy: only the importer needs it

    path = Path(path)
    if not path.is_file():
        raise XdfImportError(f"{path}: expected an XDF file, found {'a folder' if path.is_dir() else 'no such file'}")
    log = logging.getLogger("pyxdf")
    level = log.level
    log.setLevel(logging.ERROR)  # its per-stream notes would break the one-line error rule
    try:
        streams, _ = pyxdf.load_xdf(str(path), dejitter_timestamps=False)
    except Exception as exc:  # pyxdf raises bare Exceptions on a damaged file
        raise XdfImportError(f"{path}: expected an XDF file, found {type(exc).__name__}: {exc}") from None
    finally:
        log.setLevel(level)
    return streams


def _field(stream: XdfStream, key: str) -> str:
    return str((stream["info"].get(key) or [""])[0])


def describe(streams: Sequence[XdfStream]) -> str:
    """``name (type), ...`` of the streams, for messages."""
    return ", ".join(f"{_field(s, 'name')!r} ({_field(s, 'type')})" for s in streams) or "no streams"


def find_stream(path: Path, streams: Sequence[XdfStream], wanted: str | None, default_type: str,
                option: str) -> XdfStream | None:
    """The one stream whose name or type is ``wanted`` (default: of type ``default_type``), or None.

    Raises
    ------
    XdfImportError
        Several match (naming them and the option that chooses).
    """
    key = wanted or default_type
    found = [s for s in streams if key in (_field(s, "name"), _field(s, "type"))] if wanted else \
        [s for s in streams if _field(s, "type") == default_type]
    if len(found) > 1:
        raise XdfImportError(f"{path}: expected one stream named or typed {key!r}, found {len(found)}: "
                             f"{describe(found)} (choose one by name with {option})")
    return found[0] if found else None


def pick_stream(path: Path, streams: Sequence[XdfStream], wanted: str | None, default_type: str,
                option: str) -> XdfStream:
    """Like :func:`find_stream`, but none found is an error naming the streams there are."""
    found = find_stream(path, streams, wanted, default_type, option)
    if found is None:
        raise XdfImportError(f"{path}: expected a stream named or typed {wanted or default_type!r} ({option}), "
                             f"found {describe(streams)}")
    return found


def channel_labels(stream: XdfStream) -> list[str]:
    """Channel labels from the stream description (empty strings where none)."""
    n = int(_field(stream, "channel_count") or 0)
    try:
        chans = stream["info"]["desc"][0]["channels"][0]["channel"]
        labels = [str((c.get("label") or [""])[0]) for c in chans]
    except (KeyError, IndexError, TypeError):
        labels = []
    return labels if len(labels) == n else [""] * n


def _samples(stream: XdfStream) -> tuple[np.ndarray, Any]:
    return np.asarray(stream["time_stamps"], dtype=float), stream["time_series"]


def hr_rows(path: Path, stream: XdfStream, t0: float) -> list[HrSample]:
    """``heart_rate.csv`` rows: samples sharing a time stamp make one row (their R-R intervals)."""
    labels = channel_labels(stream)
    stamps, values = _samples(stream)
    values = np.asarray(values, dtype=float).reshape(len(stamps), -1)
    hr_col = labels.index("hr_bpm") if "hr_bpm" in labels else 0
    rr_col = labels.index("rr_ms") if "rr_ms" in labels else None
    device = _field(stream, "name") or "xdf"
    rows: list[HrSample] = []
    for stamp in np.unique(stamps):
        group = values[stamps == stamp]
        hr = float(group[0, hr_col])
        rr = tuple(float(v) for v in group[:, rr_col] if math.isfinite(v)) if rr_col is not None else ()
        ok = math.isfinite(hr) and hr > 0
        rows.append(HrSample(round(stamp - t0, 4), hr if ok else None, rr, None, device, ok))
    if not rows:
        raise XdfImportError(f"{path}: stream {device!r}: expected heart-rate samples, found none")
    return rows


def marker_events(stream: XdfStream, t0: float) -> list[Event]:
    """Events of a marker stream (effortface JSON markers keep kind, label, value)."""
    stamps, values = _samples(stream)
    out = []
    for stamp, sample in zip(stamps, values):
        text = str(sample[0])
        try:
            doc = json.loads(text)
            event = Event(stamp - t0, str(doc["kind"]), str(doc.get("label", "")), str(doc.get("value", "")))
        except (ValueError, KeyError, TypeError):
            event = Event(stamp - t0, "marker", text, "")
        out.append(event)
    return out


def _write_work(folder: Path, stream: XdfStream, t0: float) -> None:
    labels = channel_labels(stream)
    stamps, values = _samples(stream)
    values = np.asarray(values, dtype=float).reshape(len(stamps), -1)
    cols = [labels.index(c) if c in labels else i for i, c in enumerate(("w_per_kg", "p_per_kg"))]
    lines = ["t_s,w_per_kg,p_per_kg"] + [f"{t - t0:.4f},{v[cols[0]]:.6g},{v[cols[1]]:.6g}"
                                         for t, v in zip(stamps, values)]
    atomic_write_text(folder / "work.csv", "\n".join(lines) + "\n")


def _write_mocap(path: Path, folder: Path, stream: XdfStream, t0: float) -> None:
    from effortface.train.motion_csv import csv_header

    labels = channel_labels(stream)
    joints = [lab[:-2] for lab in labels[::3]]
    if not joints or any(labels[3 * i:3 * i + 3] != [f"{j}_x", f"{j}_y", f"{j}_z"] for i, j in enumerate(joints)):
        raise XdfImportError(f"{path}: mocap stream {_field(stream, 'name')!r}: expected channel labels "
                             f"<joint>_x, <joint>_y, <joint>_z, found {labels[:6]}")
    stamps, values = _samples(stream)
    (folder / "motion").mkdir(exist_ok=True)
    rows = [",".join(csv_header(joints))] + [",".join(f"{x:.9g}" for x in [t - t0, *v])
                                             for t, v in zip(stamps, np.asarray(values, float))]
    atomic_write_text(folder / "motion" / "mocap.csv", "\n".join(rows) + "\n")


def _frame_times(path: Path, streams: Sequence[XdfStream], video: Path, video_stream: str | None,
                 video_offset_s: float | None) -> np.ndarray:
    """LSL times of the video's frames: from a stream (one sample per frame) or an offset + fps."""
    cv2 = import_cv2()  # lazy: only with a video (OpenCV log silenced)

    cap = cv2.VideoCapture(str(video))
    n_frames, fps = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), float(cap.get(cv2.CAP_PROP_FPS))
    cap.release()
    if n_frames <= 0:
        raise XdfImportError(f"--video {video}: expected a readable video, found no frames")
    if video_stream is not None:
        stream = pick_stream(path, streams, video_stream, "VideoFrames", "--video-stream")
        stamps = _samples(stream)[0]
        if len(stamps) < n_frames:
            raise XdfImportError(f"--video-stream {video_stream}: expected one sample per frame ({n_frames}), "
                                 f"found {len(stamps)}")
        return stamps[:n_frames]
    if video_offset_s is None:
        raise XdfImportError(f"--video {video}: expected its frame times, --video-stream NAME or "
                             "--video-offset S, found neither")
    return video_offset_s + np.arange(n_frames) / fps


def import_xdf(path: str | os.PathLike, out_dir: str | os.PathLike, participant: Participant, *,
               hr_stream: str | None = None, marker_streams: Sequence[str] = (),
               work_stream: str | None = None, mocap_stream: str | None = None,
               video: str | os.PathLike | None = None, video_stream: str | None = None,
               video_offset_s: float | None = None, label: str | None = None) -> Path:
    """Turn an XDF recording into a new session folder in ``out_dir``; return it.

    Parameters
    ----------
    path : path-like
        The ``.xdf`` file.
    out_dir : path-like
        Folder that receives the session folder (never reused).
    participant : Participant
        Who was recorded.
    hr_stream : str, optional
        Name or type of the heart-rate stream (default: the one of type ``HeartRate``).
    marker_streams : sequence of str
        Names or types of marker streams (default: every stream of type ``Markers``).
    work_stream, mocap_stream : str, optional
        Name or type of an ``EffortWork`` stream (default: one of that type if present) and of a
        mocap stream (none by default).
    video : path-like, optional
        The video recorded beside it; ``video_stream`` (one sample per frame) or ``video_offset_s``
        (LSL time of frame 0) gives its frame times.
    label : str, optional
        Appended to the session id.

    Raises
    ------
    XdfImportError
        Missing or ambiguous streams, unreadable files (one line each).
    """
    path = Path(path)
    streams = load_xdf(path)
    hr = pick_stream(path, streams, hr_stream, "HeartRate", "--hr-stream")
    markers = ([pick_stream(path, streams, m, "Markers", "--marker-stream") for m in marker_streams]
               or [s for s in streams if _field(s, "type") == "Markers"])
    work = (pick_stream if work_stream else find_stream)(path, streams, work_stream, "EffortWork", "--work-stream")
    mocap = pick_stream(path, streams, mocap_stream, "MoCap", "--mocap-stream") if mocap_stream else None
    video_path = Path(video) if video is not None else None
    if video_path is not None and not video_path.is_file():
        raise XdfImportError(f"--video {video_path}: expected a video file, found no such file")
    frames = _frame_times(path, streams, video_path, video_stream, video_offset_s) if video_path else None
    used = [s for s in (hr, *markers, work, mocap) if s is not None]
    t0 = min(float(_samples(s)[0][0]) for s in used if len(_samples(s)[0]))
    if frames is not None:
        t0 = min(t0, float(frames[0]))
    info = SessionInfo(session_id=make_session_id(participant.code, _dt.datetime.now(), label),
                       participant=participant, devices={"heart_rate": {"device": _field(hr, "name"),
                                                                         "protocol": "lsl", "port": str(path)}},
                       complete=False, created_utc=utc_now_iso(),
                       software={"name": "effortface", "version": __version__},
                       extra={"lsl": {"clock_offset_s": t0, "imported_from": path.name,
                                      "streams": [_field(s, "name") for s in used]}})
    folder = create_session(out_dir, info)
    _write_rows(HrWriter(folder / HEART_RATE_CSV), hr_rows(path, hr, t0))
    events = sorted((e for m in markers for e in marker_events(m, t0)), key=lambda e: e.t_s)
    _write_rows(EventWriter(folder / EVENTS_CSV), events)
    if work is not None:
        _write_work(folder, work, t0)
    if mocap is not None:
        _write_mocap(path, folder, mocap, t0)
    if video_path is not None and frames is not None:
        _copy_video(video_path, folder / VIDEO_AVI)
        writer = FrameTimeWriter(folder / VIDEO_FRAMES_CSV)
        for k, stamp in enumerate(frames):
            writer.write(k, float(stamp - t0))
        writer.close()
    info.complete = True
    info.save(folder, overwrite=True)
    return folder


def _write_rows(writer: Any, rows: Sequence[Any]) -> None:
    for row in rows:
        writer.write(row)
    writer.close()


def _copy_video(src: Path, dst: Path) -> None:
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
