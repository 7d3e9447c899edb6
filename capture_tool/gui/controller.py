"""The Capture stage's model (Qt-free): drives a :class:`~effortface.capture_tool.recorder.Recorder`.

The widgets call :class:`CaptureController` methods and draw what :meth:`CaptureController.poll`
returns on a QTimer; nothing here blocks for long or touches a widget (STYLE.md L3, L5). What
the live view plots is read back from the session files as they grow (:class:`CsvTail`), so the
screen shows exactly what is on disk.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import statistics
from pathlib import Path
from typing import Any

from effortface.core.errors import UserError
from effortface.capture_tool.gui.preflight import DeviceChoice
from effortface.capture_tool.gui.sync import flash_offset_s, video_brightness
from effortface.capture_tool.recorder import Recorder, RecorderStatus, recover_session
from effortface.capture_tool.session import (
    EVENTS_CSV,
    HEART_RATE_CSV,
    VIDEO_AVI,
    VIDEO_FRAMES_CSV,
    Event,
    Participant,
    list_sessions,
    read_events,
    read_session_info,
    read_video_frames,
)

SYNC_KIND, FLASH_LABEL = "sync", "flash"


@dataclasses.dataclass(frozen=True)
class HrRow:
    """One ``heart_rate.csv`` row as the live view needs it."""

    t_s: float
    hr_bpm: float | None
    rr_ms: float | None
    valid: bool


@dataclasses.dataclass
class LiveUpdate:
    """What changed since the last :meth:`CaptureController.poll`."""

    status: RecorderStatus
    hr_rows: list[HrRow]
    events: list[Event]
    frame: Any = None
    frames_bad: int = 0
    camera_ended: bool = False


class CsvTail:
    """Read the complete lines appended to a CSV file since the last call (header skipped).

    Parameters
    ----------
    path : path-like
        The growing file (it may not exist yet).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self._offset = 0
        self._partial = b""
        self._header_seen = False

    def read_rows(self) -> list[list[str]]:
        """New complete rows, split into fields (a torn last line waits for the next call)."""
        try:
            with open(self.path, "rb") as fh:
                fh.seek(self._offset)
                blob = fh.read()
        except FileNotFoundError:
            return []
        self._offset += len(blob)
        lines = (self._partial + blob).split(b"\n")
        self._partial = lines.pop()
        text = [line.decode("utf-8", "replace") for line in lines if line.strip()]
        if text and not self._header_seen:
            text, self._header_seen = text[1:], True
        return list(csv.reader(text))


def _hr_row(fields: list[str]) -> HrRow | None:
    """``t_s,hr_bpm,rr_ms,beat_count,device,valid`` -> HrRow (None if malformed)."""
    try:
        t_s, hr, rr, _beat, _device, valid = fields
        rr_last = rr.split()[-1] if rr.strip() else None
        return HrRow(float(t_s), float(hr) if hr else None, float(rr_last) if rr_last else None,
                     valid.strip() == "1")
    except ValueError:
        return None


def _event(fields: list[str]) -> Event | None:
    try:
        t_s, kind, label, value = fields
        return Event(float(t_s), kind, label, value)
    except ValueError:
        return None


