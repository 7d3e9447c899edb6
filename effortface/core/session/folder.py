"""The session folder (schema version 1): the one reader and writer every stage uses.

A session is a folder named ``<participant-code>_<YYYYmmdd-HHMMSS>[_<label>]`` holding::

    session.json              schema_version, session_id, complete, created_utc, participant,
                              devices, software, optional recovered / stats
    heart_rate.csv            t_s,hr_bpm,rr_ms,beat_count,device,valid   (effortface.core.session.hr_csv)
    events.csv                t_s,kind,label,value
    serial/<device>.serlog    every raw byte received (effortface.capture_tool.serlog)
    video.avi                 MJPG video
    video_frames.csv          frame,t_s

All ``t_s`` are seconds since the session start on the host's monotonic clock. This module is
pandas-free on purpose: annotate, train and the sample-lab generator import it cheaply.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import errno
import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

from effortface.core import bounds
from effortface.core.errors import SessionFormatError, UserError, json_type, not_text_error
from effortface.core.fileio import check_regular_file, naming, read_json, refuse_overwrite, write_json_atomic  # noqa: F401  (re-exported for callers)
# The participant record lives in the core (one limits table for every stage); re-exported here.
from effortface.core.participant import (CODE_PATTERN, CODE_RULE, LIMITS, SEX_ALIASES,  # noqa: F401
                                         SEXES, Participant, check_participant_code)
from effortface.core.locks import FileLock, LockedError, acquire_lock, describe_owner, lock_owner
from effortface.core.session.hr_csv import HR_CSV_HEADER, format_hr_row, read_hr_csv
from effortface.core.hr_sample import HrSample

SCHEMA_VERSION = 1
SESSION_JSON = "session.json"
HEART_RATE_CSV = "heart_rate.csv"
EVENTS_CSV = "events.csv"
VIDEO_AVI = "video.avi"
VIDEO_FRAMES_CSV = "video_frames.csv"
SERIAL_DIR = "serial"
EVENTS_HEADER = "t_s,kind,label,value"
FRAMES_HEADER = "frame,t_s"
#: held (``fcntl.flock``) by the recorder while it records; names its owner (effortface.core.locks)
RECORDING_LOCK = ".recording.lock"

_LABEL_RE = re.compile(r"[A-Za-z0-9-]{1,32}")  # used with fullmatch (a final newline never matches)
_ID_RE = re.compile(rf"(?P<code>{CODE_PATTERN})_(?P<stamp>\d{{8}}-\d{{6}})(?:_(?P<label>[A-Za-z0-9-]{{1,32}}))?")
_STAMP_FMT = "%Y%m%d-%H%M%S"
#: ``{field: (lo, hi)}`` of :data:`effortface.core.participant.LIMITS` (kept for callers).
PARTICIPANT_RANGES = {name: limit.bounds for name, limit in LIMITS.items()}


# ------------------------------------------------------------------------------------ session id
def make_session_id(code: str, when: _dt.datetime, label: str | None = None) -> str:
    """Return ``<code>_<YYYYmmdd-HHMMSS>[_<label>]``.

    Parameters
    ----------
    code : str
        Participant code.
    when : datetime
        Session start (local wall-clock time of the lab).
    label : str, optional
        Letters, digits and '-' only (e.g. ``treadmill``).
    """
    check_participant_code(code)
    sid = f"{code}_{when.strftime(_STAMP_FMT)}"
    if label:
        if not _LABEL_RE.fullmatch(label):
            raise UserError(f"session label: expected 1-32 letters, digits or '-', found {label!r}")
        sid += f"_{label}"
    return sid


def parse_session_id(session_id: str) -> tuple[str, _dt.datetime, str | None]:
    """Split a session id into ``(code, start time, label or None)``; UserError if malformed."""
    m = _ID_RE.fullmatch(session_id)
    if not m:
        raise UserError(
            f"session id: expected <code>_<YYYYmmdd-HHMMSS>[_<label>], found {session_id!r}"
        )
    return m["code"], _dt.datetime.strptime(m["stamp"], _STAMP_FMT), m["label"]


#: the highest suffix tried for a session id already taken (``_2`` up to ``_99``)
MAX_SESSION_SUFFIX = 99
#: ``session.json`` key naming the session id a suffixed session wanted (the folder that existed)
ID_TAKEN_KEY = "session_id_taken"


def free_session_id(out_dir: str | os.PathLike, session_id: str) -> str:
    """``session_id``, or its first suffixed form with no folder in ``out_dir`` when a folder has it.

    Two sessions of one participant started in the same second (two imports, two captures) want the
    same folder: the second gets ``_2`` (``P01_20260112-093000_2``), or ``-2`` after its label
    (``P01_20260112-093000_bike-2``), then 3, 4...: a valid session id either way.

    Raises
    ------
    UserError
        When the id and its :data:`MAX_SESSION_SUFFIX` suffixed forms are all taken.
    """
    out = Path(out_dir)
    if not _taken(out / session_id):
        return session_id
    code, when, label = parse_session_id(session_id)
    for n in range(2, MAX_SESSION_SUFFIX + 1):
        tail = f"-{n}" if label else str(n)
        candidate = make_session_id(code, when, f"{(label or '')[:32 - len(tail)]}{tail}")
        if not _taken(out / candidate):
            return candidate
    raise UserError(f"{out / session_id}: expected a free session folder name, found it and its suffixes up to "
                    f"{MAX_SESSION_SUFFIX} taken")


def _taken(path: Path) -> bool:
    return path.exists() or path.is_symlink()


def move_session_in(folder: str | os.PathLike, out_dir: str | os.PathLike, info: SessionInfo) -> Path:
    """Rename a finished session folder (built in a staging folder) into ``out_dir`` under a free id.

    When ``info.session_id`` is taken, or taken while renaming (another import the same second), the
    session gets :func:`free_session_id`'s suffix, its ``session.json`` saying so (:data:`ID_TAKEN_KEY`)
    before it appears; a folder is never replaced.

    Returns
    -------
    Path
        The session folder in ``out_dir``.
    """
    out, wanted = Path(out_dir), info.extra.get(ID_TAKEN_KEY, info.session_id)
    while True:
        sid = free_session_id(out, info.session_id)
        if sid != info.session_id:
            info.session_id = sid
            info.extra[ID_TAKEN_KEY] = wanted
            info.save(folder, overwrite=True)
        try:
            os.rename(folder, out / sid)  # refused (ENOTEMPTY/EEXIST) if another session took the name meanwhile
        except OSError as exc:
            if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY):
                raise
            continue
        return out / sid


def id_taken_note(folder: str | os.PathLike) -> str | None:
    """The line stating a session's suffix (:func:`move_session_in`), or None when it has its own id."""
    info = read_session_info(folder)
    wanted = info.extra.get(ID_TAKEN_KEY)
    if not isinstance(wanted, str):
        return None
    return (f"note: a session folder {wanted} exists already (a session of {info.participant.code} started "
            f"the same second): this one is {info.session_id}")


