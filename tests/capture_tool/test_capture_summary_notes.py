"""The after-Stop summary says what ``session.json`` records beyond the counts: a suffixed session id (two
recordings of one participant in the same second) and how often the camera framing check found the face
framed for the machine rater. The real main window offscreen, a pseudo-terminal strap, real video files
(a GRID talker, CC BY 4.0, and a numbered video with no face)."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import pytest
from PySide6 import QtWidgets

from effortface.capture_tool import recorder
from effortface.capture_tool.gui.capture_stage import saved_notes
from effortface.capture_tool.replay import start_replay_thread
from effortface.core.session.folder import Participant, SessionInfo, create_session, make_session_id

from .capture_helpers import make_numbered_video
from .test_capture_stage_daily import _confirm, _end, _record, _stop, _strap

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

GRID_MPG = Path(__file__).resolve().parents[1] / "data" / "video" / "grid_sbwe5n.mpg"

def _record_video(qtbot, stage, video: Path) -> Path:
    """Record P01 with ``video`` and a strap until the framing check has looked at least twice."""
    replay = _strap(30.0)
    stage.preflight.set_choice(port=replay.path, protocol="lines", video_file=video)
    qtbot.waitUntil(lambda: stage.settled() and stage.preflight.missing() == [], timeout=10_000)
    _confirm(stage, "P01")
    _record(qtbot, stage)
    thread = start_replay_thread(replay)
    sampler = stage.session.recorder.framing
    qtbot.waitUntil(lambda: sampler is not None and sampler.samples >= 2 and stage.live.n_samples() >= 2,
                    timeout=20_000)
    stage.sync_test()  # a recording with video asks for one at Stop otherwise
    path = _stop(qtbot, stage)
    _end(replay, thread)
    return path


def _framing(path: Path) -> dict:
    return json.loads((path / "session.json").read_text())["stats"]["framing"]


def test_the_summary_states_the_suffix_and_the_framing(qtbot, window, tmp_path, monkeypatch,
                                                         freeze_now) -> None:
    when = freeze_now(recorder)
    monkeypatch.setattr(QtWidgets.QMessageBox, "question", lambda *a: pytest.fail(f"asked: {a[1:3]}"))
    stage = window.stages["capture"]
    first = _record_video(qtbot, stage, GRID_MPG)
    framing = _framing(first)
    text = stage.summary_text.text()
    assert first.name == f"P01_{when:%Y%m%d-%H%M%S}" == "P01_20260302-101507" and "exists already" not in text
    assert framing["samples"] >= 2 and framing["framed"] >= 1  # the GRID talker fills 40 % of the frame
    assert (f"Camera: the face was framed for the machine rater in {framing['framed']} of "
            f"{framing['samples']} looks") in text
    second = _record_video(qtbot, stage, make_numbered_video(tmp_path / "noface.avi", n_frames=300))
    framing = _framing(second)
    text = stage.summary_text.text()
    assert second.name == "P01_20260302-101507_2" and first.exists()
    assert ("A session folder P01_20260302-101507 exists already (a session of P01 started the same second): "
            "this one is P01_20260302-101507_2") in text
    assert framing["framed"] == 0 and (f"in 0 of {framing['samples']} looks (last look: no face found"
                                       in text)


def test_saved_notes_of_a_session_without_them_or_unreadable(tmp_path) -> None:
    when = dt.datetime(2026, 3, 2, 10, 15, 7)
    info = SessionInfo(make_session_id("P01", when, None), Participant("P01"), complete=True,
                       extra={"stats": {"video_frames": 0}})
    folder = create_session(tmp_path / "lab", info)
    assert saved_notes(folder) == []  # no suffix, no video framing
    (folder / "session.json").write_text("{not json")
    assert saved_notes(folder) == []  # the summary's counts still show; the reader says why elsewhere
    assert saved_notes(tmp_path / "absent") == []
