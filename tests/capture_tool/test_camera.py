"""Camera source from a real video file: frames stamped, written as MJPG, seekable, drops counted."""

from __future__ import annotations

import time

import pytest

from effortface.core.opencv import import_cv2

from effortface.capture_tool.avi_writer import MjpgAviWriter, mjpg_frames
from effortface.capture_tool.camera import (CameraSource, copy_mjpg_frames, index_video, open_avi_writer,
                                            read_frame, rewrite_video)
from effortface.core.errors import UserError
from effortface.core.session.folder import read_video_frames

from .capture_helpers import frame_number, make_numbered_video

cv2 = import_cv2()


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


def test_a_crashed_avi_is_rewritten_with_the_recorded_jpeg_bytes(tmp_path, numbered_video) -> None:
    cap = cv2.VideoCapture(str(numbered_video))
    frames = [cap.read()[1] for _ in range(12)]
    cap.release()
    writer = MjpgAviWriter(tmp_path / "live.avi", 15.0, (160, 120), quality=60)
    for frame in frames:
        writer.write(frame)
    blob = (tmp_path / "live.avi").read_bytes()  # as a kill leaves it: open sizes, no index
    writer.release()
    recorded = list(mjpg_frames(tmp_path / "live.avi"))
    assert len(recorded) == 12
    cut = tmp_path / "cut.avi"
    cut.write_bytes(blob[: len(blob) - len(recorded[-1]) // 2])  # the last frame torn
    assert rewrite_video(cut, tmp_path / "fixed.avi") == 11 == index_video(tmp_path / "fixed.avi")
    assert list(mjpg_frames(tmp_path / "fixed.avi")) == recorded[:11]  # not encoded a second time
    assert [frame_number(read_frame(tmp_path / "fixed.avi", k)) for k in (0, 10)] == [0, 10]


def test_a_video_without_mjpg_chunks_is_decoded_and_encoded(tmp_path, numbered_video) -> None:
    cap = cv2.VideoCapture(str(numbered_video))
    frames = [cap.read()[1] for _ in range(5)]
    cap.release()
    raw = tmp_path / "raw.mp4"  # an MPEG-4 file: no AVI chunks at all
    out = cv2.VideoWriter(str(raw), cv2.VideoWriter_fourcc(*"mp4v"), 15.0, (160, 120))
    for frame in frames:
        out.write(frame)
    out.release()
    assert copy_mjpg_frames(raw, tmp_path / "copy.avi") == 0 and not (tmp_path / "copy.avi").exists()
    assert rewrite_video(raw, tmp_path / "fixed.avi") == index_video(raw) == 5
    assert [frame_number(read_frame(tmp_path / "fixed.avi", k)) for k in range(5)] == list(range(5))


@pytest.mark.parametrize(("fps", "size"), [(15.0, (40000, 120)), (15.0, (0, 120)), (1e9, (160, 120)),
                                           (float("nan"), (160, 120))])
def test_a_size_or_rate_the_avi_headers_cannot_hold_is_refused_before_the_file(tmp_path, fps, size) -> None:
    with pytest.raises(UserError, match=r"video.avi: expected a frame size of 1 to 32767 pixels a side"):
        open_avi_writer(tmp_path / "video.avi", fps, size)
    assert not (tmp_path / "video.avi").exists()


def test_nested_lists_of_a_hostile_avi_are_walked_without_recursion(tmp_path) -> None:
    hostile = tmp_path / "deep.avi"
    hostile.write_bytes(b"RIFF\0\0\0\0AVI " + b"LIST\0\0\0\0movi" * 100_000 + b"00dc\x03\0\0\0abc\0")
    assert list(mjpg_frames(hostile)) == [b"abc"]
    assert copy_mjpg_frames(hostile, tmp_path / "copy.avi") == 0  # "abc" is no JPEG


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