# ---------------------------------------------------------------------------------- session.json
@dataclasses.dataclass
class SessionInfo:
    """The content of ``session.json``.

    Attributes
    ----------
    session_id : str
        Folder name, see :func:`make_session_id`.
    participant : Participant
    devices : dict
        ``{"heart_rate": {protocol, port, settings...}, "camera": {source, width, height, fps, codec}}``.
    complete : bool
        False until a clean stop (or :func:`effortface.capture_tool.recorder.recover_session`).
    created_utc : str
        ISO 8601 UTC time of creation.
    software : dict
        ``{"name": "effortface", "version": ...}``.
    extra : dict
        Other top-level keys (``stats``, ``recovered``...), kept on a round trip.
    """

    session_id: str
    participant: Participant
    devices: dict[str, Any] = dataclasses.field(default_factory=dict)
    complete: bool = False
    created_utc: str = ""
    software: dict[str, Any] = dataclasses.field(default_factory=dict)
    extra: dict[str, Any] = dataclasses.field(default_factory=dict)
    schema_version: int = SCHEMA_VERSION

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict in the order of DESIGN.md."""
        out: dict[str, Any] = {
            "schema_version": self.schema_version,
            "session_id": self.session_id,
            "complete": self.complete,
            "created_utc": self.created_utc,
            "participant": self.participant.to_dict(),
            "devices": self.devices,
            "software": self.software,
        }
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str | os.PathLike = SESSION_JSON) -> SessionInfo:
        """Build from a parsed ``session.json``; SessionFormatError naming ``source`` if invalid."""
        missing = [k for k in ("schema_version", "session_id", "complete", "participant") if k not in data]
        if missing:
            raise SessionFormatError(f"{source}: expected keys {missing}, found {sorted(data)}")
        if isinstance(data["schema_version"], bool) or data["schema_version"] != SCHEMA_VERSION:
            raise SessionFormatError(
                f"{source}: expected schema_version {SCHEMA_VERSION}, found {data['schema_version']!r}"
            )
        try:
            participant = Participant.from_dict(data["participant"])
        except (UserError, TypeError, ValueError, OverflowError) as exc:  # Overflow: an integer beyond float
            raise SessionFormatError(f"{source}: {exc}") from None
        if not isinstance(data["complete"], bool):
            raise SessionFormatError(f"{source}: field 'complete': expected true or false, "
                                     f"found {json_type(data['complete'])}")
        known = {"schema_version", "session_id", "complete", "created_utc", "participant", "devices", "software"}
        _check_numbers(data, source)
        return cls(
            session_id=str(data["session_id"]),
            participant=participant,
            devices=_object_field(data, "devices", source),
            complete=data["complete"],
            created_utc=str(data.get("created_utc", "")),
            software=_object_field(data, "software", source),
            extra={k: v for k, v in data.items() if k not in known},
        )

    def save(self, folder: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write ``folder/session.json`` atomically (temp file + ``os.replace``).

        Parameters
        ----------
        folder : path-like
            The session folder.
        overwrite : bool
            Replace an existing ``session.json`` (the recorder does, to update ``complete``).

        Raises
        ------
        FileExistsError
            If the file exists and ``overwrite`` is False.
        """
        path = refuse_overwrite(Path(folder) / SESSION_JSON, overwrite=overwrite, what=SESSION_JSON)
        write_json_atomic(path, self.to_dict())
        return path


