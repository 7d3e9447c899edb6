"""Frame-exact video access: time <-> frame from the recorded frame times, exact seeks, the cache."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.video_index import FrameTimes, VideoIndex
from effortface.capture_tool.camera import open_avi_writer
from effortface.core.errors import UserError
from effortface.core.session.folder import read_video_frames

ROOT = Path(__file__).resolve().parents[2]
P01 = ROOT / "sample_sessions" / "P01_20260112-093000_cardio"


def _numbered_video(path: Path, n_frames: int, size: tuple[int, int] = (640, 480)) -> None:
    """An MJPG video whose frame k is a flat grey of level 3 k (readable back after JPEG)."""
    writer = open_avi_writer(path, 30.0, size)
    for k in range(n_frames):
        writer.write(np.full((size[1], size[0], 3), 3 * k, np.uint8))
    writer.release()


def _level(image: np.ndarray) -> int:
    return int(round(float(image.mean()) / 3))


def _wait_until(predicate, timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def test_frame_at_uses_recorded_times_not_the_nominal_rate() -> None:
    t_s = read_video_frames(P01 / "video_frames.csv")
    times = FrameTimes(t_s)
    frames = np.arange(len(times))
    assert all(times.frame_at(times.t_at(f)) == f for f in frames)
    # just before a frame arrives, the previous one is on screen
    assert all(times.frame_at(times.t_at(f) - 1e-4) == f - 1 for f in frames[1:])
    np.testing.assert_array_equal(times.frames_at(times.t_s), frames)
    # the sample camera runs 0.3 % slow: time x nominal 8 fps lands on the wrong frame by the end
    nominal = np.round(np.asarray(t_s) * 8.0).astype(int)
    assert np.any(nominal != frames)
    assert times.frame_at(-5.0) == 0 and times.frame_at(1e6) == len(times) - 1


@pytest.mark.parametrize(("match", "times_s"), [
    ("at least one frame", []),
    ("non-decreasing", [0.0, 0.2, 0.1]),
])
def test_frame_times_refuse_bad_tables(match: str, times_s: list[float]) -> None:
    with pytest.raises(UserError, match=match):
        FrameTimes(times_s)


@pytest.mark.parametrize("frame", [-1, 3, 1.5, True])
def test_t_at_names_the_valid_range(frame: object) -> None:
    with pytest.raises(UserError, match=r"frame: expected an integer from 0 to 2, found"):
        FrameTimes([0.0, 0.1, 0.2]).t_at(frame)  # type: ignore[arg-type]


def test_random_seeks_are_exact_on_the_sample_video() -> None:
    import cv2

    cap = cv2.VideoCapture(str(P01 / "video.avi"), cv2.CAP_OPENCV_MJPEG)  # the same JPEG decoder
    sequential = [cap.read()[1] for _ in range(300)]
    cap.release()
    rng = np.random.default_rng(7)
    with VideoIndex(P01 / "video.avi", read_video_frames(P01 / "video_frames.csv"), prefetch=False) as video:
        assert len(video) == 953  # 640 s at 1.5 fps (0.3 % slow, late frames)
        for k in rng.permutation(300)[:60]:
            np.testing.assert_array_equal(video.get(int(k)), sequential[k])


def test_seeks_on_a_640x480_mjpg_land_on_the_asked_frame(tmp_path: Path) -> None:
    path = tmp_path / "numbered.avi"
    _numbered_video(path, 80)
    times = np.arange(80) / 30.0
    with VideoIndex(path, times, cache_frames=4, prefetch=False) as video:
        for k in np.random.default_rng(1).permutation(80):
            image = video.get(int(k))
            assert image.shape == (480, 640, 3)
            assert _level(image) == k
        assert video.frame_at(times[41] + 0.001) == 41


def test_prefetch_fills_the_neighbours_and_the_lru_keeps_its_size(tmp_path: Path) -> None:
    path = tmp_path / "numbered.avi"
    _numbered_video(path, 60, (160, 120))
    with VideoIndex(path, np.arange(60) / 30.0, cache_frames=20, prefetch_ahead=10, prefetch_behind=3) as video:
        video.get(30)
        assert _wait_until(lambda: all(f in video.cache for f in (*range(31, 41), 27, 28, 29)))
        hits = video.cache.hits
        assert [_level(video.get(f, prefetch=False)) for f in range(31, 41)] == list(range(31, 41))
        assert video.cache.hits == hits + 10
        for f in range(0, 60, 2):
            video.get(f, prefetch=False)
        assert len(video.cache._frames) == 20


def test_a_short_frame_table_limits_the_frames(tmp_path: Path) -> None:
    path = tmp_path / "numbered.avi"
    _numbered_video(path, 20, (160, 120))
    with VideoIndex(path, np.arange(12) / 30.0, prefetch=False) as video:
        assert len(video) == 12
        with pytest.raises(UserError, match="from 0 to 11, found 12"):
            video.get(12)


def test_from_session_needs_a_video(tmp_path: Path) -> None:
    folder = tmp_path / P01.name
    folder.mkdir()
    shutil.copy(P01 / "session.json", folder)
    with pytest.raises(UserError, match="expected a session video"):
        VideoIndex.from_session(folder)
    with VideoIndex.from_session(P01, prefetch=False) as video:
        assert video.t_at(100) == pytest.approx(read_video_frames(P01 / "video_frames.csv")[100])


def test_an_unreadable_video_is_a_user_error(tmp_path: Path) -> None:
    bad = tmp_path / "video.avi"
    bad.write_bytes(b"not a video" * 100)
    with pytest.raises(UserError, match="video.avi: expected a video OpenCV can decode"):
        VideoIndex(bad, [0.0, 0.1], prefetch=False)
