"""The camera: frames from a webcam (or a video file at its real rate) stamped on arrival, written
to an MJPG ``video.avi`` with one ``frame,t_s`` row per written frame in ``video_frames.csv``.

Two threads: the grabber stamps each frame with the session clock the moment it arrives and puts
it in a bounded queue; the writer encodes and appends. When the writer cannot keep up, the queue is
full and the grabber drops the frame and counts it (``dropped``), so the timing of the frames that
are kept is never distorted. A video file gives every frame from the first, none skipped (its
grabber waits for the writer instead); frames it had not reached by the stop because it fell behind
real time are counted as dropped and said (:meth:`CameraSource.lag_note`). OpenCV is imported inside functions (it is heavy).

Every frame reaches the OS as it is written (:mod:`~effortface.capture_tool.avi_writer`), the frame
table at least every :data:`FLUSH_EVERY_S`, and both are fsynced every :data:`SYNC_EVERY_S`, so a
``kill -9`` at any frame rate loses under a second (issue 29). The writer watches the disk itself (issue 17): it stops
the video cleanly, before a write can fail, when the disk or the process's file-size limit
(``RLIMIT_FSIZE``) leaves too little room; and it notices a write that failed anyway (the AVI stops
growing while frames go in). Either way the reason is :attr:`CameraSource.fault` (one line naming
the file), later frames are counted in ``dropped``, and :attr:`CameraSource.write_failed` says the
AVI may miss frames that ``video_frames.csv`` lists (then the session must be recovered).
"""

from __future__ import annotations

import math
import os
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

try:
    import resource
except ImportError:  # pragma: no cover - not POSIX: no file-size limit to watch
    resource = None  # type: ignore[assignment]

from effortface.core.errors import DeviceError, DeviceErrorReason, UserError
from effortface.capture_tool.avi_writer import MAX_AVI_FPS, MAX_AVI_SIDE, MjpgAviWriter, mjpg_frames
from effortface.core.opencv import avi_header_frames, index_video  # noqa: F401  (the session format counts frames too)
from effortface.core.session.folder import FrameTimeWriter

FOURCC = "MJPG"
_STOP = object()
#: OpenCV's AVI muxer hands the file 32 KiB at a time
MUXER_CHUNK_BYTES = 32768
#: free disk kept for the heart-rate files, the events and session.json once the video stops
DISK_RESERVE_BYTES = 2 << 20
#: frames that may go in before the first byte reaches the disk (tiny frames fill a chunk slowly)
FIRST_GROWTH_FRAMES = 300
#: the frame table is handed to the OS at least this often, even while the writer is behind
FLUSH_EVERY_S = 0.5
#: the video and the frame table are fsynced this often (a power cut loses at most this much)
SYNC_EVERY_S = 1.0
#: a video file replayed this much later than its own timing is reported (:meth:`CameraSource.lag_note`)
LAG_NOTE_S = 1.0


def _cv2() -> Any:
    from effortface.core.opencv import import_cv2

    return import_cv2()


def open_capture(source: int | str | os.PathLike) -> Any:
    """Open a camera index or a video file with OpenCV.

    Raises
    ------
    UserError
        If a camera index is negative, or a video file is missing or cannot be decoded.
    DeviceError
        If the camera index cannot be opened (reason NOT_FOUND).
    """
    if isinstance(source, int) and source < 0:
        raise UserError(f"--camera: expected a camera index >= 0, found {source}")
    cv2 = _cv2()
    if isinstance(source, int):
        cap = cv2.VideoCapture(source)
        if not cap.isOpened():
            raise DeviceError(f"--camera {source}: expected a camera, found none at that index", DeviceErrorReason.NOT_FOUND)
        return cap
    path = Path(source)
    if not path.is_file():
        raise UserError(f"--video {path}: expected a video file, found {'a folder' if path.exists() else 'nothing'}")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened() or not cap.read()[0]:
        raise UserError(f"--video {path}: expected a video OpenCV can decode, found an unreadable file")
    cap.release()  # opened again, not seeked back: a seek to frame 0 lands on frame 12 of an MPEG-1 file
    return cv2.VideoCapture(str(path))