def _check_numbers(data: dict[str, Any], source: str | os.PathLike) -> None:
    """Refuse absurd numbers ``session.json`` carries, naming the field (issue 29).

    ``devices.camera.fps`` must lie within ``BOUNDS["fps"]`` and its width and height be counts;
    every number in ``stats`` (frames, drops, bytes...) must be a count (finite, 0 or more).

    Raises
    ------
    SessionFormatError
        ``'<source>: field 'stats.video_frames': expected a number from 0 to 1e+15, found -7'``.
    """
    camera = data.get("devices", {}).get("camera") if isinstance(data.get("devices"), dict) else None
    checks: list[tuple[str, str, object]] = []
    if isinstance(camera, dict):
        checks += [("fps", "devices.camera.fps", camera["fps"])] if "fps" in camera else []
        checks += [("count", f"devices.camera.{k}", camera[k]) for k in ("width", "height") if k in camera]
    stats = data.get("stats")
    if isinstance(stats, dict):
        checks += [("count", f"stats.{k}", v) for k, v in stats.items()
                   if isinstance(v, (int, float)) and not isinstance(v, bool)]
    for name, field, value in checks:
        try:
            bounds.check(name, value, f"{source}: field {field!r}")
        except UserError as exc:
            raise SessionFormatError(str(exc)) from None


