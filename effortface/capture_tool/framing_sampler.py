"""Capture's framing check: is the face large and lit enough for the machine rater?

:func:`check_camera_framing` looks at one frame (the camera check before Record);
:class:`FramingSampler` looks at the camera's newest frame about twice a second while recording,
in its own thread: it only reads :attr:`~effortface.capture_tool.camera.CameraSource.latest_frame`
(a reference the grabber replaces), so it never holds up a frame on its way to the disk. Both run
the face detector of the machine rater (:func:`effortface.core.framing.check_framing`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from effortface.core.errors import UserError
from effortface.core.framing import Framing, check_framing

#: seconds between two looks at the camera while recording
SAMPLE_EVERY_S = 0.5


def _engine() -> Any:
    from effortface.core.face_landmarker import FaceLandmarker

    return FaceLandmarker(num_threads=1)


def check_camera_framing(bgr: Any) -> Framing:
    """The framing of one BGR frame (as OpenCV reads it).

    Raises
    ------
    UserError
        When the face detector cannot run here (``ai-edge-litert`` not installed).
    """
    from effortface.core.opencv import import_cv2

    return check_framing(import_cv2().cvtColor(bgr, import_cv2().COLOR_BGR2RGB), _engine())


class FramingSampler:
    """Check the framing of a camera's newest frame every :data:`SAMPLE_EVERY_S`, off the recording path.

    Parameters
    ----------
    newest_frame : callable
        Returns the newest BGR frame (or None); called from the sampler's thread.
    every_s : float
        Seconds between two looks.

    Attributes
    ----------
    latest : Framing or None
        The last look's result (None before the first).
    samples, framed : int
        Frames looked at, and of those the ones framed for the rater (:attr:`Framing.ok`).
    error : str or None
        Why the sampler stopped (the detector cannot run here), one line.
    """

    def __init__(self, newest_frame: Callable[[], Any], every_s: float = SAMPLE_EVERY_S) -> None:
        self.newest_frame = newest_frame
        self.every_s = every_s
        self.latest: Framing | None = None
        self.samples = 0
        self.framed = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Start looking (a daemon thread)."""
        self._thread = threading.Thread(target=self._run, name="framing-sampler", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop looking (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def _run(self) -> None:
        from effortface.core.opencv import import_cv2

        cv2 = import_cv2()
        try:
            engine = _engine()
        except UserError as exc:
            self.error = str(exc)
            return
        seen = None
        while not self._stop.wait(self.every_s):
            frame = self.newest_frame()
            if frame is None or frame is seen:
                continue
            seen = frame
            self.latest = check_framing(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB), engine)
            self.samples += 1
            self.framed += self.latest.ok

    def summary(self) -> dict[str, Any]:
        """For ``session.json``'s ``stats.framing``: looks taken, how many were framed for the rater, the last line."""
        out: dict[str, Any] = {"samples": self.samples, "framed": self.framed,
                               "last": self.latest.line() if self.latest is not None else None}
        if self.error is not None:
            out["error"] = self.error
        return out
