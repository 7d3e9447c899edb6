"""The recorder: writes a session folder as data arrives, and finishes one a crash left behind.

Producers (the serial link thread, the camera threads, :meth:`Recorder.mark` from the GUI) put
items on one :class:`queue.Queue`; one writer thread consumes it and appends ``heart_rate.csv`` and
``events.csv``, flushing whenever the queue runs empty (so at least once a second, usually within
milliseconds). ``session.json`` says ``complete: false`` until :meth:`Recorder.stop`.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import os
import queue
import threading
import time
from pathlib import Path
from typing import Any

from capture_tool import __version__
from capture_tool.camera import CameraSource, index_video, rewrite_video
from capture_tool.errors import SessionFormatError
from capture_tool.hr_csv import HR_CSV_HEADER, read_hr_csv
from capture_tool.protocols import DeviceEvent, HrSample, get_decoder
from capture_tool.serial_link import SerialLink, is_simulated_port
from capture_tool.serlog import DATA, EVENT, read_serlog
from capture_tool.session import (
    EVENTS_CSV,
    HEART_RATE_CSV,
    SERIAL_DIR,
    VIDEO_AVI,
    VIDEO_FRAMES_CSV,
    Event,
    EventWriter,
    HrWriter,
    Participant,
    SessionInfo,
    create_session,
    make_session_id,
    read_session_info,
    utc_now_iso,
)

FLUSH_INTERVAL_S = 1.0


@dataclasses.dataclass(frozen=True)
class RecorderStatus:
    """A snapshot for the GUI's status bar (all counts since the start)."""

    elapsed_s: float
    samples: int
    frames: int
    dropped_frames: int
    bad_bytes: int
    bytes_on_disk: int
    hr_bpm: float | None
    rr_ms: float | None
    link_state: str


def device_startup_frames(protocol: str, port: str) -> list[bytes]:
    """Configuration a real device needs after opening (ANT stick: reset, key, HRM channel).

    Simulated ports (pseudo-terminals, ``replay://``) get none, so replays need no ANT+ key.

    Raises
    ------
    DeviceError
        ``NO_KEY`` for a real ANT stick without a network key (the message says how to get one).
    """
    if protocol != "ant" or is_simulated_port(port):
        return []
    from capture_tool.protocols.ant_stick import load_network_key, open_sequence

    return open_sequence(load_network_key())