def _object_field(data: dict[str, Any], key: str, source: str | os.PathLike) -> dict[str, Any]:
    """``data[key]`` as a dict ({} when absent or null); SessionFormatError naming ``source`` otherwise.

    Parameters
    ----------
    data : dict
        The parsed ``session.json``.
    key : str
        The field, e.g. ``"devices"``.
    source : path-like
        The file, for the message.

    Returns
    -------
    dict
        A copy of the field.
    """
    value = data.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise SessionFormatError(f"{source}: field {key!r}: expected a JSON object, found {json_type(value)}")
    return dict(value)


def read_session_info(folder: str | os.PathLike) -> SessionInfo:
    """Read ``folder/session.json``.

    Raises
    ------
    SessionFormatError
        If ``folder`` is a file, ``session.json`` is missing, a folder or not JSON, or it does not
        follow schema version 1 (a field of the wrong JSON type is named).
    """
    path = Path(folder) / SESSION_JSON
    if Path(folder).exists() and not Path(folder).is_dir():
        raise SessionFormatError(f"{folder}: expected a session folder, found a file")
    if path.is_dir():
        raise SessionFormatError(f"{path}: expected a session.json file, found a folder")
    if not path.exists():
        raise SessionFormatError(f"{path}: expected a session.json in the session folder, found none")
    data = read_json(path, "JSON (session.json)", SessionFormatError)
    if not isinstance(data, dict):
        raise SessionFormatError(f"{path}: expected a JSON object, found {type(data).__name__}")
    return SessionInfo.from_dict(data, path)


def create_session(out_dir: str | os.PathLike, info: SessionInfo) -> Path:
    """Create the session folder ``out_dir/<session_id>`` with its ``session.json`` and ``serial/``.

    Raises
    ------
    FileExistsError
        If the folder exists already: a session folder is never reused.
    """
    return create_recording_session(out_dir, info, lock=False)[0]


def create_recording_session(out_dir: str | os.PathLike, info: SessionInfo,
                             *, lock: bool = True) -> tuple[Path, FileLock | None]:
    """Create the session folder as :func:`create_session` does, holding its recording lock.

    The lock (:data:`RECORDING_LOCK`) is taken before ``session.json`` exists, so no program ever
    sees the new session unlocked while it is being recorded.

    Returns
    -------
    (Path, FileLock or None)
        The folder, and the lock to release when the recording stops (None if ``lock`` is False).

    Raises
    ------
    FileExistsError
        If the folder exists already.
    """
    folder = Path(out_dir) / info.session_id
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    folder.mkdir(exist_ok=False)
    held = acquire_lock(folder / RECORDING_LOCK, "capture") if lock else None
    try:
        (folder / SERIAL_DIR).mkdir()
        info.save(folder)
    except BaseException:
        if held is not None:
            held.release()
        raise
    return folder, held


# ------------------------------------------------------------------------------------ csv files
@dataclasses.dataclass(frozen=True)
class Event:
    """One row of ``events.csv``: time, kind (``phase_start``, ``marker``, ``gap``...), label, value."""

    t_s: float
    kind: str
    label: str = ""
    value: str = ""


