"""The recorder: writes a session folder as data arrives, and finishes one a crash left behind.

Producers (the serial link thread, the camera threads, :meth:`Recorder.mark` from the GUI) put
items on one :class:`queue.Queue`; one writer thread consumes it and appends ``heart_rate.csv`` and
``events.csv``, flushing whenever the queue runs empty (so at least once a second, usually within
milliseconds). ``session.json`` says ``complete: false`` until :meth:`Recorder.stop`.

While it records, the recorder holds the session's recording lock (``.recording.lock``, see
:mod:`effortface.core.locks`): recovery, Annotate and Train leave the session alone. A write that
fails (disk full, file-size limit) is a fault said in one line naming the file
(:attr:`Recorder.faults`); a session with a failed write is never marked complete.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import os
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from effortface.core.version import __version__
from effortface.capture_tool.camera import CameraSource, index_video, rewrite_video
from effortface.capture_tool.framing_sampler import FramingSampler
from effortface.core.framing import Framing
from effortface.core.errors import SessionFormatError
from effortface.core.fileio import not_a_file
from effortface.core.locks import FileLock
from effortface.core.session.hr_csv import HR_CSV_HEADER, read_hr_csv
from effortface.capture_tool.protocols import DeviceEvent, HrSample, get_decoder, header_protocol
from effortface.capture_tool.serial_link import SerialLink, check_port_exists, is_simulated_port
from effortface.capture_tool.serlog import DATA, EVENT, read_serlog
from effortface.core.session.folder import (
    EVENTS_CSV,
    EVENTS_HEADER,
    FRAMES_HEADER,
    HEART_RATE_CSV,
    SERIAL_DIR,
    VIDEO_AVI,
    VIDEO_FRAMES_CSV,
    Event,
    EventWriter,
    HrWriter,
    Participant,
    SessionInfo,
    RECORDING_LOCK,
    check_not_recording,
    create_recording_session,
    read_events,
    read_video_frames,
    recording_owner,
    video_problems,
    ID_TAKEN_KEY,
    free_session_id,
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
    fault: str | None = None  # the first fault (one line naming the file), if any
    framing: Framing | None = None  # the framing sampler's last look at the camera (None: none yet)


def device_startup_frames(protocol: str, port: str) -> list[bytes]:
    """Configuration a real device needs after opening (ANT stick: reset, key, HRM channel).

    Simulated ports (pseudo-terminals, ``replay://``) get none, so replays need no ANT+ key.

    Raises
    ------
    DeviceError
        ``NOT_FOUND`` for a port that does not exist (checked first, so a missing port is not
        reported as a missing key); ``NO_KEY`` for a real ANT stick without a network key (the
        message says how to get one).
    """
    if protocol != "ant" or is_simulated_port(port):
        return []
    check_port_exists(port)
    from effortface.capture_tool.protocols.ant_stick import load_network_key, open_sequence

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
    lsl : bool
        Also publish the strap and the events as LSL streams (:mod:`effortface.capture_tool.lsl`);
        the LSL clock offset goes into ``session.json`` under ``lsl``.
    framing : bool
        With video, look at the face's framing about twice a second in a thread of its own
        (:class:`~effortface.capture_tool.framing_sampler.FramingSampler`): :attr:`framing`, and
        ``framing`` in :meth:`status`.
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
        lsl: bool = False,
        framing: bool = True,
    ) -> None:
        self.out_dir = Path(out_dir)
        self._framing_wanted = framing
        self.framing: FramingSampler | None = None
        self._lsl_wanted = lsl
        self.lsl: Any = None  # an LslPublisher once started with lsl=True
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
        self._lock: FileLock | None = None
        self._file_faults: dict[Path, str] = {}
        self.warnings: list[str] = []

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
                self.camera = CameraSource(self._video_source, self.clock, on_fault=self._camera_fault)
            self.info = self._new_info()
            if self._lsl_wanted:
                from effortface.capture_tool.lsl import LslPublisher  # lazy: pylsl loads liblsl

                self.lsl = LslPublisher(self.link.device, self.link.port, self.participant.code,
                                        self.info.session_id)
            self.path, self._lock = create_recording_session(self.out_dir, self.info)
        except BaseException:
            self.link.stop()
            if self.camera is not None:
                self.camera.stop()
            raise
        try:
            self._open_files()
        except BaseException:  # e.g. a full disk: stop the devices and free the session's lock
            self.link.stop()
            if self.camera is not None:
                self.camera.stop()
            if self._lock is not None:
                self._lock.release()
            raise
        self._writer_thread = threading.Thread(target=self._write_loop, name="recorder-writer", daemon=True)
        self._writer_thread.start()
        self.mark("sync", "session_start", self.info.created_utc)
        return self.path

    def _open_files(self) -> None:
        """Create the session's files and start the link and camera threads writing them."""
        assert self.path is not None and self.info is not None
        self._hr = HrWriter(self.path / HEART_RATE_CSV)
        self._events = EventWriter(self.path / EVENTS_CSV)
        self._t0 = time.monotonic()
        if self.lsl is not None:
            self.lsl.sync(self.clock())
            self.info.extra["lsl"] = self.lsl.session_record()
            self.info.save(self.path, overwrite=True)
        self.link.start(self.path / SERIAL_DIR / f"{self.link.device}.serlog")
        if self.camera is not None:
            self.camera.start(self.path / VIDEO_AVI, self.path / VIDEO_FRAMES_CSV)
            if self._framing_wanted:
                camera = self.camera
                self.framing = FramingSampler(lambda: camera.latest_frame)
                self.framing.start()

    def _new_info(self) -> SessionInfo:
        now = _dt.datetime.now()
        devices: dict[str, Any] = {"heart_rate": self.link.settings()}
        if self.camera is not None:
            devices["camera"] = self.camera.settings()
        wanted = make_session_id(self.participant.code, now, self.label)
        session_id = free_session_id(self.out_dir, wanted)  # a capture in the same second: a suffix, stated
        return SessionInfo(
            session_id=session_id,
            participant=self.participant,
            devices=devices,
            complete=False,
            created_utc=utc_now_iso(),
            software={"name": "effortface", "version": __version__},
            extra={ID_TAKEN_KEY: wanted} if session_id != wanted else {},
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

    def _camera_fault(self, message: str) -> None:
        """The video stopped early (camera thread): a ``device_gap`` event for ``events.csv``."""
        self.queue.put(("event", DeviceEvent(self.clock(), "device_gap", "camera", message)))

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
                self._flush()
                last_flush = time.monotonic()
        self._flush()

    def _flush(self) -> None:
        self._guarded(self._hr, self._hr.flush)
        self._guarded(self._events, self._events.flush)

    def _write_item(self, item: tuple[str, Any]) -> None:
        kind, obj = item
        if kind == "hr":
            self._guarded(self._hr, lambda: self._hr.write(obj))
            self._samples += 1
            self._last = obj
        elif kind == "event":
            self._guarded(self._events, lambda: self._events.write(Event(obj.t_s, obj.kind, obj.label, obj.value)))
        if self.lsl is not None:
            self.lsl(kind, obj)

    def _guarded(self, writer: Any, action: Callable[[], None]) -> None:
        """Run a write of ``writer``'s file; a failure becomes a fault naming the file (said once)."""
        if writer.path in self._file_faults:
            return
        try:
            action()
        except OSError as exc:
            self._file_faults[writer.path] = (
                f"{writer.path}: could not write ({exc.strerror or exc}); rows from {self.clock():.1f} s on are "
                "missing (once there is room, 'effortface recover' rebuilds heart_rate.csv from the serial log)")

    @property
    def faults(self) -> list[str]:
        """What went wrong while recording, one line each naming the file (empty: nothing)."""
        out = [self.link.fault] + [self.camera.fault if self.camera else None]
        return [f for f in out if f] + list(self._file_faults.values())

    @property
    def failed(self) -> bool:
        """True if a write failed: a file may miss data, so the session cannot be marked complete."""
        return bool(self.link.fault or (self.camera and self.camera.write_failed) or self._file_faults)

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
            fault=next(iter(self.faults), None),
            framing=self.framing.latest if self.framing is not None else None,
        )

    def stop(self) -> Path:
        """Stop every device, write what is queued, and mark the session complete (idempotent).

        A session with a failed write (:attr:`failed`) stays ``complete: false``, its faults in
        ``session.json`` (``faults``), for ``effortface recover``. The recording lock is released.
        """
        assert self.path is not None and self.info is not None, "stop() before start()"
        if self._stopped:
            return self.path
        self._stopped = True
        try:
            self._stop_devices()
            self.warnings = self._warnings()
            self.info.complete = not self.failed
            self.info.extra["stats"] = self._stats()
            if self.faults:
                self.info.extra["faults"] = self.faults
            self._save_info()
        finally:
            if self._lock is not None:
                self._lock.release()
        return self.path

    def _stop_devices(self) -> None:
        """Stop camera and link, write what is queued, close the files."""
        self.mark("sync", "session_stop", utc_now_iso())
        if self.framing is not None:
            self.framing.stop()
        if self.camera is not None:
            self.camera.stop()
        self.link.stop()
        self.queue.put(("stop", None))
        if self._writer_thread is not None:
            self._writer_thread.join()
        for writer in (self._hr, self._events):
            self._close(writer)
        if self.lsl is not None:
            self.lsl.close()

    def _close(self, writer: Any) -> None:
        """Close a CSV writer even after a failed write (the file is released even when its last flush
        fails; a fault not yet said is recorded)."""
        try:
            writer.close()
        except OSError as exc:
            self._file_faults.setdefault(writer.path, f"{writer.path}: could not write ({exc.strerror or exc})")

    def _save_info(self) -> None:
        """Write session.json; on failure the previous one (``complete: false``) stays, and it is a fault."""
        assert self.path is not None and self.info is not None
        try:
            self.info.save(self.path, overwrite=True)
        except OSError as exc:
            path = self.path / "session.json"
            self._file_faults[path] = (f"{path}: could not write ({exc.strerror or exc}); the session stays "
                                       "incomplete: run 'effortface recover' on it once there is room")

    def _warnings(self) -> list[str]:
        """Soft problems worth a line: a video file replayed slower than real time, a port that
        delivered no valid heart-rate sample."""
        lag = self.camera.lag_note() if self.camera is not None else None
        out = [lag] if lag else []
        st = self.link.decoder.stats
        if st.samples - st.invalid_samples > 0 or self.link.fault:
            return out
        return out + [f"{self.link.port}: delivered no valid heart-rate sample ({st.bytes_in} bytes, {st.frames_ok} "
                f"frames decoded, {st.frames_bad} bad, {st.invalid_samples} invalid samples): check --protocol "
                "and the strap's contact"]

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
            **({"framing": self.framing.summary()} if self.framing is not None else {}),
            **({"warnings": self.warnings} if self.warnings else {}),
        }


