"""The one place OpenCV is imported: quiet, so our one-line errors are the only thing a user reads.

OpenCV logs its own warnings on stderr ("[ WARN:0@0.02] global cap_v4l.cpp ... can't open camera by
index") before our :class:`~effortface.core.errors.UserError` line says the same thing in the user's
terms. :func:`import_cv2` imports ``cv2`` lazily (the runtime and ``effortface decode`` never pay for
it) and sets OpenCV's log level once, to silent, unless the user asked for a level with the
environment variable ``OPENCV_LOG_LEVEL`` (OpenCV's own, for debugging a camera).
"""

from __future__ import annotations

import os
from types import ModuleType

#: environment variable with which a user keeps OpenCV's own log (OpenCV reads it at import)
OPENCV_LOG_ENV = "OPENCV_LOG_LEVEL"

_quieted = False


def import_cv2() -> ModuleType:
    """Import ``cv2``, its log level set to silent on first use (unless ``OPENCV_LOG_LEVEL`` is set).

    Returns
    -------
    module
        The ``cv2`` module.
    """
    global _quieted
    import cv2

    if not _quieted:
        if not os.environ.get(OPENCV_LOG_ENV):
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
        _quieted = True
    return cv2


def avi_header_frames(path: str | os.PathLike[str]) -> int:
    """The frame count an AVI's header and index claim (quick: nothing is decoded; 0 if unreadable).

    A finished or recovered capture's header is exact, so a frame table of another length means the
    table or the video is not this session's; :func:`index_video` decodes the frames instead.

    Parameters
    ----------
    path : path-like
        The video file.

    Returns
    -------
    int
    """
    cv2 = import_cv2()
    cap = cv2.VideoCapture(str(path))
    try:
        return int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0) if cap.isOpened() else 0
    finally:
        cap.release()


def index_video(path: str | os.PathLike[str]) -> int:
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
    cv2 = import_cv2()
    cap = cv2.VideoCapture(str(path))
    n = 0
    try:
        while cap.grab():
            n += 1
    finally:
        cap.release()
    return n
