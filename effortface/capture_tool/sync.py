"""The sync self-test, measured: find the on-screen flash in the recorded video (Qt-free).

The stage flashes the screen white and writes a ``sync`` event at the session time it painted the
flash. A camera that films the screen sees the frames brighten; the first bright frame's time minus
the event time is the video-to-HR offset (positive: the video stamps its frames late).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

#: a flash must raise the mean grey level by at least this much (0-255) to count
MIN_STEP = 25.0


def flash_offset_s(
    frame_t_s: Sequence[float],
    brightness: Sequence[float],
    t_flash_s: float,
    window_s: float = 2.0,
) -> float | None:
    """Offset from the flash event to the first frame that shows it.

    Parameters
    ----------
    frame_t_s : sequence of float
        Session time of each frame.
    brightness : sequence of float
        Mean grey level (0-255) of each frame.
    t_flash_s : float
        Session time of the ``sync`` event.
    window_s : float
        Search frames from one second before to ``window_s`` after the event.

    Returns
    -------
    float or None
        ``t_frame - t_flash_s`` in seconds, or None if no frame brightened by :data:`MIN_STEP`.
    """
    t = np.asarray(frame_t_s, dtype=float)
    b = np.asarray(brightness, dtype=float)
    before = b[(t >= t_flash_s - 1.0) & (t < t_flash_s)]
    if before.size == 0:
        return None
    base = float(np.median(before))
    after = np.flatnonzero((t >= t_flash_s - 1.0) & (t <= t_flash_s + window_s) & (b > base + MIN_STEP))
    if after.size == 0:
        return None
    return float(t[after[0]] - t_flash_s)


def first_flash_frame(brightness: Sequence[float], fps: float) -> int | None:
    """The first frame at least :data:`MIN_STEP` brighter than the median of the second before it.

    For a video filmed beside a watch or phone: a flash (a phone's torch, a screen turned white)
    shown at a moment the heart-rate file marks.

    Parameters
    ----------
    brightness : sequence of float
        Mean grey level (0-255) of each frame, from the first.
    fps : float
        The video's frame rate (how many frames make the second before).

    Returns
    -------
    int or None
        The frame number, or None when no frame brightens so.
    """
    b = np.asarray(brightness, dtype=float)
    span = max(1, int(round(fps)))
    for k in range(1, len(b)):
        if b[k] > float(np.median(b[max(0, k - span):k])) + MIN_STEP:
            return k
    return None


def video_brightness(video_path: str | os.PathLike, first: int, last: int) -> list[float]:
    """Mean grey level of frames ``first`` to ``last`` (inclusive) of an MJPG file.

    Parameters
    ----------
    video_path : path-like
        The session's ``video.avi``.
    first, last : int
        Frame numbers (0-based).

    Returns
    -------
    list of float
        One value per frame read (shorter if the file ends early).
    """
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()

    cap = cv2.VideoCapture(os.fspath(video_path))
    try:
        cap.set(cv2.CAP_PROP_POS_FRAMES, first)
        out: list[float] = []
        for _ in range(first, last + 1):
            ok, frame = cap.read()
            if not ok:
                break
            out.append(float(frame.mean()))
        return out
    finally:
        cap.release()