class CameraSource:
    """Grab, stamp and record video.

    Parameters
    ----------
    source : int or path-like
        Camera index, or a video file played at its own frame rate, every frame from the first (tests, demos).
    clock : callable
        Session clock in seconds.
    queue_frames : int
        Frames that may wait for the writer before new ones are dropped.
    loop : bool
        Restart a video file at its end instead of stopping.

    Attributes
    ----------
    frames_written, dropped : int
        Frames handed to the writer, and frames not recorded (the writer could not keep up, the
        video stopped on a fault, or a video file's frames were due by the stop but not reached).
    late_frames : int
        Of ``dropped``: a video file's frames due by the stop that decoding had not reached.
    lag_s : float
        A video file: how late (seconds) its latest-replayed frame came against the file's timing.
    fault : str or None
        Why the video stopped early: one line naming the file.
    write_failed : bool
        True if a write failed: the AVI may miss frames ``video_frames.csv`` lists.
    width, height : int
    fps : float
        Nominal rate (what the camera or file claims).
    """

    def __init__(
        self,
        source: int | str | os.PathLike,
        clock: Callable[[], float],
        queue_frames: int = 30,
        loop: bool = False,
        on_fault: Callable[[str], None] | None = None,
    ) -> None:
        self.source = source
        self.on_fault = on_fault
        self.fault: str | None = None
        self.write_failed = False
        self._size_at_growth = 0
        self._frames_at_growth = 0
        self.clock = clock
        self.loop = loop
        self.frames_written = 0
        self.grabbed = 0
        self.dropped = 0
        self.late_frames = 0
        self.lag_s = 0.0
        self.latest_frame: Any = None  # newest grabbed frame (a reference, for previews)
        self.ended = False
        self._cap = open_capture(source)
        cv2 = _cv2()
        self.width = int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = fps if 1.0 <= fps <= 240.0 else 30.0
        self._queue: queue.Queue = queue.Queue(maxsize=queue_frames)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def settings(self) -> dict[str, Any]:
        """Source, size, nominal fps and codec, for ``session.json``."""
        src = self.source if isinstance(self.source, int) else str(self.source)
        return {"source": src, "width": self.width, "height": self.height, "fps": self.fps, "codec": FOURCC}

    def start(self, avi_path: str | os.PathLike, frames_csv: str | os.PathLike) -> None:
        """Create ``avi_path`` (MJPG) and ``frames_csv`` (``frame,t_s``) and start the threads.

        Raises
        ------
        FileExistsError
            If either file exists (never overwritten).
        """
        self.avi_path = Path(avi_path)
        self.frames_csv = Path(frames_csv)
        if self.avi_path.exists():
            raise FileExistsError(f"{self.avi_path}: exists; refusing to overwrite")
        self._writer = open_avi_writer(self.avi_path, self.fps, (self.width, self.height))
        self._times = FrameTimeWriter(self.frames_csv)
        self._flushed_at = self._synced_at = time.monotonic()
        for target, name in ((self._write_loop, "camera-writer"), (self._grab_loop, "camera-grab")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)

    def _grab_loop(self) -> None:
        if isinstance(self.source, int):
            self._grab_camera()
        else:
            self._grab_file()
        self._queue.put(_STOP)

    def _grab_camera(self) -> None:
        """A camera's frames as they come; a frame the writer has no room for is dropped and counted."""
        while not self._stop.is_set():
            ok, frame = self._cap.read()
            t_s = self.clock()
            if not ok:
                self.ended = True
                break
            self._offer(frame, t_s)

    def _grab_file(self) -> None:
        """Every frame of the file from the first, in order, each no earlier than its time in the file.

        No frame is skipped: a writer behind holds the reading back (the queue waits). When decoding
        and writing are slower than real time the replay falls behind: the worst lateness is
        :attr:`lag_s`, and the frames that were due by the stop but not reached are counted in
        :attr:`late_frames` (and in :attr:`dropped`).
        """
        t_start = time.monotonic()
        n = 0
        while not self._stop.is_set():
            if self._stop.wait(max(0.0, t_start + n / self.fps - time.monotonic())):
                break
            ok, frame = self._cap.read()
            t_s = self.clock()
            if not ok:
                if self.loop and n > 0:
                    self._cap.release()
                    self._cap = open_capture(self.source)  # opened again: a seek to 0 may miss the first frames
                    continue
                self.ended = True
                return
            self.lag_s = max(self.lag_s, time.monotonic() - (t_start + n / self.fps))
            n += 1
            self.grabbed += 1
            self.latest_frame = frame
            self._queue.put((frame, t_s))  # waits while the writer is behind: a file's frames are never skipped
        self._count_late(t_start, n)

    def _count_late(self, t_start: float, n_read: int) -> None:
        """At a stop before the file's end: the frames due by now that were not read count as dropped."""
        due = math.floor((time.monotonic() - t_start) * self.fps) + 1
        total = int(self._cap.get(_cv2().CAP_PROP_FRAME_COUNT) or 0)
        if total > 0 and not self.loop:
            due = min(due, total)
        self.late_frames = max(0, due - n_read)
        self.dropped += self.late_frames

    def lag_note(self) -> str | None:
        """One line when a video file could not be replayed in real time (None when it kept up).

        It names the file, the frames due by the stop that were not recorded (dropped) and the worst lateness.
        """
        if isinstance(self.source, int) or (self.late_frames == 0 and self.lag_s <= LAG_NOTE_S):
            return None
        head = (f"--video {self.source}: could not keep up in real time ({self.width}x{self.height} at "
                f"{self.fps:g} fps; a frame came up to {self.lag_s:.1f} s late)")
        if self.late_frames == 0:
            return f"{head}: every frame recorded, stamped when it was read"
        return f"{head}: {self.late_frames} frames due by the stop were not recorded (dropped)"

    def _offer(self, frame: Any, t_s: float) -> None:
        """Queue a frame for the writer, or drop and count it when the writer is behind."""
        self.grabbed += 1
        self.latest_frame = frame
        try:
            self._queue.put_nowait((frame, t_s))
        except queue.Full:
            self.dropped += 1

    def _write_loop(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                break
            if self.fault is None:
                self._set_fault(self._room_problem())
            if self.fault is not None:
                self.dropped += 1  # the video stopped: the frame is counted, not written
                continue
            try:
                self._write_frame(*item)
            except OSError as exc:
                self._set_fault(f"{exc.filename or self.frames_csv}: could not write ({exc.strerror}); video "
                                f"stopped after frame {self.frames_written}", failed=True)

    def _write_frame(self, frame: Any, t_s: float) -> None:
        """Append one frame and its time; watch that the AVI keeps growing."""
        self._writer.write(frame)
        self._times.write(self.frames_written, t_s)
        self.frames_written += 1
        self._check_growth()
        now = time.monotonic()
        if self._queue.empty() or now - self._flushed_at >= FLUSH_EVERY_S:  # kill -9 keeps the rows
            self._times.flush()
            self._flushed_at = now
        if now - self._synced_at >= SYNC_EVERY_S:  # a power cut keeps them too
            self._writer.sync()
            self._times.sync()
            self._synced_at = now

    def _set_fault(self, message: str | None, failed: bool = False) -> None:
        """Stop the video for ``message`` (nothing if None) and tell :attr:`on_fault` once."""
        if message is None or self.fault is not None:
            return
        self.fault, self.write_failed = message, failed
        if self.on_fault is not None:
            self.on_fault(message)

    def _room_problem(self) -> str | None:
        """Why the next frame must not be written (the disk or the file-size limit is near), or None."""
        size = self._size_at_growth
        per_frame = size / self._frames_at_growth if self._frames_at_growth else 0.0
        needed = 3 * MUXER_CHUNK_BYTES + 2 * per_frame + 16 * (self.frames_written + 1)  # + the index
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0] if resource else -1  # -1: RLIM_INFINITY
        if limit >= 0 and os.stat(self.avi_path).st_size + needed > limit:
            return (f"{self.avi_path}: video stopped after frame {self.frames_written}: the file-size limit "
                    f"({limit} bytes) is reached; later frames are dropped")
        st = os.statvfs(self.avi_path.parent)
        free = st.f_bavail * st.f_frsize
        if free < needed + DISK_RESERVE_BYTES:
            return (f"{self.avi_path}: video stopped after frame {self.frames_written}: the disk is full "
                    f"({free / 2**20:.1f} MiB left, {DISK_RESERVE_BYTES >> 20} MiB kept for heart rate and "
                    "events); later frames are dropped")
        return None

    def _check_growth(self) -> None:
        """Fault if the AVI stopped growing while frames went in (a write failed unseen)."""
        size = os.stat(self.avi_path).st_size
        if size > self._size_at_growth:
            self._size_at_growth, self._frames_at_growth = size, self.frames_written
            return
        since = self.frames_written - self._frames_at_growth
        per_frame = self._size_at_growth / self._frames_at_growth if self._frames_at_growth else 0.0
        limit = max(8, math.ceil(3 * MUXER_CHUNK_BYTES / per_frame)) if per_frame else FIRST_GROWTH_FRAMES
        if since > limit:
            self._set_fault(f"{self.avi_path}: video writes failed: the file stopped growing at {size} bytes "
                            f"after frame {self._frames_at_growth} while {since} more frames went in (disk full "
                            "or file-size limit?); run 'effortface recover' on the session", failed=True)

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop grabbing, write the queued frames, close the files (idempotent)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout_s)
        self._threads = []
        if hasattr(self, "_writer"):
            try:
                self._writer.release()
            except OSError as exc:  # the index could not be written: recover rebuilds it
                self._set_fault(f"{exc.filename or self.avi_path}: could not write the video's index "
                                f"({exc.strerror}); run 'effortface recover' on the session", failed=True)
            try:
                self._times.close()
            except OSError as exc:
                self._set_fault(f"{self.frames_csv}: could not write ({exc.strerror})", failed=True)
            self._check_closed_video()
        self._cap.release()

    def _check_closed_video(self) -> None:
        """After release: the AVI's index must count every frame written (else a write failed)."""
        if self.write_failed or self.frames_written == 0:
            return
        n_header = avi_header_frames(self.avi_path)
        if n_header != self.frames_written:
            self._set_fault(f"{self.avi_path}: holds {n_header} frames in its index, expected "
                            f"{self.frames_written} (a write failed); run 'effortface recover' on the session",
                            failed=True)

    def wait_ended(self, timeout_s: float | None = None) -> bool:
        """Wait until a (non-looping) video file source has been fully grabbed."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.ended:
            if deadline is not None and time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True


def open_avi_writer(path: str | os.PathLike, fps: float, size: tuple[int, int]) -> MjpgAviWriter:
    """A streaming MJPG AVI writer (:class:`~effortface.capture_tool.avi_writer.MjpgAviWriter`).

    Why not OpenCV's writers: the FFmpeg backend holds whole frames in its buffers and OpenCV's own
    muxer hands the file 32 KiB at a time (five seconds of 160 x 120 video at 1.5 fps), so a
    ``kill -9`` lost seconds; this one writes every frame to the OS as it comes. Raises UserError if
    the file cannot be created.
    """
    try:
        return MjpgAviWriter(path, fps, size)
    except FileExistsError:
        raise FileExistsError(f"{path}: exists; refusing to overwrite") from None
    except OSError as exc:
        raise UserError(f"{path}: expected a writable MJPG video file, found {exc.strerror or exc}") from None
    except ValueError as exc:  # a size or rate the AVI headers cannot hold
        raise UserError(str(exc)) from None


def rewrite_video(src: str | os.PathLike, dst: str | os.PathLike, max_frames: int | None = None) -> int:
    """Copy the decodable frames of ``src`` into a fresh MJPG AVI ``dst`` (a correct index).

    The frames of an MJPG AVI are copied byte for byte (:func:`copy_mjpg_frames`: no second JPEG
    encoding, the recovered video is the recorded one); any other video is decoded and encoded.
    Either way the copy stops at the first frame that does not decode, or after ``max_frames``.

    Returns
    -------
    int
        Frames written.
    """
    dst = Path(dst)
    if dst.exists():
        raise FileExistsError(f"{dst}: exists; refusing to overwrite")
    return copy_mjpg_frames(src, dst, max_frames) or _reencode_video(src, dst, max_frames)


def _avi_fps(src: str | os.PathLike) -> float:
    """The nominal frame rate OpenCV reads from a video's headers (30 when it has none or an absurd one)."""
    cv2 = _cv2()
    cap = cv2.VideoCapture(str(src))
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    cap.release()
    return fps if 1 <= fps <= MAX_AVI_FPS else 30.0


