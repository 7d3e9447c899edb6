"""Camera source from a real video file: frames stamped, written as MJPG, seekable, drops counted."""

from __future__ import annotations

import time

import pytest

from effortface.capture_tool.camera import CameraSource, index_video, read_frame, rewrite_video
from effortface.core.errors import UserError
from effortface.core.session.folder import read_video_frames

from .capture_helpers import frame_number, make_numbered_video


@pytest.fixture(scope="module")
def numbered_video(tmp_path_factory) -> object:
    return make_numbered_video(tmp_path_factory.mktemp("video") / "numbered.avi", 45, fps=30)


def test_records_every_frame_with_arrival_times(tmp_path, numbered_video) -> None:
    t0 = time.monotonic()
    cam = CameraSource(numbered_video, lambda: time.monotonic() - t0)
    assert (cam.width, cam.height, cam.fps) == (160, 120, 30.0)
    cam.start(tmp_path / "video.avi", tmp_path / "video_frames.csv")
    assert cam.wait_ended(timeout_s=20)
    cam.stop()
    times = read_video_frames(tmp_path / "video_frames.csv")
    assert cam.frames_written == len(times) == index_video(tmp_path / "video.avi") == 45
    assert cam.dropped == 0
    assert all(b > a for a, b in zip(times, times[1:]))  # stamped on arrival, in order
    for n in (0, 1, 22, 44):
        assert frame_number(read_frame(tmp_path / "video.avi", n)) == n
    assert cam.settings()["codec"] == "MJPG"


def test_output_never_overwritten(tmp_path, numbered_video) -> None:
    (tmp_path / "video.avi").write_bytes(b"old")
    cam = CameraSource(numbered_video, time.monotonic)
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        cam.start(tmp_path / "video.avi", tmp_path / "video_frames.csv")
    cam.stop()
    assert (tmp_path / "video.avi").read_bytes() == b"old"


def test_full_queue_drops_and_counts(numbered_video) -> None:
    cam = CameraSource(numbered_video, time.monotonic, queue_frames=2)
    ok, frame = cam._cap.read()
    for k in range(5):  # no writer running: the third frame on finds the queue full
        cam._offer(frame, float(k))
    assert (cam.grabbed, cam.dropped) == (5, 3)
    cam.stop()


def test_truncated_avi_is_reindexed_and_rewritten(tmp_path, numbered_video) -> None:
    cut = tmp_path / "cut.avi"
    blob = numbered_video.read_bytes()
    cut.write_bytes(blob[: len(blob) * 6 // 10])  # a crash: no index, header count is wrong
    n = index_video(cut)
    assert 0 < n < 45
    fixed = rewrite_video(cut, tmp_path / "fixed.avi")
    assert fixed == n == index_video(tmp_path / "fixed.avi")
    for k in (0, n // 2, n - 1):
        assert frame_number(read_frame(tmp_path / "fixed.avi", k)) == k
    with pytest.raises(FileExistsError):
        rewrite_video(cut, tmp_path / "fixed.avi")


@pytest.mark.parametrize(
    ("match", "make"),
    [
        ("--video .*expected a video file, found nothing", lambda p: p / "missing.avi"),
        ("--video .*expected a video OpenCV can decode", lambda p: (p / "junk.avi").write_bytes(b"RIFF junk") and p / "junk.avi"),
    ],
)
def test_bad_video_source(tmp_path, match: str, make) -> None:
    with pytest.raises(UserError, match=match):
        CameraSource(make(tmp_path), time.monotonic)


def test_read_frame_past_end(numbered_video) -> None:
    with pytest.raises(UserError, match="expected a frame 45, found the video ends"):
        read_frame(numbered_video, 45)