class Recorder:
    """Record one strap (and optionally video) into a new session folder.

    Parameters
    ----------
    out_dir : path-like
        Folder that receives the session folder.
    participant : Participant
    port : str
        Strap port (device path or pyserial URL).
    protocol : str
        ``ant``, ``hxm``, ``hrmi`` or ``lines``.
    video : int, path-like or None
        Camera index, video file (played at its rate), or None for no video.
    label : str, optional
        Appended to the session id.
    device : str
        Strap name: ``serial/<device>.serlog``.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike,
        participant: Participant,
        port: str,
        protocol: str,
        video: int | str | os.PathLike | None = None,
        label: str | None = None,
        device: str | None = None,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.participant = participant
        self.label = label
        self.queue: queue.Queue = queue.Queue()
        self._t0 = time.monotonic()
        self.link = SerialLink(port, get_decoder(protocol), self.queue, self.clock, device or protocol,
                               startup_frames=device_startup_frames(protocol, port))
        self._video_source = video
        self.camera: CameraSource | None = None
        self.path: Path | None = None
        self.info: SessionInfo | None = None
        self._samples = 0
        self._last: HrSample | None = None
        self._writer_thread: threading.Thread | None = None
        self._stopped = False

    def clock(self) -> float:
        """Session time in seconds (host monotonic clock since the start)."""
        return time.monotonic() - self._t0

    def start(self) -> Path:
        """Open the devices, create the session folder and start recording; return the folder.

        Raises
        ------
        DeviceError, UserError
            If the port or video cannot be opened (before any folder is created).
        FileExistsError
            If the session folder exists.
        """
        self.link.open()
        try:
            if self._video_source is not None:
                self.camera = CameraSource(self._video_source, self.clock)
            self.info = self._new_info()
            self.path = create_session(self.out_dir, self.info)
        except BaseException:
            self.link.stop()
            if self.camera is not None:
                self.camera.stop()
            raise
        self._hr = HrWriter(self.path / HEART_RATE_CSV)
        self._events = EventWriter(self.path / EVENTS_CSV)
        self._t0 = time.monotonic()
        self.link.start(self.path / SERIAL_DIR / f"{self.link.device}.serlog")
        if self.camera is not None:
            self.camera.start(self.path / VIDEO_AVI, self.path / VIDEO_FRAMES_CSV)
        self._writer_thread = threading.Thread(target=self._write_loop, name="recorder-writer", daemon=True)
        self._writer_thread.start()
        self.mark("sync", "session_start", self.info.created_utc)
        return self.path

    def _new_info(self) -> SessionInfo:
        now = _dt.datetime.now()
        devices: dict[str, Any] = {"heart_rate": self.link.settings()}
        if self.camera is not None:
            devices["camera"] = self.camera.settings()
        return SessionInfo(
            session_id=make_session_id(self.participant.code, now, self.label),
            participant=self.participant,
            devices=devices,
            complete=False,
            created_utc=utc_now_iso(),
            software={"name": "effortface", "version": __version__},
        )

    def mark(self, kind: str, label: str = "", value: str = "") -> float:
        """Record an event now (``phase_start``, ``phase_end``, ``marker``, ``load``, ``sync``...).

        Returns
        -------
        float
            Its session time in seconds.
        """
        t_s = self.clock()
        self.queue.put(("event", DeviceEvent(t_s, kind, label, str(value))))
        return t_s

    def _write_loop(self) -> None:
        last_flush = time.monotonic()
        while True:
            try:
                item = self.queue.get(timeout=0.2)
            except queue.Empty:
                item = None
            if item is not None and item[0] == "stop":
                break
            if item is not None:
                self._write_item(item)
            if self.queue.empty() or time.monotonic() - last_flush >= FLUSH_INTERVAL_S:
                self._hr.flush()
                self._events.flush()
                last_flush = time.monotonic()
        self._hr.flush()
        self._events.flush()

    def _write_item(self, item: tuple[str, Any]) -> None:
        kind, obj = item
        if kind == "hr":
            self._hr.write(obj)
            self._samples += 1
            self._last = obj
        elif kind == "event":
            self._events.write(Event(obj.t_s, obj.kind, obj.label, obj.value))

    def status(self) -> RecorderStatus:
        """A snapshot of the recording (thread-safe reads of counters)."""
        last = self._last
        cam = self.camera
        return RecorderStatus(
            elapsed_s=self.clock(),
            samples=self._samples,
            frames=cam.frames_written if cam else 0,
            dropped_frames=cam.dropped if cam else 0,
            bad_bytes=self.link.decoder.stats.bytes_dropped,
            bytes_on_disk=_folder_bytes(self.path) if self.path else 0,
            hr_bpm=last.hr_bpm if last else None,
            rr_ms=last.rr_ms[-1] if last and last.rr_ms else None,
            link_state=self.link.state,
        )

    def stop(self) -> Path:
        """Stop every device, write what is queued, and mark the session complete (idempotent)."""
        assert self.path is not None and self.info is not None, "stop() before start()"
        if self._stopped:
            return self.path
        self._stopped = True
        self.mark("sync", "session_stop", utc_now_iso())
        if self.camera is not None:
            self.camera.stop()
        self.link.stop()
        self.queue.put(("stop", None))
        if self._writer_thread is not None:
            self._writer_thread.join()
        self._hr.close()
        self._events.close()
        self.info.complete = True
        self.info.extra["stats"] = self._stats()
        self.info.save(self.path, overwrite=True)
        return self.path

    def _stats(self) -> dict[str, Any]:
        cam = self.camera
        return {
            "duration_s": round(self.clock(), 3),
            "hr_samples": self._samples,
            "decoder": self.link.decoder.stats.as_dict(),
            "serial_gaps": self.link.gaps,
            "serial_reconnects": self.link.reconnects,
            "video_frames": cam.frames_written if cam else 0,
            "dropped_frames": cam.dropped if cam else 0,
        }


def _folder_bytes(path: Path) -> int:
    """Total size of the files under ``path``."""
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


# ------------------------------------------------------------------------------------ recovery
def recover_session(path: str | os.PathLike) -> dict[str, Any]:
    """Finish a session that a crash left incomplete.

    Re-indexes the video (counts the frames that decode; rewrites the AVI into a fresh MJPG file
    when its header disagrees, so seeks are exact; trims ``video_frames.csv`` to match), re-decodes
    the serial logs to restore ``heart_rate.csv`` rows lost after the last flush, drops torn last
    lines, and marks ``session.json`` complete with a ``recovered`` note.

    Parameters
    ----------
    path : path-like
        The session folder.

    Returns
    -------
    dict
        The ``recovered`` note (``when`` and the list ``done``).

    Raises
    ------
    SessionFormatError
        If the folder is not a session, or it is already complete.
    """
    folder = Path(path)
    info = read_session_info(folder)
    if info.complete:
        raise SessionFormatError(f"{folder / 'session.json'}: expected an incomplete session, found complete: true")
    done: list[str] = []
    for name, header in ((EVENTS_CSV, "t_s,kind,label,value"), (VIDEO_FRAMES_CSV, "frame,t_s"), (HEART_RATE_CSV, HR_CSV_HEADER)):
        done += _drop_torn_line(folder / name, header)
    done += _recover_heart_rate(folder, info)
    done += _recover_video(folder)
    note = {"when": utc_now_iso(), "done": done or ["nothing to repair"]}
    info.complete = True
    info.extra["recovered"] = note
    info.save(folder, overwrite=True)
    return note


def _drop_torn_line(path: Path, header: str) -> list[str]:
    """Cut a last line that has no newline (written half when the process died); create if absent."""
    if not path.exists():
        return []
    blob = path.read_bytes()
    if not blob:
        path.write_text(header + "\n", encoding="utf-8")
        return [f"{path.name}: wrote the missing header"]
    if blob.endswith(b"\n"):
        return []
    cut = blob.rfind(b"\n") + 1
    with open(path, "r+b") as fh:
        fh.truncate(cut)
    return [f"{path.name}: dropped a torn last line ({len(blob) - cut} bytes)"]


def decode_serlog(path: str | os.PathLike) -> list[HrSample]:
    """Decode a ``.serlog`` exactly as the link did live (a gap event ends the partial frame)."""
    log = read_serlog(path)
    decoder = get_decoder(str(log.header.get("protocol", "")))
    out: list[HrSample] = []
    for rec in log.records:
        if rec.kind == DATA:
            out += decoder.feed(rec.payload, rec.t_s)
        elif rec.kind == EVENT and rec.event().get("kind") == "device_gap":
            out += decoder.finish()
    return out + decoder.finish()


def _recover_heart_rate(folder: Path, info: SessionInfo) -> list[str]:
    """Append the samples the serial logs hold beyond the rows already in heart_rate.csv."""
    hr_path = folder / HEART_RATE_CSV
    rows = read_hr_csv(hr_path) if hr_path.exists() else []
    samples: list[HrSample] = []
    for log in sorted((folder / SERIAL_DIR).glob("*.serlog")):
        samples += decode_serlog(log)
    samples.sort(key=lambda s: s.t_s)
    missing = samples[len(rows):]
    if not missing:
        return []
    writer = HrWriter(hr_path, append=True)
    for s in missing:
        writer.write(s)
    writer.close()
    return [f"{HEART_RATE_CSV}: restored {len(missing)} rows from the serial log"]


def _recover_video(folder: Path) -> list[str]:
    """Re-index video.avi; keep only frames that both decode and have a time; exact index."""
    avi, frames_csv = folder / VIDEO_AVI, folder / VIDEO_FRAMES_CSV
    if not avi.exists():
        return []
    import cv2

    times = _frame_rows(frames_csv)
    n_decoded = index_video(avi)
    n_keep = min(n_decoded, len(times))
    cap = cv2.VideoCapture(str(avi))
    n_header = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    cap.release()
    done = []
    if n_header != n_keep or n_decoded != n_keep:
        fresh = avi.with_name(".video.recovered.avi")
        fresh.unlink(missing_ok=True)
        n_keep = rewrite_video(avi, fresh, max_frames=n_keep)
        os.replace(fresh, avi)
        done.append(
            f"{VIDEO_AVI}: header said {n_header} frames, {n_decoded} decode, {len(times)} have a time; "
            f"rewrote {n_keep} frames with an exact index"
        )
    if len(times) != n_keep:
        tmp = frames_csv.with_name("." + frames_csv.name + ".tmp")
        tmp.write_text("\n".join(["frame,t_s"] + times[:n_keep]) + "\n", encoding="utf-8")
        os.replace(tmp, frames_csv)
        done.append(f"{VIDEO_FRAMES_CSV}: trimmed {len(times) - n_keep} rows of frames missing from the video")
    return done


def _frame_rows(path: Path) -> list[str]:
    """The data lines of video_frames.csv (empty if absent)."""
    if not path.exists():
        return []
    return [line for line in path.read_text(encoding="utf-8").splitlines()[1:] if line.strip()]
