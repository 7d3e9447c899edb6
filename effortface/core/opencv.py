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