def _folder_bytes(path: Path) -> int:
    """Total size of the files under ``path``."""
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


# ------------------------------------------------------------------------------------ recovery
#: where recovery keeps a video with no whole frame, and its frame table (the session then has none)
UNRECOVERABLE_AVI = "video.unrecoverable.avi"
UNRECOVERABLE_FRAMES_CSV = "video_frames.unrecoverable.csv"
#: where recovery keeps a heart_rate.csv with unreadable rows that it rebuilt from the serial log
DAMAGED_HR_CSV = "heart_rate.damaged.csv"


def recover_session(path: str | os.PathLike) -> dict[str, Any]:
    """Finish a session that a crash left incomplete.

    Re-indexes the video (counts the frames that decode; rewrites the AVI into a fresh MJPG file
    when its header disagrees, so seeks are exact; trims ``video_frames.csv`` to match), re-decodes
    the serial logs to restore ``heart_rate.csv`` rows lost after the last flush, drops torn last
    lines, and marks ``session.json`` complete with a ``recovered`` note. A video with no frame that
    both decodes and has a time (a crash in the first second) is kept as ``video.unrecoverable.avi``
    (its table as ``video_frames.unrecoverable.csv``), so the session has no video.

    Lines holding NUL bytes (a block of zeros a power cut can leave) are dropped like torn lines; a
    ``heart_rate.csv`` with unreadable rows is rebuilt from the serial log (the damaged file kept as
    ``heart_rate.damaged.csv``). Every repaired file is read back with the session readers before
    anything changes. A session marked complete whose video does not match its frame table (an
    older capture ignored failed video writes) is repaired too. Hidden temporary files a killed
    program left (``.*.tmp``, a stale ``.recording.lock``) are removed.

    Every repair is first written to a hidden file beside its target; only when all are ready are
    they renamed over their targets, ``session.json`` last. A failure while preparing leaves the
    folder as it was; one while renaming leaves it incomplete, and recovering again finishes it.

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
        If the folder is not a session, it is already complete (and its video matches its frame
        table), or a file cannot be read or repaired into one the session readers accept (the
        folder is left as it was).
    LockedError
        If a capture is recording the session now (its recording lock is held).
    OSError
        If a repair cannot be written (disk full...); the folder is left as it was.
    """
    folder = Path(path)
    info = read_session_info(folder)
    check_not_recording(folder, "recover")
    repairs = _Repairs()
    if info.complete:
        _check_complete_needs_repair(folder, repairs)
    try:
        _stage_text_file(folder / EVENTS_CSV, EVENTS_HEADER, repairs)
        _stage_heart_rate(folder, repairs)
        _stage_video(folder, repairs)
        _check_read_back(folder, repairs)
        repairs.commit()
    finally:
        repairs.discard()
    repairs.done += _remove_leftovers(folder)
    note = {"when": utc_now_iso(), "done": repairs.done or ["nothing to repair"]}
    info.complete = True
    info.extra["recovered"] = note
    info.save(folder, overwrite=True)
    return note