def copy_mjpg_frames(src: str | os.PathLike, dst: str | os.PathLike, max_frames: int | None = None) -> int:
    """Copy an MJPG AVI's frames, undecoded, into a new AVI; 0 (and no ``dst``) if ``src`` has none.

    Frames are taken in file order while each decodes (``cv2.imdecode``) to the first frame's size.

    Parameters
    ----------
    src, dst : path-like
        The AVI to read and the one to create (an existing ``dst`` is refused).
    max_frames : int, optional
        Stop after this many frames.

    Returns
    -------
    int
        Frames copied.
    """
    cv2 = _cv2()
    writer: MjpgAviWriter | None = None
    n = 0
    try:
        for jpeg in mjpg_frames(src):
            if max_frames is not None and n >= max_frames:
                break
            image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
            size = None if image is None else (image.shape[1], image.shape[0])
            if size is None or max(size) > MAX_AVI_SIDE or (writer is not None and size != writer.size):
                break
            if writer is None:
                writer = open_avi_writer(dst, _avi_fps(src), size)
            writer.write_jpeg(jpeg)
            n += 1
    finally:
        if writer is not None:
            writer.release()
    return n


def _reencode_video(src: str | os.PathLike, dst: Path, max_frames: int | None) -> int:
    """Decode ``src`` with OpenCV and encode each frame into a new MJPG AVI ``dst``; frames written."""
    cv2 = _cv2()
    fps = _avi_fps(src)
    cap = cv2.VideoCapture(str(src))
    writer = None
    n = 0
    try:
        while max_frames is None or n < max_frames:
            ok, frame = cap.read()
            if not ok or max(frame.shape[:2]) > MAX_AVI_SIDE:
                break
            if writer is None:
                h, w = frame.shape[:2]
                writer = open_avi_writer(dst, fps, (w, h))
            writer.write(frame)
            n += 1
    finally:
        cap.release()
        if writer is not None:
            writer.release()
    return n


def read_frame(path: str | os.PathLike, n: int) -> Any:
    """Return frame ``n`` (0-based, BGR array) of a video by seeking.

    Raises
    ------
    UserError
        If the video cannot be opened or has no frame ``n``.
    """
    cv2 = _cv2()
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise UserError(f"{path}: expected a video OpenCV can decode, found an unreadable file")
        cap.set(cv2.CAP_PROP_POS_FRAMES, n)
        ok, frame = cap.read()
    finally:
        cap.release()
    if not ok:
        raise UserError(f"{path}: expected a frame {n}, found the video ends before it")
    return frame


def list_cameras() -> list[str]:
    """Video devices present (``/dev/video*`` on Linux); empty where none or not Linux."""
    return sorted(str(p) for p in Path("/dev").glob("video*"))
