"""Capture's framing check for the machine rater (issue 38): face found, its height as a share of the
frame, brightness; said before Record and while recording, off the recording path.

The face is a real GRID talking face (tests/data/video), shrunk so that it fills 12 % of the
frame's height (the rater needs 25 %), or left at its own size (42 %).
"""

from __future__ import annotations

import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from effortface.capture_tool.framing_sampler import FramingSampler, check_camera_framing
from effortface.core.face_landmarker import FaceLandmarker
from effortface.core.framing import MIN_FACE_SHARE, check_framing
from effortface.core.opencv import import_cv2
from effortface.core.session.folder import read_session_info

from .capture_helpers import BODY, effortface, hxm_chunks, start_replay, write_serlog
from .test_video_file_frames import GRID_MPG

cv2 = import_cv2()


def grid_frames() -> list[np.ndarray]:
    """The GRID clip's frames, BGR."""
    cap = cv2.VideoCapture(str(GRID_MPG))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    cap.release()
    return frames


def shrink_face(frame: np.ndarray, scale: float) -> np.ndarray:
    """The frame shrunk by ``scale`` into the middle of a grey frame of the same size (a camera farther away)."""
    h, w = frame.shape[:2]
    small = cv2.resize(frame, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
    out = np.full_like(frame, 40)
    top, left = (h - small.shape[0]) // 2, (w - small.shape[1]) // 2
    out[top:top + small.shape[0], left:left + small.shape[1]] = small
    return out


def scale_for(share: float) -> float:
    """The shrink that makes the GRID face ``share`` of the frame's height (measured by the detector)."""
    first = grid_frames()[0]
    measured = check_camera_framing(first).face_share
    assert measured is not None and measured > 0.35  # the clip as recorded: a face the rater sees
    return share / measured


def write_video(path: Path, frames: list[np.ndarray], fps: float = 25.0) -> Path:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def small_face_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The GRID clip with the face at 12 % of the frame height."""
    scale = scale_for(0.12)
    frames = [shrink_face(f, scale) for f in grid_frames()]
    return write_video(tmp_path_factory.mktemp("small") / "small_face.avi", frames)


def test_a_face_at_12_percent_is_found_and_called_too_small() -> None:
    frame = shrink_face(grid_frames()[0], scale_for(0.12))
    framing = check_camera_framing(frame)
    assert not framing.ok and framing.cause == "size" and not framing.rater_sees
    assert framing.face_share is not None and 0.09 <= framing.face_share <= 0.15
    pct = round(100 * framing.face_share)
    assert framing.line() == f"move the camera closer: the face is {pct} % of the frame; the rater needs 25 %"
    # and the rater itself, on the same frame, finds no face: the check predicts it
    assert not FaceLandmarker().process(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)).face


def test_a_well_framed_face_is_ok_and_no_face_is_said() -> None:
    framing = check_camera_framing(grid_frames()[0])
    assert framing.ok and framing.face_share >= MIN_FACE_SHARE and framing.line().startswith("face found: ")
    blank = np.full((288, 360, 3), 150, np.uint8)
    assert check_camera_framing(blank).line() == "no face found: turn the camera to the participant's face"
    dark = np.full((288, 360, 3), 10, np.uint8)
    assert check_camera_framing(dark).cause == "darkness" and "dark (brightness 10 of 255)" in check_camera_framing(dark).line()


def test_the_sampler_never_holds_up_the_recording_path() -> None:
    """The sampler reads the newest frame reference only; a slow look does not block whoever replaces it."""
    frames = grid_frames()
    newest = {"frame": frames[0]}
    sampler = FramingSampler(lambda: newest["frame"], every_s=0.05)
    sampler.start()
    replaced = 0
    t_end = time.monotonic() + 1.5
    while time.monotonic() < t_end:  # a 'grabber' replacing the frame at 250 Hz all along
        newest["frame"] = frames[replaced % len(frames)]
        replaced += 1
        time.sleep(0.004)
    sampler.stop()
    assert replaced >= 200 and sampler.samples >= 3
    assert sampler.latest is not None and sampler.latest.ok
    assert sampler.summary()["samples"] == sampler.samples and threading.active_count() >= 1


def test_capture_says_the_framing_of_a_small_face(tmp_path, shared_data, small_face_video) -> None:
    replay, pty = start_replay(write_serlog(tmp_path / "hr.serlog", hxm_chunks(shared_data, 0, 30)))
    proc = subprocess.run(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P01", *BODY,
                                     "--video", small_face_video, "--duration", "3", "--out", tmp_path / "out"),
                          capture_output=True, text=True, timeout=60)
    replay.kill()
    replay.wait(10)
    assert proc.returncode == 0, proc.stderr
    said = [line for line in proc.stderr.splitlines() if line.startswith("camera: ")]
    assert said and said[0].startswith("camera: move the camera closer: the face is ")
    assert said[0].endswith(" % of the frame; the rater needs 25 %")
    stats = read_session_info(Path(proc.stdout.splitlines()[0])).extra["stats"]
    assert stats["framing"]["samples"] >= 2 and stats["framing"]["framed"] == 0
    assert stats["video_frames"] == 75 and stats["dropped_frames"] == 0  # the looks cost the recording nothing


def test_check_framing_reads_rgb_frames_with_the_engine_given() -> None:
    rgb = cv2.cvtColor(grid_frames()[0], cv2.COLOR_BGR2RGB)
    engine = FaceLandmarker()
    assert check_framing(rgb, engine) == check_framing(rgb, engine)  # the engine's tracking is not touched