def _check_complete_needs_repair(folder: Path, repairs: _Repairs) -> None:
    """A complete session is recovered only if its video does not match its frame table."""
    avi, frames = folder / VIDEO_AVI, folder / VIDEO_FRAMES_CSV
    problems = []
    if avi.is_file() and frames.is_file():
        problems = video_problems(folder, len(_frame_rows(_kept_bytes(frames)[0], frames)))
    if not problems:
        raise SessionFormatError(f"{folder / 'session.json'}: expected an incomplete session, found complete: true")
    repairs.done.append(f"session.json: was marked complete, but {problems[0]}")


def _remove_leftovers(folder: Path) -> list[str]:
    """Remove the hidden temporary files killed programs left in the session folder; say which."""
    gone = [p for p in folder.glob(".*.tmp") if p.is_file()]
    if (folder / RECORDING_LOCK).is_file() and recording_owner(folder) is None:
        gone.append(folder / RECORDING_LOCK)
    for p in gone:
        p.unlink(missing_ok=True)
    return [f"removed {len(gone)} leftover temporary file(s): {', '.join(p.name for p in gone)}"] if gone else []


def _check_read_back(folder: Path, repairs: _Repairs) -> None:
    """Read every session file as it will be after the renames; SessionFormatError naming it if not."""
    for name, reader in ((EVENTS_CSV, read_events), (HEART_RATE_CSV, read_hr_csv),
                         (VIDEO_FRAMES_CSV, read_video_frames)):
        staged = repairs.final(folder / name)
        if staged.is_file():
            try:
                reader(staged)
            except SessionFormatError as exc:
                raise SessionFormatError(str(exc).replace(str(staged), str(folder / name))
                                         + "; recovery cannot repair it (nothing was changed)") from None