class _LineWriter:
    """Append-only CSV-ish text writer that refuses to overwrite and can flush on demand."""

    def __init__(self, path: str | os.PathLike, header: str, *, append: bool = False) -> None:
        self.path = Path(path)
        exists = self.path.exists() and self.path.stat().st_size > 0
        if exists and not append:
            raise FileExistsError(f"{self.path}: exists; refusing to overwrite")
        self._fh: TextIO = open(self.path, "a", encoding="utf-8", newline="")
        if not exists:
            self._fh.write(header + "\n")
        self.rows = 0

    def write_line(self, line: str) -> None:
        """Append one line (no newline in ``line``); an OSError names the file."""
        with naming(self.path):
            self._fh.write(line + "\n")
        self.rows += 1

    def flush(self) -> None:
        """Hand buffered lines to the OS (survives a ``kill -9``); an OSError names the file."""
        with naming(self.path):
            self._fh.flush()

    def sync(self) -> None:
        """Flush and fsync (survives a power cut); an OSError names the file."""
        with naming(self.path):
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Flush and close (idempotent); an OSError names the file."""
        if not self._fh.closed:
            with naming(self.path):
                self._fh.close()


class EventWriter(_LineWriter):
    """Writer of ``events.csv`` (``t_s,kind,label,value``)."""

    def __init__(self, path: str | os.PathLike, *, append: bool = False) -> None:
        super().__init__(path, EVENTS_HEADER, append=append)

    def write(self, event: Event) -> None:
        """Append one event (fields are CSV-quoted when needed)."""
        self.write_line(_csv_line([f"{event.t_s:.4f}", event.kind, event.label, event.value]))


class FrameTimeWriter(_LineWriter):
    """Writer of ``video_frames.csv`` (``frame,t_s``)."""

    def __init__(self, path: str | os.PathLike, *, append: bool = False) -> None:
        super().__init__(path, FRAMES_HEADER, append=append)

    def write(self, frame: int, t_s: float) -> None:
        """Append the arrival time of frame number ``frame``."""
        self.write_line(f"{frame},{t_s:.4f}")


class HrWriter(_LineWriter):
    """Writer of ``heart_rate.csv`` rows in the :mod:`effortface.core.session.hr_csv` format."""

    def __init__(self, path: str | os.PathLike, *, append: bool = False) -> None:
        super().__init__(path, HR_CSV_HEADER, append=append)

    def write(self, sample: HrSample) -> None:
        """Append one sample."""
        self.write_line(format_hr_row(sample))


def _csv_line(fields: Iterable[str]) -> str:
    """One CSV line with minimal quoting."""
    out = []
    for f in fields:
        f = str(f)
        out.append('"' + f.replace('"', '""') + '"' if any(c in f for c in ',"\n\r') else f)
    return ",".join(out)


def _read_csv_rows(path: Path, header: str) -> list[tuple[int, list[str]]]:
    """Data rows of a CSV as ``(line number, fields)`` after checking its header line.

    Raises
    ------
    SessionFormatError
        If the file is a folder, is not UTF-8 CSV text, or its header differs.
    """
    check_regular_file(path, "a CSV file", SessionFormatError)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            first = next(reader, None)
            if first is None or ",".join(first) != header:
                raise SessionFormatError(f"{path}: expected header {header!r}, found {','.join(first or [])!r}")
            return [(reader.line_num, row) for row in reader if row]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise not_text_error(path, exc) from None


def read_events(path: str | os.PathLike) -> list[Event]:
    """Read ``events.csv``; SessionFormatError naming the file and line on a bad row."""
    path = Path(path)
    out = []
    for line, row in _read_csv_rows(path, EVENTS_HEADER):
        try:
            t_s, kind, label, value = row
            out.append(Event(bounds.check("t_s", float(t_s)), kind, label, value))
        except ValueError as exc:
            why = f" ({exc})" if isinstance(exc, UserError) else ""
            raise SessionFormatError(f"{path}: line {line}: expected t_s,kind,label,value, found {row!r}{why}") from None
    return out


def read_video_frames(path: str | os.PathLike) -> list[float]:
    """Read ``video_frames.csv``; return ``t_s`` of frames 0, 1, 2... (frames must be consecutive)."""
    path = Path(path)
    out: list[float] = []
    for line, row in _read_csv_rows(path, FRAMES_HEADER):
        try:
            frame, t_s = int(row[0]), float(row[1])
            bounds.check("t_s", t_s)
        except (ValueError, IndexError) as exc:
            why = f" ({exc})" if isinstance(exc, UserError) else ""
            raise SessionFormatError(f"{path}: line {line}: expected frame,t_s, found {row!r}{why}") from None
        if frame != len(out):
            raise SessionFormatError(f"{path}: line {line}: expected frame {len(out)}, found {frame}")
        out.append(t_s)
    return out


# ------------------------------------------------------------------------------- whole sessions
@dataclasses.dataclass
class Session:
    """A read session folder.

    Attributes
    ----------
    path : Path
        The folder.
    info : SessionInfo
        ``session.json``.
    heart_rate : list of HrSample
        ``heart_rate.csv`` rows (empty if the file is absent).
    events : list of Event
        ``events.csv`` rows.
    frame_times_s : list of float
        Arrival time of each video frame (``video_frames.csv``); empty without video.
    """

    path: Path
    info: SessionInfo
    heart_rate: list[HrSample]
    events: list[Event]
    frame_times_s: list[float]

    @property
    def participant(self) -> Participant:
        """The participant record."""
        return self.info.participant

    @property
    def devices(self) -> dict[str, Any]:
        """The ``devices`` dict of session.json."""
        return self.info.devices

    @property
    def video_path(self) -> Path | None:
        """``video.avi`` if the session has one."""
        p = self.path / VIDEO_AVI
        return p if p.exists() else None

    def serlog_paths(self) -> list[Path]:
        """The raw serial logs, sorted."""
        return sorted((self.path / SERIAL_DIR).glob("*.serlog"))


def read_session(path: str | os.PathLike) -> Session:
    """Read a session folder (complete or not).

    Parameters
    ----------
    path : path-like
        The session folder.

    Returns
    -------
    Session

    Raises
    ------
    SessionFormatError
        If the folder or one of its files does not follow the session format (names the file).
    """
    folder = Path(path)
    if not folder.is_dir():
        raise SessionFormatError(f"{folder}: expected a session folder, found {'a file' if folder.exists() else 'nothing'}")
    info = read_session_info(folder)
    hr = folder / HEART_RATE_CSV
    ev = folder / EVENTS_CSV
    fr = folder / VIDEO_FRAMES_CSV
    return Session(
        path=folder,
        info=info,
        heart_rate=read_hr_csv(hr) if hr.exists() else [],
        events=read_events(ev) if ev.exists() else [],
        frame_times_s=read_video_frames(fr) if fr.exists() else [],
    )


def validate_session(path: str | os.PathLike) -> list[str]:
    """List the problems of a session folder (empty list: valid and complete).

    Checks: readable files, folder name equals ``session_id``, ``complete`` true, the heart-rate
    and frame times non-decreasing, no invalid row carrying a heart rate, video and frame table
    present together, and one row of the frame table per frame that decodes in the video.
    """
    folder = Path(path)
    try:
        s = read_session(folder)
    except SessionFormatError as exc:
        return [str(exc)]
    problems = []
    if s.info.session_id != folder.name:
        problems.append(f"{folder}: folder name differs from session_id {s.info.session_id!r}")
    if not s.info.complete:
        problems.append(f"{folder / SESSION_JSON}: complete is false (run 'effortface recover {folder}')")
    problems += _order_problems(s)
    bad = [h for h in s.heart_rate if (h.valid and h.hr_bpm is None) or (h.hr_bpm is not None and h.hr_bpm <= 0)]
    if bad:
        problems.append(f"{folder / HEART_RATE_CSV}: {len(bad)} rows with a missing or non-positive hr_bpm")
    if (folder / VIDEO_AVI).exists() != (folder / VIDEO_FRAMES_CSV).exists():
        problems.append(f"{folder}: video.avi and video_frames.csv must be present together")
    elif (folder / VIDEO_AVI).is_file():
        problems += video_problems(folder, len(s.frame_times_s))
    return problems


def video_problems(folder: str | os.PathLike, n_rows: int) -> list[str]:
    """One problem line if the frames of ``video.avi`` that decode are not ``n_rows`` (the frame table's).

    Parameters
    ----------
    folder : path-like
        The session folder.
    n_rows : int
        Rows of its ``video_frames.csv``.

    Returns
    -------
    list of str
        Empty when they match.
    """
    folder = Path(folder)
    from effortface.core.opencv import index_video

    n_decoded = index_video(folder / VIDEO_AVI)
    if n_decoded == n_rows:
        return []
    return [f"{folder / VIDEO_FRAMES_CSV}: lists {n_rows} frames, found {n_decoded} that decode in {VIDEO_AVI} "
            f"(run 'effortface recover {folder}')"]
def check_session(path: str | os.PathLike) -> Session:
    """Read a session folder and refuse it if it cannot be used as it is: the one check before use.

    Training, evaluation and annotation read sessions through this. On top of :func:`read_session`
    (whose readers refuse unreadable rows, NaN, negative and absurd times): heart-rate and frame
    times must not go back, and ``video.avi`` must hold as many frames as ``video_frames.csv`` has
    rows (a table of another video, or a video cut short). Soft problems (``complete`` false) are
    left to :func:`validate_session`.

    Parameters
    ----------
    path : path-like
        The session folder.

    Returns
    -------
    Session

    Raises
    ------
    SessionFormatError
        One line naming the file, what was expected and what was found.
    """
    s = read_session(path)
    problems = _order_problems(s) + _video_problems(s)
    if problems:
        raise SessionFormatError(problems[0])
    return s


def _order_problems(s: Session) -> list[str]:
    """Lines for heart-rate or frame times that go back."""
    return (_monotonic_problems(s.path / HEART_RATE_CSV, [h.t_s for h in s.heart_rate])
            + _monotonic_problems(s.path / VIDEO_FRAMES_CSV, s.frame_times_s))


def _video_problems(s: Session) -> list[str]:
    """A line if the video's frame count differs from the frame table's rows."""
    if s.video_path is None or not s.frame_times_s:
        return []
    from effortface.core.opencv import avi_header_frames  # lazy: cv2 loads slowly

    n_video = avi_header_frames(s.video_path)
    if n_video != len(s.frame_times_s):
        return [f"{s.path / VIDEO_FRAMES_CSV}: expected one row per frame of {VIDEO_AVI} ({n_video} frames), "
                f"found {len(s.frame_times_s)} rows"]
    return []


def _monotonic_problems(path: Path, times: list[float]) -> list[str]:
    """One problem line if ``times`` ever decreases."""
    back = sum(b < a for a, b in zip(times, times[1:]))
    return [f"{path}: t_s decreases {back} times"] if back else []


def list_sessions(directory: str | os.PathLike, *, include_recording: bool = False) -> list[Path]:
    """Session folders (those with a ``session.json``) directly inside ``directory``, sorted by name.

    Parameters
    ----------
    directory : path-like
        The folder of sessions.
    include_recording : bool
        Also list sessions a running capture is recording (hidden by default: nothing may read
        them as finished, recover them or annotate them while they grow).

    Raises
    ------
    UserError
        If ``directory`` is not a folder.
    """
    d = Path(directory)
    if not d.is_dir():
        raise UserError(f"{d}: expected a folder of sessions, found {'a file' if d.exists() else 'nothing'}")
    found = sorted(p for p in d.iterdir() if p.is_dir() and (p / SESSION_JSON).is_file())
    return found if include_recording else [p for p in found if recording_owner(p) is None]


def recording_owner(folder: str | os.PathLike) -> dict[str, Any] | None:
    """Who is recording the session ``folder`` now (pid, host, started_utc), or None.

    A lock file left by a killed capture is stale (its ``flock`` died with the process): None.
    """
    return lock_owner(Path(folder) / RECORDING_LOCK)


def check_not_recording(folder: str | os.PathLike, action: str) -> None:
    """Refuse to ``action`` (``"recover"``, ``"annotate"``...) a session a capture is recording.

    Raises
    ------
    LockedError
        One line naming the session, the action and the recording's owner.
    """
    owner = recording_owner(folder)
    if owner is not None:
        raise LockedError(f"{folder}: expected a session no capture is recording (to {action} it), found it "
                          f"being recorded by {describe_owner(owner)}; stop that capture first")


def utc_now_iso() -> str:
    """Current UTC time, ISO 8601 with seconds and ``Z``."""
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
