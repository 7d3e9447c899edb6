"""A streaming MJPG AVI writer whose every frame reaches the OS as it is written (issue 29).

OpenCV's own AVI muxer hands the file 32 KiB at a time: at 160 x 120 (about 4 KB a frame) and
1.5 fps that is five seconds of video a ``kill -9`` loses. This writer encodes each frame with
``cv2.imencode`` and appends its ``00dc`` chunk with one unbuffered ``os.write``, so a killed
process loses only the frames still in the camera's queue; :meth:`MjpgAviWriter.sync` fsyncs the
file (the camera calls it about twice a second) so a power cut loses at most that much. The index
(``idx1``) and the frame counts in the headers are written by :meth:`MjpgAviWriter.release`; a
crashed file has none, which FFmpeg reads by scanning the ``movi`` list, and ``effortface
recover`` rewrites it with an exact index.

Layout::

    RIFF 'AVI ' { LIST 'hdrl' { avih, LIST 'strl' { strh 'vids' 'MJPG', strf BITMAPINFOHEADER } },
                  LIST 'movi' { '00dc' <jpeg> ... }, idx1 }
"""

from __future__ import annotations

import errno
import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

AVIF_HASINDEX = 0x10
AVIIF_KEYFRAME = 0x10
#: JPEG quality of the frames (OpenCV's MJPG muxer default)
JPEG_QUALITY = 95
#: the largest frame side the AVI headers hold (16-bit fields)
MAX_AVI_SIDE = 32767
#: the highest nominal rate written in the headers
MAX_AVI_FPS = 1000.0
#: a placeholder size a crashed file keeps: FFmpeg reads such a RIFF or movi list to the end of the file
_OPEN_SIZE = 0


def _chunk(fourcc: bytes, payload: bytes) -> bytes:
    pad = b"\0" if len(payload) % 2 else b""
    return fourcc + struct.pack("<I", len(payload)) + payload + pad


def _list(kind: bytes, payload: bytes, size: int | None = None) -> bytes:
    return b"LIST" + struct.pack("<I", len(payload) + 4 if size is None else size) + kind + payload


def _avih(width: int, height: int, fps: float, n_frames: int, max_bytes: int) -> bytes:
    us_per_frame = int(round(1e6 / fps))
    return struct.pack("<10I4x4x4x4x", us_per_frame, int(max_bytes * fps), 0, AVIF_HASINDEX,
                       n_frames, 0, 1, max_bytes, width, height)


def _strh(width: int, height: int, fps: float, n_frames: int, max_bytes: int) -> bytes:
    rate, scale = int(round(fps * 1000)), 1000
    return b"vids" + b"MJPG" + struct.pack("<IHH8I4h", 0, 0, 0, 0, scale, rate, 0,
                                           n_frames, max_bytes, 0xFFFFFFFF, 0, 0, 0, width, height)


#: chunk ids of video frames in a ``movi`` list (compressed, uncompressed)
_FRAME_IDS = (b"00dc", b"00db")


def mjpg_frames(path: str | os.PathLike) -> Iterator[bytes]:
    """The JPEG bytes of each video frame of an MJPG AVI, in file order, read straight from its chunks.

    Walks the ``RIFF 'AVI '`` (and OpenDML ``RIFF 'AVIX'``) lists and yields the payload of every
    ``00dc`` chunk of a ``movi`` list, so frames are copied without decoding and encoding again. A
    crashed file's open sizes (0, see :class:`MjpgAviWriter`) read to the end of the file; a chunk cut
    by the end of the file ends the walk.

    Parameters
    ----------
    path : path-like
        The AVI file.

    Yields
    ------
    bytes
        One frame's JPEG data.
    """
    with open(path, "rb") as f:
        stop = os.fstat(f.fileno()).st_size
        at = 0
        while at + 8 <= stop:  # one flat walk: a list's header is stepped into, never recursed
            f.seek(at)
            fourcc, size = struct.unpack("<4sI", f.read(8))
            if fourcc in (b"RIFF", b"LIST"):
                at += 12
                continue
            if at + 8 + size > stop:  # cut by the end of the file
                return
            if fourcc in _FRAME_IDS:
                yield f.read(size)
            at += 8 + size + size % 2


