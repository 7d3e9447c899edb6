"""The camera: frames from a webcam (or a video file at its real rate) stamped on arrival, written
to an MJPG ``video.avi`` with one ``frame,t_s`` row per written frame in ``video_frames.csv``.

Two threads: the grabber stamps each frame with the session clock the moment it arrives and puts
it in a bounded queue; the writer encodes and appends. When the writer cannot keep up, the queue is
full and the grabber drops the frame and counts it (``dropped``), so the timing of the frames that
are kept is never distorted. OpenCV is imported inside functions (it is heavy).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from effortface.core.errors import DeviceError, DeviceErrorReason, UserError
from effortface.capture_tool.session import FrameTimeWriter

FOURCC = "MJPG"
_STOP = object()


def _cv2() -> Any:
    import cv2

    return cv2


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
    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
    return cap


class CameraSource:
    """Grab, stamp and record video.

    Parameters
    ----------
    source : int or path-like
        Camera index, or a video file played at its own frame rate (for tests and demos).
    clock : callable
        Session clock in seconds.
    queue_frames : int
        Frames that may wait for the writer before new ones are dropped.
    loop : bool
        Restart a video file at its end instead of stopping.

    Attributes
    ----------
    frames_written, dropped : int
        Frames on disk and frames the writer could not keep up with.
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
    ) -> None:
        self.source = source
        self.clock = clock
        self.loop = loop
        self.frames_written = 0
        self.grabbed = 0
        self.dropped = 0
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
        for target, name in ((self._write_loop, "camera-writer"), (self._grab_loop, "camera-grab")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)

    def _grab_loop(self) -> None:
        is_file = not isinstance(self.source, int)
        t_start = time.monotonic()
        n = 0
        while not self._stop.is_set():
            if is_file and self._stop.wait(max(0.0, t_start + n / self.fps - time.monotonic())):
                break
            ok, frame = self._cap.read()
            t_s = self.clock()
            if not ok:
                if is_file and self.loop and n > 0:
                    self._cap.set(_cv2().CAP_PROP_POS_FRAMES, 0)
                    continue
                self.ended = True
                break
            n += 1
            self._offer(frame, t_s)
        self._queue.put(_STOP)

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
            frame, t_s = item
            self._writer.write(frame)
            self._times.write(self.frames_written, t_s)
            self.frames_written += 1
            if self._queue.empty():  # caught up: hand the rows to the OS (kill -9 keeps them)
                self._times.flush()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop grabbing, write the queued frames, close the files (idempotent)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout_s)
        self._threads = []
        if hasattr(self, "_writer"):
            self._writer.release()
            self._times.close()
        self._cap.release()

    def wait_ended(self, timeout_s: float | None = None) -> bool:
        """Wait until a (non-looping) video file source has been fully grabbed."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.ended:
            if deadline is not None and time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True


def open_avi_writer(path: str | os.PathLike, fps: float, size: tuple[int, int]) -> Any:
    """An MJPG AVI writer through OpenCV's own AVI muxer (``CAP_OPENCV_MJPEG``).

    Why not the default FFmpeg backend: it holds whole frames in its buffers, so a ``kill -9``
    can leave an empty file; OpenCV's muxer hands every 32 KiB to the OS (under one frame at
    640 x 480), so a crash loses at most the last frames. Raises UserError if it cannot open.
    """
    cv2 = _cv2()
    writer = cv2.VideoWriter(str(path), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*FOURCC), fps, size)
    if not writer.isOpened():
        raise UserError(f"{path}: expected a writable MJPG video file, found OpenCV could not open it")
    return writer


def index_video(path: str | os.PathLike) -> int:
    """Count the frames of a video by decoding it to the end (headers of a crashed AVI lie).

    Parameters
    ----------
    path : path-like
        The video file.

    Returns
    -------
    int
        Frames that decode.
    """
    cv2 = _cv2()
    cap = cv2.VideoCapture(str(path))
    n = 0
    try:
        while cap.grab():
            n += 1
    finally:
        cap.release()
    return n


def avi_frame_count(path: str | os.PathLike) -> int:
    """Frames the video's header declares (cheap; :func:`index_video` decodes them all instead).

    A finished or recovered capture's header is exact, so a frame table of another length means the
    table or the video is not this session's.
    """
    cv2 = _cv2()
    cap = cv2.VideoCapture(str(path))
    try:
        return int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0) if cap.isOpened() else 0
    finally:
        cap.release()


def rewrite_video(src: str | os.PathLike, dst: str | os.PathLike, max_frames: int | None = None) -> int:
    """Copy the decodable frames of ``src`` into a fresh MJPG AVI ``dst`` (a correct index).

    Returns
    -------
    int
        Frames written.
    """
    cv2 = _cv2()
    dst = Path(dst)
    if dst.exists():
        raise FileExistsError(f"{dst}: exists; refusing to overwrite")
    cap = cv2.VideoCapture(str(src))
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    writer = None
    n = 0
    try:
        while max_frames is None or n < max_frames:
            ok, frame = cap.read()
            if not ok:
                break
            if writer is None:
                h, w = frame.shape[:2]
                writer = open_avi_writer(dst, fps if fps >= 1 else 30.0, (w, h))
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
