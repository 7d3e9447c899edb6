"""A minimal MJPG AVI (RIFF, AVI 1.0 with an ``idx1`` index) writer with a chosen JPEG quality.

OpenCV's ``VideoWriter`` ignores the JPEG quality with its FFmpeg backend (about 3 KB a frame at
160x120) and its built-in MJPG backend (about 6.5 KB); the sample lab must fit in 25 MB, so frames
are compressed with ``cv2.imencode`` at :data:`JPEG_QUALITY` and wrapped here. The result is a plain
MJPG AVI that OpenCV (and FFmpeg) read with exact seeks; the bytes are deterministic.

Layout::

    RIFF 'AVI ' { LIST 'hdrl' { avih, LIST 'strl' { strh 'vids' 'MJPG', strf BITMAPINFOHEADER } },
                  LIST 'movi' { '00dc' <jpeg> ... }, idx1 }
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterable
from pathlib import Path

import numpy as np

AVIF_HASINDEX = 0x10
AVIIF_KEYFRAME = 0x10


def _chunk(fourcc: bytes, payload: bytes) -> bytes:
    pad = b"\0" if len(payload) % 2 else b""
    return fourcc + struct.pack("<I", len(payload)) + payload + pad


def _list(kind: bytes, payload: bytes) -> bytes:
    return b"LIST" + struct.pack("<I", len(payload) + 4) + kind + payload


def _headers(width: int, height: int, fps: float, n_frames: int, max_bytes: int) -> bytes:
    """``hdrl`` list: main header, then one video stream header and format."""
    us_per_frame = int(round(1e6 / fps))
    rate, scale = int(round(fps * 1000)), 1000
    avih = struct.pack("<10I4x4x4x4x", us_per_frame, int(max_bytes * fps), 0, AVIF_HASINDEX,
                       n_frames, 0, 1, max_bytes, width, height)
    strh = b"vids" + b"MJPG" + struct.pack("<IHH8I4h", 0, 0, 0, 0, scale, rate, 0,
                                           n_frames, max_bytes, 0xFFFFFFFF, 0, 0, 0, width, height)
    strf = struct.pack("<IiiHH4sIiiII", 40, width, height, 1, 24, b"MJPG", width * height * 3,
                       0, 0, 0, 0)
    return _list(b"hdrl", _chunk(b"avih", avih) + _list(b"strl", _chunk(b"strh", strh) + _chunk(b"strf", strf)))


def encode_jpeg(frame_bgr: np.ndarray, quality: int) -> bytes:
    """JPEG bytes of one BGR frame at ``quality`` (1-100), with optimised Huffman tables."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()

    ok, buf = cv2.imencode(".jpg", frame_bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality),
                                                cv2.IMWRITE_JPEG_OPTIMIZE, 1])
    if not ok:
        raise RuntimeError("cv2.imencode could not encode a JPEG frame")
    return buf.tobytes()


def write_mjpg_avi(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float,
                   quality: int = 50) -> int:
    """Write BGR frames (all the same size) as an MJPG AVI; return the number of frames.

    Parameters
    ----------
    path : path-like
        The ``.avi`` to create (an existing file is refused: FileExistsError).
    frames : iterable of numpy.ndarray
        BGR uint8 images of one size.
    fps : float
        Nominal rate written in the header (the true times live in ``video_frames.csv``).
    quality : int
        JPEG quality.
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path}: video exists; refusing to overwrite")
    jpegs: list[bytes] = []
    size: tuple[int, int] | None = None
    for frame in frames:
        size = size or (frame.shape[1], frame.shape[0])
        if (frame.shape[1], frame.shape[0]) != size:
            raise ValueError(f"frames: expected {size[0]}x{size[1]}, found {frame.shape[1]}x{frame.shape[0]}")
        jpegs.append(encode_jpeg(frame, quality))
    if size is None:
        raise ValueError("frames: expected at least one frame, found none")
    movi, index, offset = [], [], 4
    for jpg in jpegs:
        movi.append(_chunk(b"00dc", jpg))
        index.append(b"00dc" + struct.pack("<III", AVIIF_KEYFRAME, offset, len(jpg)))
        offset += len(movi[-1])
    body = _headers(*size, fps, len(jpegs), max(map(len, jpegs)))
    body += _list(b"movi", b"".join(movi)) + _chunk(b"idx1", b"".join(index))
    with open(path, "xb") as fh:
        fh.write(b"RIFF" + struct.pack("<I", len(body) + 4) + b"AVI " + body)
    return len(jpegs)