class MjpgAviWriter:
    """Append MJPG frames to a new AVI, each handed to the OS at once (OpenCV ``VideoWriter``'s API).

    Parameters
    ----------
    path : path-like
        The ``.avi`` to create; an existing file is refused (FileExistsError).
    fps : float
        Nominal rate for the headers (the true times live in ``video_frames.csv``).
    size : tuple of int
        ``(width, height)`` of every frame.
    quality : int
        JPEG quality 1-100.

    Raises
    ------
    OSError
        When the file cannot be created or written (its ``filename`` is the path).
    ValueError
        When the size or rate do not fit the AVI headers (checked before the file is created).
    """

    def __init__(self, path: str | os.PathLike, fps: float, size: tuple[int, int],
                 quality: int = JPEG_QUALITY) -> None:
        self.path = Path(path)
        self.fps = float(fps)
        self.size = (int(size[0]), int(size[1]))
        if not (0 < self.fps <= MAX_AVI_FPS and all(0 < side <= MAX_AVI_SIDE for side in self.size)):
            raise ValueError(f"{self.path}: expected a frame size of 1 to {MAX_AVI_SIDE} pixels a side and 0 to "
                             f"{MAX_AVI_FPS:g} fps, found {self.size[0]}x{self.size[1]} at {self.fps:g} fps")
        self.quality = int(quality)
        self.frames = 0
        self._index: list[bytes] = []
        self._max_bytes = 0
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0),
                                       0o666)
        strl = _list(b"strl", _chunk(b"strh", _strh(*self.size, self.fps, 0, 0))
                     + _chunk(b"strf", struct.pack("<IiiHH4sIiiII", 40, *self.size, 1, 24, b"MJPG",
                                                   self.size[0] * self.size[1] * 3, 0, 0, 0, 0)))
        hdrl = _list(b"hdrl", _chunk(b"avih", _avih(*self.size, self.fps, 0, 0)) + strl)
        head = b"RIFF" + struct.pack("<I", _OPEN_SIZE) + b"AVI " + hdrl
        self._avih_at = 12 + 12 + 8  # RIFF header, LIST hdrl header, avih chunk header
        self._strh_at = 12 + 12 + 8 + 56 + 12 + 8
        self._movi_at = len(head)  # the LIST 'movi' header starts here
        self._write(head + _list(b"movi", b"", size=_OPEN_SIZE))
        self._offset = 4  # idx1 offsets count from the 'movi' fourcc

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        """True until :meth:`release`."""
        return self._fd is not None

    def write(self, frame: Any) -> None:
        """Encode one BGR frame as JPEG and append it (one ``os.write``: a kill keeps it)."""
        from effortface.core.opencv import import_cv2

        cv2 = import_cv2()
        ok, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, self.quality])
        if not ok:
            raise OSError(errno.EIO, "could not encode a JPEG frame", str(self.path))
        self.write_jpeg(buf.tobytes())

    def write_jpeg(self, jpeg: bytes) -> None:
        """Append one frame's JPEG bytes as a ``00dc`` chunk."""
        chunk = _chunk(b"00dc", jpeg)
        self._write(chunk)
        self._index.append(b"00dc" + struct.pack("<III", AVIIF_KEYFRAME, self._offset, len(jpeg)))
        self._offset += len(chunk)
        self._max_bytes = max(self._max_bytes, len(jpeg))
        self.frames += 1

    def sync(self) -> None:
        """fsync the file: the frames written so far survive a power cut."""
        if self._fd is not None:
            os.fsync(self._fd)

    def release(self) -> None:
        """Write the index and the frame counts, fsync and close (idempotent)."""
        if self._fd is None:
            return
        try:
            movi_size = self._offset
            self._write(_chunk(b"idx1", b"".join(self._index)))
            end = os.lseek(self._fd, 0, os.SEEK_CUR)
            patches = ((4, struct.pack("<I", end - 8)), (self._movi_at + 4, struct.pack("<I", movi_size)),
                       (self._avih_at, _avih(*self.size, self.fps, self.frames, self._max_bytes)),
                       (self._strh_at, _strh(*self.size, self.fps, self.frames, self._max_bytes)))
            for at, data in patches:
                os.pwrite(self._fd, data, at)
            os.fsync(self._fd)
        finally:
            fd, self._fd = self._fd, None
            os.close(fd)

    def _write(self, data: bytes) -> None:
        """Write all of ``data`` (a short write is retried; no progress raises ENOSPC naming the file)."""
        if self._fd is None:
            raise OSError(errno.EBADF, "the video is closed", str(self.path))
        fd, view = self._fd, memoryview(data)
        try:
            while view:
                n = os.write(fd, view)
                if not n:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
                view = view[n:]
        except OSError as exc:
            if exc.filename is None:
                raise OSError(exc.errno, exc.strerror, str(self.path)) from None
            raise