class _Repairs:
    """The renames one recovery will do, and what they repair; nothing changes before :meth:`commit`."""

    def __init__(self) -> None:
        self.done: list[str] = []
        self._scratch: list[Path] = []
        self._renames: list[tuple[Path, Path]] = []

    def scratch(self, target: Path) -> Path:
        """A hidden, empty path beside ``target`` (same extension) to build its replacement in.

        A scratch file left by an interrupted recovery is removed: it is rebuilt from the sources.
        """
        tmp = target.with_name(f".{target.stem}.recovering{target.suffix}")
        tmp.unlink(missing_ok=True)
        self._scratch.append(tmp)
        return tmp

    def final(self, target: Path) -> Path:
        """The file that will be ``target`` after :meth:`commit` (its scratch copy, or itself)."""
        for src, dst in reversed(self._renames):
            if dst == target:
                return src
        return target

    def replace(self, scratch: Path, target: Path, notes: list[str]) -> None:
        """At commit, rename the finished ``scratch`` over ``target``; ``notes`` say why."""
        self._renames.append((scratch, target))
        self.done += notes

    def keep_as(self, src: Path, dst: Path) -> None:
        """At commit, rename ``src`` to ``dst`` (never over an existing file).

        Raises
        ------
        SessionFormatError
            If ``dst`` exists already.
        """
        if dst.exists():
            raise SessionFormatError(f"{dst}: expected no file (recovery keeps {src.name} under this name), "
                                     "found one; move it out of the session and recover again")
        self._renames.append((src, dst))

    def commit(self) -> None:
        """Do the renames, in the order they were planned."""
        for src, dst in self._renames:
            os.replace(src, dst)

    def discard(self) -> None:
        """Remove the scratch files not renamed (all of them when planning failed)."""
        for tmp in self._scratch:
            tmp.unlink(missing_ok=True)


