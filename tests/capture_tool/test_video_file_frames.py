"""``capture --video FILE`` records every frame of the file from the first (issue 38).

The file is a real MPEG-1 talking face of the GRID corpus (tests/data/video/README.md): OpenCV's
seek back to frame 0 of such a file lands on frame 12, so a capture that probed then seeked lost the
first 12 frames. A file that cannot be replayed in real time says so and counts what it dropped.
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import numpy as np

from effortface.capture_tool.camera import CameraSource, index_video
from effortface.core.opencv import import_cv2
from effortface.core.session.folder import read_session, validate_session

from .capture_helpers import BODY, effortface, hxm_chunks, start_replay, write_serlog

cv2 = import_cv2()
GRID_MPG = Path(__file__).resolve().parents[1] / "data" / "video" / "grid_sbwe5n.mpg"


def decoded_frames(video: Path) -> list[np.ndarray]:
    """Every frame OpenCV decodes from a video, read straight through (no seek)."""
    cap = cv2.VideoCapture(str(video))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame.astype(np.float32))
    cap.release()
    return frames


def nearest_source_frame(frame: np.ndarray, source: list[np.ndarray]) -> int:
    """The index of the source frame a recorded (MJPG re-encoded) frame is closest to."""
    return int(np.argmin([np.abs(frame.astype(np.float32) - s).mean() for s in source]))


def test_the_mpeg1_seek_to_zero_is_what_we_avoid() -> None:
    """The trap itself: after one read, CAP_PROP_POS_FRAMES=0 lands on frame 12 of this file."""
    source = decoded_frames(GRID_MPG)
    cap = cv2.VideoCapture(str(GRID_MPG))
    cap.read()
    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
    ok, frame = cap.read()
    cap.release()
    assert ok and len(source) == 75
    assert nearest_source_frame(frame, source) != 0


def test_a_session_recorded_from_an_mpeg1_file_has_every_frame(tmp_path, shared_data) -> None:
    source = decoded_frames(GRID_MPG)
    replay, pty = start_replay(write_serlog(tmp_path / "hr.serlog", hxm_chunks(shared_data, 0, 30)))
    proc = subprocess.run(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P01", *BODY,
                                     "--video", GRID_MPG, "--duration", "5", "--out", tmp_path / "out"),
                          capture_output=True, text=True, timeout=60)
    replay.kill()
    replay.wait(10)
    assert proc.returncode == 0, proc.stderr
    path = Path(proc.stdout.splitlines()[0])
    session = read_session(path)
    assert len(session.frame_times_s) == index_video(path / "video.avi") == len(source) == 75
    recorded = decoded_frames(path / "video.avi")
    assert [nearest_source_frame(recorded[k], source) for k in (0, 1, 12, 74)] == [0, 1, 12, 74]
    assert np.abs(recorded[0] - source[0]).mean() < 3.0  # the file's first frame, through one JPEG encoding
    assert "75 frames (0 dropped)" in proc.stderr.splitlines()[-1]
    assert "could not keep up" not in proc.stderr
    assert validate_session(path) == []


def _big_fast_video(path: Path, n_frames: int = 240) -> Path:
    """The GRID face enlarged to 1920 x 1536 at a nominal 240 fps: more than this machine replays in real time."""
    frames = decoded_frames(GRID_MPG)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 240.0, (1920, 1536))
    for k in range(n_frames):
        writer.write(cv2.resize(frames[k % len(frames)].astype(np.uint8), (1920, 1536)))
    writer.release()
    return path


def test_a_file_replayed_slower_than_real_time_counts_the_frames_it_dropped(tmp_path) -> None:
    video = _big_fast_video(tmp_path / "big.avi")
    t0 = time.monotonic()
    cam = CameraSource(video, lambda: time.monotonic() - t0)
    cam.start(tmp_path / "video.avi", tmp_path / "video_frames.csv")
    time.sleep(0.5)  # 120 frames are due; decoding and encoding 1920 x 1536 frames is far slower
    cam.stop()
    assert not cam.ended
    assert 0 < cam.late_frames == cam.dropped
    assert cam.frames_written == cam.grabbed == index_video(tmp_path / "video.avi")
    assert cam.frames_written + cam.late_frames >= 120  # every frame due by the stop: recorded or counted
    note = cam.lag_note()
    assert note is not None and f"{cam.late_frames} frames due by the stop were not recorded (dropped)" in note
    assert note.startswith(f"--video {video}: could not keep up in real time (1920x1536 at 240 fps")
    # the frames kept are the file's first ones, in order
    recorded = decoded_frames(tmp_path / "video.avi")
    source = decoded_frames(GRID_MPG)
    assert [nearest_source_frame(cv2.resize(f, (360, 288)), source) for f in recorded[:3]] == [0, 1, 2]
