"""Frame-exact video access for annotation (no Qt).

Two parts:

- :class:`FrameTimes` maps between time and frame number using the session's own frame arrival
  times (``video_frames.csv``), never ``t x nominal rate``: the sample cameras run 0.3 % slow and
  drop or delay frames, so a nominal rate drifts by whole frames within a minute.
- :class:`VideoIndex` decodes frame ``n`` exactly (MJPG is intra-frame, so a seek lands on the
  frame itself, no key-frame search), keeps an LRU cache of decoded frames and prefetches the
  neighbours of the last frame asked for on a background thread with its own decoder handle, so
  stepping and scrubbing hit the cache. The thread only fills the cache (behind a lock); it never
  touches a widget.

OpenCV is imported inside functions (it is heavy).
"""

from __future__ import annotations

import collections
import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.core.session.folder import VIDEO_AVI, read_session


def _cv2() -> Any:
    from effortface.core.opencv import import_cv2

    return import_cv2()


class FrameTimes:
    """Time <-> frame number from the recorded arrival time of each frame.

    Parameters
    ----------
    frame_times_s : sequence of float
        Arrival time of frames 0, 1, 2... in session seconds (``video_frames.csv``), non-decreasing.

    Raises
    ------
    UserError
        If there is no frame or the times decrease.
    """

    def __init__(self, frame_times_s: Sequence[float] | np.ndarray) -> None:
        t_s = np.asarray(frame_times_s, dtype=float)
        if t_s.ndim != 1 or t_s.size == 0:
            raise UserError(f"video frame times: expected at least one frame, found {t_s.size}")
        if np.any(np.diff(t_s) < 0):
            raise UserError("video frame times: expected non-decreasing t_s, found a decrease")
        self.t_s = t_s

    def __len__(self) -> int:
        return int(self.t_s.size)

    @property
    def duration_s(self) -> float:
        """Time of the last frame."""
        return float(self.t_s[-1])

    def frame_at(self, t_s: float) -> int:
        """The frame on screen at time ``t_s``: the last frame that arrived at or before it.

        Times before the first frame give frame 0, after the last frame the last frame.
        """
        i = int(np.searchsorted(self.t_s, float(t_s), side="right")) - 1
        return min(max(i, 0), len(self) - 1)

    def frames_at(self, t_s: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`frame_at`."""
        i = np.searchsorted(self.t_s, np.asarray(t_s, dtype=float), side="right") - 1
        return np.clip(i, 0, len(self) - 1)

    def t_at(self, frame: int) -> float:
        """Arrival time in seconds of ``frame``; UserError outside ``0 .. len - 1``."""
        return float(self.t_s[self.check(frame)])

    def check(self, frame: int) -> int:
        """Return ``frame`` as int if it exists, else raise UserError naming the valid range."""
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or not 0 <= frame < len(self):
            raise UserError(f"frame: expected an integer from 0 to {len(self) - 1}, found {frame!r}")
        return int(frame)

    def clamp(self, frame: int) -> int:
        """``frame`` clipped to the valid range."""
        return min(max(int(frame), 0), len(self) - 1)


class _FrameCache:
    """A thread-safe LRU of decoded frames keyed by frame number."""

    def __init__(self, capacity: int) -> None:
        self.capacity = max(1, int(capacity))
        self._frames: collections.OrderedDict[int, np.ndarray] = collections.OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0  # read by the cache test: a cached frame is never decoded again

    def get(self, frame: int) -> np.ndarray | None:
        with self._lock:
            image = self._frames.get(frame)
            if image is None:
                return None
            self._frames.move_to_end(frame)
            self.hits += 1
            return image

    def __contains__(self, frame: int) -> bool:
        with self._lock:
            return frame in self._frames

    def put(self, frame: int, image: np.ndarray) -> None:
        with self._lock:
            self._frames[frame] = image
            self._frames.move_to_end(frame)
            while len(self._frames) > self.capacity:
                self._frames.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._frames.clear()


class _Decoder:
    """One OpenCV handle that reads sequentially when it can and seeks only when it must."""

    def __init__(self, path: Path) -> None:
        cv2 = _cv2()
        # OpenCV's own MJPEG demuxer seeks exactly and fast; fall back to the default backend.
        self._cap = cv2.VideoCapture(str(path), cv2.CAP_OPENCV_MJPEG)
        if not self._cap.isOpened():
            self._cap = cv2.VideoCapture(str(path))
        if not self._cap.isOpened():
            raise UserError(f"{path}: expected a video OpenCV can decode, found an unreadable file")
        self.n_frames = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        self._next = 0  # frame the next read() returns

    def read(self, frame: int) -> np.ndarray | None:
        """Decode ``frame``; None if the file ends before it."""
        if frame != self._next:
            self._cap.set(_cv2().CAP_PROP_POS_FRAMES, frame)
        ok, image = self._cap.read()
        self._next = frame + 1 if ok else -1
        return image if ok else None

    def close(self) -> None:
        self._cap.release()


class VideoIndex:
    """Frame-exact, cached access to a session's video.

    Parameters
    ----------
    video_path : path-like
        The MJPG ``video.avi``.
    frame_times_s : sequence of float
        ``video_frames.csv`` times; frames beyond the shorter of this table and the file are absent.
    cache_frames : int
        Decoded frames kept (LRU). 256 frames at 640 x 480 are about 236 MB; at 160 x 120, 15 MB.
    prefetch_ahead, prefetch_behind : int
        Neighbours the background thread decodes after / before the last frame asked for.
    prefetch : bool
        Start the background prefetch thread (False: decode on demand only, e.g. benchmarks).

    Raises
    ------
    UserError
        If the video cannot be opened or the frame table is empty.
    """

    def __init__(self, video_path: str | os.PathLike, frame_times_s: Sequence[float] | np.ndarray, *,
                 cache_frames: int = 256, prefetch_ahead: int = 24, prefetch_behind: int = 8,
                 prefetch: bool = True) -> None:
        self.path = Path(video_path)
        if not self.path.is_file():
            raise UserError(f"{self.path}: expected a video file, found nothing")
        self._fg = _Decoder(self.path)
        n_file = self._fg.n_frames or len(frame_times_s)
        self.times = FrameTimes(np.asarray(frame_times_s, dtype=float)[:n_file])
        self.cache = _FrameCache(cache_frames)
        self.prefetch_ahead, self.prefetch_behind = int(prefetch_ahead), int(prefetch_behind)
        self._fg_lock = threading.Lock()
        self._wanted: int | None = None
        self._wake = threading.Condition()
        self._closed = False
        self._thread: threading.Thread | None = None
        if prefetch:
            self._thread = threading.Thread(target=self._prefetch_loop, name="video-prefetch", daemon=True)
            self._thread.start()

    @classmethod
    def from_session(cls, folder: str | os.PathLike, **kwargs: Any) -> VideoIndex:
        """Open the video of a session folder (UserError if it has none)."""
        session = read_session(folder)
        if session.video_path is None or not session.frame_times_s:
            raise UserError(f"{Path(folder) / VIDEO_AVI}: expected a session video with video_frames.csv, found none")
        return cls(session.video_path, session.frame_times_s, **kwargs)

    def __len__(self) -> int:
        return len(self.times)

    def __enter__(self) -> VideoIndex:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def frame_at(self, t_s: float) -> int:
        """The frame on screen at session time ``t_s`` (see :meth:`FrameTimes.frame_at`)."""
        return self.times.frame_at(t_s)

    def t_at(self, frame: int) -> float:
        """Session time of ``frame`` in seconds."""
        return self.times.t_at(frame)

    def get(self, frame: int, *, prefetch: bool = True) -> np.ndarray:
        """The decoded BGR image of ``frame`` (from the cache when it is there).

        Parameters
        ----------
        frame : int
            Frame number, ``0 .. len - 1``.
        prefetch : bool
            Ask the background thread to decode this frame's neighbours.

        Raises
        ------
        UserError
            If the frame does not exist or does not decode.
        """
        frame = self.times.check(frame)
        if prefetch:
            self.request(frame)
        image = self.cache.get(frame)
        if image is None:
            with self._fg_lock:
                image = self._fg.read(frame)
            if image is None:
                raise UserError(f"{self.path}: expected a frame {frame}, found the video ends before it")
            self.cache.put(frame, image)
        return image

    def request(self, frame: int) -> None:
        """Ask the prefetch thread to fill the cache around ``frame`` (returns at once)."""
        with self._wake:
            self._wanted = int(frame)
            self._wake.notify()

    def _prefetch_loop(self) -> None:
        decoder = _Decoder(self.path)
        try:
            while True:
                with self._wake:
                    while self._wanted is None and not self._closed:
                        self._wake.wait()
                    if self._closed:
                        return
                    centre, self._wanted = self._wanted, None
                # not None: the wait above ends only on a request or on close
                self._fill_around(decoder, centre)  # type: ignore[arg-type]  # see above
        finally:
            decoder.close()

    def _fill_around(self, decoder: _Decoder, centre: int) -> None:
        """Decode the missing neighbours of ``centre``, ahead first; stop early on a new request."""
        ahead = range(centre, min(centre + self.prefetch_ahead + 1, len(self)))
        behind = range(centre - 1, max(centre - self.prefetch_behind, 0) - 1, -1)
        for frame in (*ahead, *behind):
            if self._wanted is not None or self._closed:
                return
            if frame in self.cache:
                continue
            image = decoder.read(frame)
            if image is None:
                return
            self.cache.put(frame, image)

    def close(self) -> None:
        """Stop the prefetch thread and release the decoders (idempotent)."""
        with self._wake:
            self._closed = True
            self._wake.notify()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        with self._fg_lock:
            self._fg.close()
        self.cache.clear()