def _present(path: Path) -> bool:
    """True if a session file exists; SessionFormatError if it is a folder or not a regular file."""
    if not path.exists():
        return False
    found = not_a_file(path)
    if found:
        raise SessionFormatError(f"{path}: expected a file, found {found}")
    return True


def _kept_bytes(path: Path) -> tuple[bytes, list[str]]:
    """The bytes of a CSV a recovery keeps (a torn last line and lines with NUL bytes cut) and what was cut."""
    _present(path)
    blob = path.read_bytes()
    notes = []
    if b"\0" in blob:
        lines = blob.split(b"\n")
        kept = [line for line in lines if b"\0" not in line]
        blob = b"\n".join(kept)
        notes.append(f"{path.name}: dropped {len(lines) - len(kept)} line(s) holding NUL bytes (a block of zeros)")
    if not blob or blob.endswith(b"\n"):
        return blob, notes
    cut = blob.rfind(b"\n") + 1
    return blob[:cut], notes + [f"{path.name}: dropped a torn last line ({len(blob) - cut} bytes)"]


def _stage_text_file(path: Path, header: str, repairs: _Repairs) -> None:
    """Stage ``path`` without its torn last line (with ``header`` if it would be empty)."""
    if not path.exists():
        return
    kept, notes = _kept_bytes(path)
    if not kept:
        kept, notes = (header + "\n").encode(), notes + [f"{path.name}: wrote the missing header"]
    if notes:
        tmp = repairs.scratch(path)
        tmp.write_bytes(kept)
        repairs.replace(tmp, path, notes)


def decode_serlog(path: str | os.PathLike, notes: list[str] | None = None) -> list[HrSample]:
    """Decode a ``.serlog`` exactly as the link did live (a gap event ends the partial frame).

    Parameters
    ----------
    path : path-like
        The serial log.
    notes : list of str, optional
        Receives a line counting the corrupt event records and the damaged bytes skipped, if any.

    Returns
    -------
    list of HrSample

    Raises
    ------
    SessionFormatError
        If the file is not a serial log or its header names no known protocol.
    """
    log = read_serlog(path)
    decoder = get_decoder(header_protocol(log.header, log.path))
    out: list[HrSample] = []
    for rec in log.records:
        if rec.kind == DATA:
            out += decoder.feed(rec.payload, rec.t_s)
        elif rec.kind == EVENT and rec.event().get("kind") == "device_gap":
            out += decoder.finish()
    corrupt = sum(rec.is_corrupt_event() for rec in log.records)
    if corrupt and notes is not None:
        notes.append(f"{log.path.name}: skipped {corrupt} corrupt event record(s)")
    if log.skipped_bytes and notes is not None:
        notes.append(f"{log.path.name}: skipped {log.skipped_bytes} damaged bytes in {log.skipped_places} "
                     f"place(s) (first at byte {log.first_skip_at})")
    return out + decoder.finish()