class CaptureController:
    """Start, mark, poll and stop one recording at a time; find and recover crashed sessions.

    Parameters
    ----------
    out_dir : path-like
        Folder that receives the session folders.

    Attributes
    ----------
    recorder : Recorder or None
        The running recording.
    phase : str or None
        The phase running now (``rest``, ``warmup``, ``exercise``, ``recovery``).
    last_session : Path or None
        The folder of the last recording stopped.
    """

    def __init__(self, out_dir: str | os.PathLike) -> None:
        self.out_dir = Path(out_dir)
        self.recorder: Recorder | None = None
        self.phase: str | None = None
        self.last_session: Path | None = None
        self._tails: tuple[CsvTail, CsvTail] | None = None
        self._latest_frame: Any = None

    @property
    def recording(self) -> bool:
        """True between :meth:`start` and :meth:`stop`."""
        return self.recorder is not None

    def start(self, participant: Participant, choice: DeviceChoice, label: str = "", lsl: bool = False) -> Path:
        """Open the devices and start a new session; return its folder (``lsl``: also publish the
        strap and events as LSL streams, see :mod:`effortface.capture_tool.lsl`).

        Raises
        ------
        UserError
            If already recording, no port is chosen, or a device cannot be opened
            (DeviceError, a UserError, says which).
        """
        if self.recorder is not None:
            raise UserError("Record: expected no recording running, found one (stop it first)")
        if not choice.port:
            raise UserError("Strap port: expected a serial port or URL, found none chosen")
        recorder = Recorder(self.out_dir, participant, choice.port, choice.protocol,
                            video=choice.camera, label=label or None, lsl=lsl)
        path = recorder.start()
        self.recorder, self.phase, self._latest_frame = recorder, None, None
        self._tails = (CsvTail(path / HEART_RATE_CSV), CsvTail(path / EVENTS_CSV))
        return path

    def mark(self, kind: str, label: str = "", value: str = "") -> float:
        """Write an event on the session clock; return its time in seconds.

        Raises
        ------
        UserError
            If nothing is recording.
        """
        if self.recorder is None:
            raise UserError(f"{kind}: expected a recording running, found none (press Record first)")
        return self.recorder.mark(kind, label, value)

    def start_phase(self, phase: str, value: str = "") -> float:
        """End the running phase (if any) and start ``phase``; return the start time."""
        if self.phase is not None:
            self.mark("phase_end", self.phase)
        t_s = self.mark("phase_start", phase, value)
        self.phase = phase
        return t_s

    def change_load(self, value: str) -> float:
        """Record a load/speed change (``value`` like ``load_kg=5;speed_kmh=8``)."""
        return self.mark("load", self.phase or "", value)

    def sync_flash(self) -> float:
        """Record the on-screen flash of the sync self-test; return its time."""
        return self.mark(SYNC_KIND, FLASH_LABEL)

    def poll(self) -> LiveUpdate | None:
        """What changed since the last call (None when not recording); never blocks."""
        recorder = self.recorder
        if recorder is None or self._tails is None:
            return None
        hr_tail, event_tail = self._tails
        rows = [r for r in map(_hr_row, hr_tail.read_rows()) if r is not None]
        events = [e for e in map(_event, event_tail.read_rows()) if e is not None]
        camera = recorder.camera
        frame = None if camera is None else camera.latest_frame
        if frame is self._latest_frame:
            frame = None  # nothing new since the last poll
        else:
            self._latest_frame = frame
        return LiveUpdate(recorder.status(), rows, events, frame,
                          frames_bad=recorder.link.decoder.stats.frames_bad,
                          camera_ended=bool(camera is not None and camera.ended))

    def stop(self) -> Path:
        """End the running phase, stop the recording (session complete) and measure the sync test.

        Returns
        -------
        Path
            The session folder.
        """
        recorder = self.recorder
        if recorder is None:
            raise UserError("Stop: expected a recording running, found none")
        if self.phase is not None:
            recorder.mark("phase_end", self.phase)
        path = recorder.stop()
        self.recorder, self.phase, self._tails, self.last_session = None, None, None, path
        store_sync_result(path)
        return path

    def incomplete_sessions(self) -> list[Path]:
        """Session folders in :attr:`out_dir` that a crash left with ``complete: false``."""
        if not self.out_dir.is_dir():
            return []
        out = []
        for folder in list_sessions(self.out_dir):
            try:
                if not read_session_info(folder).complete:
                    out.append(folder)
            except UserError:
                continue
        return out

    def recover(self, folder: str | os.PathLike) -> dict[str, Any]:
        """Finish an incomplete session (blocking: run it off the GUI thread)."""
        return recover_session(folder)


def measure_sync(folder: str | os.PathLike) -> dict[str, Any]:
    """Measure the video-to-HR offset from the sync flashes recorded in a session.

    Parameters
    ----------
    folder : path-like
        A session folder with ``events.csv`` (and ``video.avi`` + ``video_frames.csv``).

    Returns
    -------
    dict
        ``flashes`` (event times), ``offsets_s`` (one per flash seen in the video),
        ``video_offset_s`` (their median, or None) and a ``note``.
    """
    folder = Path(folder)
    flashes = [e.t_s for e in read_events(folder / EVENTS_CSV)
               if e.kind == SYNC_KIND and e.label == FLASH_LABEL]
    result: dict[str, Any] = {"flashes_t_s": flashes, "offsets_s": [], "video_offset_s": None}
    if not flashes:
        return {**result, "note": "no sync flash in events.csv"}
    if not (folder / VIDEO_AVI).exists():
        return {**result, "note": "no video recorded"}
    times = read_video_frames(folder / VIDEO_FRAMES_CSV)
    for t_flash in flashes:
        offset = _offset_near(folder / VIDEO_AVI, times, t_flash)
        if offset is not None:
            result["offsets_s"].append(round(offset, 4))
    if result["offsets_s"]:
        result["video_offset_s"] = round(statistics.median(result["offsets_s"]), 4)
        return {**result, "note": "video time minus event time of the first bright frame (median)"}
    return {**result, "note": "flash not seen in the video (camera not facing the screen, or a file)"}


def _offset_near(avi: Path, times: list[float], t_flash_s: float) -> float | None:
    """Offset of one flash, reading only the frames from 1 s before to 2 s after it."""
    idx = [i for i, t in enumerate(times) if t_flash_s - 1.0 <= t <= t_flash_s + 2.0]
    if not idx:
        return None
    brightness = video_brightness(avi, idx[0], idx[-1])
    return flash_offset_s(times[idx[0]:idx[0] + len(brightness)], brightness, t_flash_s)


def store_sync_result(folder: str | os.PathLike) -> dict[str, Any] | None:
    """Measure the sync test of a session and store it as ``sync`` in its ``session.json``.

    Returns the stored dict, or None when the session has no flash (nothing is written).
    """
    result = measure_sync(folder)
    if not result["flashes_t_s"]:
        return None
    info = read_session_info(folder)
    info.extra["sync"] = result
    info.save(folder, overwrite=True)
    return result
