"""Sessions made from the GRID talking-face clips of tests/data/faces/grid (CC BY 4.0), as a camera stores them.

Used by tests/annotate/test_effort_mapping.py and benchmarks/measure_effort_mapping.py.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

from effortface.core.participant import Participant
from effortface.core.session.folder import (Event, EventWriter, FrameTimeWriter, SessionInfo, create_session,
                                             make_session_id)

GRID = Path(__file__).resolve().parents[1] / "data" / "faces" / "grid"
CLIPS = ("bbaf2n", "brbk7n", "lbax4n", "pwij3p")
#: the GRID speakers are silent, with a neutral face, for the first 0.6 s of a clip
REST_S = 0.6


def clip_session(clip: Path, lab: Path, code: str, *, slow: float = 1.0, day: int = 1,
                 rest_s: float = REST_S) -> Path:
    """A complete session holding every frame of ``clip`` (times ``slow`` times the clip's own), unrated.

    ``events.csv`` opens with a rest phase over the first ``rest_s`` seconds of the clip (none when 0).
    """
    import cv2

    cap = cv2.VideoCapture(str(clip))
    fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
    frames = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        frames.append(bgr)
    cap.release()
    height, width = frames[0].shape[:2]
    when = _dt.datetime(2026, 3, day, 10, 0, 0)
    label = "".join(c if c.isalnum() else "-" for c in clip.stem)[:32]
    info = SessionInfo(make_session_id(code, when, label), Participant(code=code), complete=True,
                       created_utc=when.strftime("%Y-%m-%dT%H:%M:%SZ"),
                       devices={"camera": {"source": f"file {clip.name}", "width": width, "height": height,
                                           "fps": fps / slow, "codec": "MJPG"}})
    folder = create_session(lab, info)
    writer = cv2.VideoWriter(str(folder / "video.avi"), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*"MJPG"),
                             fps / slow, (width, height))
    times = FrameTimeWriter(folder / "video_frames.csv")
    for i, bgr in enumerate(frames):
        writer.write(bgr)
        times.write(i, i * slow / fps)
    writer.release()
    times.close()
    events = EventWriter(folder / "events.csv")
    rest = [Event(0.0, "phase_start", "rest"), Event(rest_s * slow, "phase_end", "rest")] if rest_s > 0 else []
    for event in (Event(0.0, "sync", "session_start"), *rest, Event(rest_s * slow, "phase_start", "talk")):
        events.write(event)
    events.close()
    return folder