def _stage_heart_rate(folder: Path, repairs: _Repairs) -> None:
    """Stage heart_rate.csv without a torn line, plus the samples the serial logs hold beyond it."""
    hr_path = folder / HEART_RATE_CSV
    samples = _serial_samples(folder, repairs.done)
    kept, notes = _kept_bytes(hr_path) if hr_path.exists() else (b"", [])
    if hr_path.exists() and not kept:
        notes.append(f"{HEART_RATE_CSV}: wrote the missing header")
    tmp = repairs.scratch(hr_path)
    tmp.write_bytes(kept or (HR_CSV_HEADER + "\n").encode())
    try:
        rows = _read_hr_rows(tmp, hr_path)
    except SessionFormatError as exc:  # a bad row: the serial log is the record, rebuild from it
        _stage_hr_rebuild(hr_path, tmp, str(exc), len(samples), kept.count(b"\n") - 1, repairs)
        notes.append(f"{HEART_RATE_CSV}: unreadable ({exc}); rebuilt from the serial log, the damaged file "
                     f"kept as {DAMAGED_HR_CSV}")
        rows = []
    missing = samples[len(rows):]
    if missing:
        writer = HrWriter(tmp, append=True)
        for s in missing:
            writer.write(s)
        writer.close()
        notes.append(f"{HEART_RATE_CSV}: restored {len(missing)} rows from the serial log")
    if notes:
        repairs.replace(tmp, hr_path, notes)


def _stage_hr_rebuild(hr_path: Path, tmp: Path, problem: str, n_samples: int, n_rows: int,
                      repairs: _Repairs) -> None:
    """Empty the staged heart_rate.csv to rebuild it from the serial log; keep the damaged one.

    Raises
    ------
    SessionFormatError
        If the serial log decodes to fewer samples than the damaged file has rows (rebuilding
        would lose rows).
    """
    if n_samples < n_rows:
        raise SessionFormatError(f"{problem}; the serial logs decode to {n_samples} samples, fewer than its "
                                 f"{n_rows} rows: recovery cannot rebuild it (nothing was changed)")
    tmp.write_bytes((HR_CSV_HEADER + "\n").encode())
    repairs.keep_as(hr_path, hr_path.with_name(DAMAGED_HR_CSV))


def _serial_samples(folder: Path, notes: list[str]) -> list[HrSample]:
    """Every sample the session's serial logs decode to, in time order (``notes`` get skipped events)."""
    samples: list[HrSample] = []
    for log in sorted((folder / SERIAL_DIR).glob("*.serlog")):
        samples += decode_serlog(log, notes)
    return sorted(samples, key=lambda s: s.t_s)


def _read_hr_rows(staged: Path, target: Path) -> list[HrSample]:
    """Read the staged heart-rate rows; an error names the session's file, not the scratch copy."""
    try:
        return read_hr_csv(staged)
    except SessionFormatError as exc:
        raise SessionFormatError(str(exc).replace(str(staged), str(target))) from None


def _stage_video(folder: Path, repairs: _Repairs) -> None:
    """Stage an exact video index: keep only frames that both decode and have a time."""
    avi, frames_csv = folder / VIDEO_AVI, folder / VIDEO_FRAMES_CSV
    if not _present(avi) and not _present(frames_csv):
        return
    kept, torn = _kept_bytes(frames_csv) if frames_csv.exists() else (b"", [])
    times, filled = _fill_frame_gaps(_frame_rows(kept, frames_csv), frames_csv)
    torn += filled
    n_decoded = index_video(avi) if avi.exists() else 0
    n_keep = _stage_avi(avi, n_decoded, len(times), repairs) if min(n_decoded, len(times)) else 0
    if n_keep == 0:
        _stage_no_video(avi, frames_csv, n_decoded, len(times), repairs)
        return
    if torn or len(times) != n_keep:
        trimmed = [f"{VIDEO_FRAMES_CSV}: trimmed {len(times) - n_keep} rows of frames missing from the video"]
        tmp = repairs.scratch(frames_csv)
        tmp.write_text("\n".join([FRAMES_HEADER] + times[:n_keep]) + "\n", encoding="utf-8")
        repairs.replace(tmp, frames_csv, torn + (trimmed if len(times) != n_keep else []))


