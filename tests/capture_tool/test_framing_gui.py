"""The Capture stage's camera check says when the face is too small for the machine rater (issue 38)."""

from __future__ import annotations

from pathlib import Path

import pytest

from .test_framing import grid_frames, scale_for, shrink_face, write_video

#: the offscreen platform warns that it cannot size a top-level window: harmless here
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


def test_a_small_face_gets_a_banner_and_a_framed_one_clears_it(qtbot, window, tmp_path: Path) -> None:
    stage = window.stages["capture"]
    frames = grid_frames()
    small = write_video(tmp_path / "small.avi", [shrink_face(f, scale_for(0.14)) for f in frames[:10]])
    framed = write_video(tmp_path / "framed.avi", frames[:10])
    stage.preflight.set_choice(video_file=small)
    qtbot.waitUntil(lambda: stage.banner_text().startswith("Camera: move the camera closer"), timeout=15_000)
    text = stage.banner_text()
    assert text.endswith(" % of the frame; the rater needs 25 %.")
    share = int(text.split("the face is ")[1].split(" %")[0])
    assert 11 <= share <= 17
    assert "move the camera closer" in stage.preflight.camera_status.text()  # the Camera state line says it too
    stage.preflight.set_choice(video_file=framed)
    qtbot.waitUntil(lambda: stage.banner_text() == "", timeout=15_000)
    assert "face found: " in stage.preflight.camera_status.text()


def test_while_recording_the_framing_is_the_last_banner(qtbot, window) -> None:
    """A sampler's look that finds the face too small is said, below a lost strap or camera."""
    from effortface.core.framing import Framing

    stage = window.stages["capture"]
    small = Framing(0.14, False, 120.0)
    stage._update_banner("connected", camera_ended=False, contact_ok=True, framing=small)
    assert stage.banner_text() == "Camera: move the camera closer: the face is 14 % of the frame; the rater needs 25 %."
    stage._update_banner("reconnecting", camera_ended=False, contact_ok=True, framing=small)
    assert stage.banner_text().startswith("Strap lost")
    stage._update_banner("connected", camera_ended=False, contact_ok=True, framing=Framing(0.4, True, 120.0))
    assert stage.banner_text() == ""
