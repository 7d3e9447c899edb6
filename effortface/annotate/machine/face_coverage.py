"""After a session is rated: did the machine rater see a face on enough frames, and if not, why?

``effortface preannotate`` ends with a warning line and exit status 1 when fewer than half of a
session's frames have a face (:func:`coverage_warning`). The likely cause comes from the framing
check Capture runs (:func:`effortface.core.framing.check_framing`) on a few of the frames without a
face: the face is there but too small (size), the video is dark (darkness), or no face at all (none
found).
"""

from __future__ import annotations

import statistics
from pathlib import Path

import numpy as np

from effortface.annotate.machine.track import MachineTrack
from effortface.core.framing import MIN_FACE_SHARE, Framing, check_framing
from effortface.core.session.folder import VIDEO_AVI

#: a session whose share of frames with a face is below this gets the warning
MIN_FACE_FRAMES = 0.5
#: frames without a face that the cause is read from (evenly spread)
CAUSE_LOOKS = 9


def coverage_warning(session_dir: Path, track: MachineTrack) -> str | None:
    """One line when fewer than half the frames have a face (None otherwise), naming the likely cause.

    ``effortface preannotate`` prints it after ``warning: `` and exits with status 1.
    """
    n = len(track.frame)
    found = int(np.count_nonzero(track.face))
    if n == 0 or found >= MIN_FACE_FRAMES * n:
        return None
    cause = likely_cause(Path(session_dir) / VIDEO_AVI, np.flatnonzero(~np.asarray(track.face, bool)))
    return f"{session_dir}: a face on {found} of {n} frames (fewer than half); likely cause: {cause}"


def likely_cause(video: Path, frames: np.ndarray) -> str:
    """Why the rater found no face on ``frames`` of ``video``: size, darkness or none found, with the figures."""
    from effortface.core.face_landmarker import FaceLandmarker
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    picks = frames[np.linspace(0, len(frames) - 1, min(CAUSE_LOOKS, len(frames))).round().astype(int)]
    engine = FaceLandmarker(num_threads=1)
    looks: list[Framing] = []
    cap = cv2.VideoCapture(str(video))
    try:
        for frame in picks:
            cap.set(cv2.CAP_PROP_POS_FRAMES, int(frame))  # the session's MJPG video seeks exactly
            ok, bgr = cap.read()
            if ok:
                looks.append(check_framing(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), engine))
    finally:
        cap.release()
    return describe_cause(looks)


def describe_cause(looks: list[Framing]) -> str:
    """The most common cause among the looks, in words with its figure."""
    if not looks:
        return "none found: the frames without a face could not be read back"
    causes = [look.cause or "size" for look in looks]  # a face framed but missed by tracking counts as size
    cause = max(("size", "darkness", "none found"), key=causes.count)
    if cause == "size":
        shares = [look.face_share for look in looks if look.face_share is not None]
        share = statistics.median(shares) if shares else 0.0
        return (f"size: the face is {100 * share:.0f} % of the frame height, the rater needs "
                f"{100 * MIN_FACE_SHARE:.0f} % (move the camera closer)")
    light = statistics.median(look.brightness for look in looks)
    if cause == "darkness":
        return f"darkness: the frames are dark (brightness {light:.0f} of 255; light the face)"
    return f"none found: no face in the frames, not even a small one (brightness {light:.0f} of 255)"