def _stage_avi(avi: Path, n_decoded: int, n_times: int, repairs: _Repairs) -> int:
    """Stage a rewrite of the AVI if its header or frames disagree with the times; return frames kept.

    Returns 0 when no frame could be rewritten (the caller then keeps no video).
    """
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()

    n_keep = min(n_decoded, n_times)
    cap = cv2.VideoCapture(str(avi))
    n_header = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    cap.release()
    if n_header == n_keep and n_decoded == n_keep:
        return n_keep
    tmp = repairs.scratch(avi)
    n_written = rewrite_video(avi, tmp, max_frames=n_keep)
    if n_written:
        note = (f"{VIDEO_AVI}: header said {n_header} frames, {n_decoded} decode, {n_times} have a time; "
                f"rewrote {n_written} frames with an exact index")
        repairs.replace(tmp, avi, [note])
    return n_written


def _stage_no_video(avi: Path, frames_csv: Path, n_decoded: int, n_times: int, repairs: _Repairs) -> None:
    """No frame both decodes and has a time: keep both files under other names; no video is left."""
    kept = []
    for src, name in ((avi, UNRECOVERABLE_AVI), (frames_csv, UNRECOVERABLE_FRAMES_CSV)):
        if src.exists():
            repairs.keep_as(src, src.with_name(name))
            kept.append(f"{src.name} ({src.stat().st_size} bytes) as {name}")
    found = f"{avi.stat().st_size} bytes, {n_decoded} frames decode" if avi.exists() else "missing"
    repairs.done.append(f"{VIDEO_AVI}: no whole frame that decodes and has a time ({found}, {n_times} rows "
                        f"in {VIDEO_FRAMES_CSV}); kept {' and '.join(kept)}; the session has 0 video frames")


def _fill_frame_gaps(rows: list[str], path: Path) -> tuple[list[str], list[str]]:
    """Rows of video_frames.csv with the rows a block of zeros erased put back, and a note.

    The frames are in the video; only their times were lost: each gets a time interpolated between
    its neighbours' (said in the note).

    Raises
    ------
    SessionFormatError
        If a row is not ``frame,t_s`` or the frame numbers go back or start late.
    """
    out: list[str] = []
    for row in rows:
        try:
            frame_s, t_s = row.split(",")
            frame, t = int(frame_s), float(t_s)
        except ValueError:
            raise SessionFormatError(f"{path}: expected frame,t_s rows, found {row!r}; recovery cannot "
                                     "repair it") from None
        if out and frame > len(out):
            t0, k, n = float(out[-1].split(",")[1]), len(out), frame - len(out) + 1
            out += [f"{j},{t0 + (t - t0) * (j - k + 1) / n:.4f}" for j in range(k, frame)]
        if frame != len(out):
            raise SessionFormatError(f"{path}: expected frame {len(out)}, found {frame}; recovery cannot repair it")
        out.append(row)
    filled = len(out) - len(rows)
    return out, [f"{path.name}: gave {filled} frame(s) whose rows were lost a time interpolated between "
                 "their neighbours'"] if filled else []


def _frame_rows(blob: bytes, path: Path) -> list[str]:
    """The data lines of the bytes of video_frames.csv ``path`` (the header line skipped).

    Raises
    ------
    SessionFormatError
        If the bytes are not UTF-8 text.
    """
    try:
        lines = blob.decode("utf-8").splitlines()[1:]
    except UnicodeDecodeError as exc:
        raise SessionFormatError(f"{path}: expected UTF-8 text, found byte {blob[exc.start]:#04x} "
                                 f"at offset {exc.start}") from None
    return [line for line in lines if line.strip()]
