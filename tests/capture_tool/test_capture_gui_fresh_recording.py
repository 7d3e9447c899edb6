"""Capture, the real main window offscreen (pytest-qt): nothing
carries over from one recording to the next, and one strap status behind the Strap line, the banner
and the HR readout (a real HxM stream read as ANT is named, Detect clears it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore

from effortface.capture_tool.replay import PtyReplay, TimedChunk, start_replay_thread
from effortface.core.session.folder import read_session_info

from .capture_helpers import hxm_chunks
from .test_capture_stage_daily import _choose, _confirm, _end, _record, _stop, _strap  # noqa: F401

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


def test_note_marker_and_plan_start_empty_for_the_next_recording(qtbot, window, tmp_path: Path) -> None:
    stage = window.stages["capture"]
    plan = tmp_path / "PLAN.csv"
    plan.write_text("start_s,end_s,exercise\n0.2,1.0,rest\n")
    stage.load_plan(str(plan))
    replay = _strap(60.0)
    _choose(qtbot, stage, replay.path)
    _confirm(stage, "P31")
    first = _record(qtbot, stage)
    thread = start_replay_thread(replay)
    stage.notes.setPlainText("felt dizzy")
    stage.phases.marker_text.setText("water break")
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 2, timeout=10_000)
    _stop(qtbot, stage)
    assert read_session_info(first).extra["notes"] == "felt dizzy"
    # after Stop: the note, the marker note and the plan are empty, in the window and the model
    assert stage.notes.toPlainText() == "" and stage.session.notes == ""
    assert stage.phases.marker_text.text() == ""
    assert stage.session.plan == [] and stage.phases.plan_label.text() == "no plan: phases by hotkey"
    # after Stop the strap is watched again before the next Record
    qtbot.waitUntil(lambda: stage.settled() and stage.preflight.missing() == [] and
                    stage.session.watching(replay.path), timeout=10_000)
    assert stage.form.code.text() == "" and stage.form.missing() != []  # the form is empty for the next one
    _confirm(stage, "P31")
    stage.form.label.setText("again")  # a session id has the second: two recordings within one get a label
    second = _record(qtbot, stage)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 2, timeout=10_000)
    assert stage.event_list.count() == 0  # no marker nor phase of the first recording listed
    _stop(qtbot, stage)
    _end(replay, thread)
    info = read_session_info(second)
    assert "notes" not in info.extra
    from effortface.core.session.folder import read_events
    assert [e for e in read_events(second / "events.csv") if e.kind in ("marker", "phase_start")] == []


def test_wrong_protocol_is_named_once_and_detect_clears_it(qtbot, window, shared_data) -> None:
    stage = window.stages["capture"]
    replay = PtyReplay([TimedChunk(t, d) for t, d in hxm_chunks(shared_data, 0.0, 60.0)], speed=4.0)
    stage.preflight.set_choice(port=replay.path, protocol="ant")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(lambda: stage.settled() and stage.session.watching(replay.path), timeout=10_000)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: "none decode as ANT" in stage.banner_text(), timeout=15_000)
    # the Strap line, the banner and the HR readout say the same thing
    line = stage.preflight.strap_status.text()
    assert "bytes arrive but none decode as ANT: try Detect" in line and "ready" not in line
    assert stage.live.hr_label.value.text() == "--"
    assert stage.preflight.missing() == ["strap"]
    stage.preflight.detect_seconds = 1.5
    qtbot.mouseClick(stage.preflight.detect_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: stage.preflight.detect_button.isEnabled(), timeout=15_000)
    assert stage.preflight.protocol.currentText() == "hxm"
    assert stage.banner_text() == ""  # the cause went, so did its banner
    qtbot.waitUntil(lambda: stage.live.hr_label.value.text() != "--", timeout=15_000)
    assert "ready" in stage.preflight.strap_status.text() and stage.banner_text() == ""
    _end(replay, thread)


def test_a_busy_port_banner_goes_when_another_port_is_chosen(qtbot, window, tmp_path: Path) -> None:
    stage = window.stages["capture"]
    stage.preflight.strap.choose("/dev/ttyFAKE", "hxm")
    stage._show_status("Live heart rate: --port /dev/ttyFAKE: expected a free port, found it in use by another "
                       "program", True)
    assert "in use by another program" in stage.banner_text()
    assert "ready" not in stage.preflight.strap_status.text()
    replay = _strap(10.0)
    _choose(qtbot, stage, replay.path)
    assert stage.banner_text() == "" and "ready" in stage.preflight.strap_status.text()
    replay.close()


def test_record_refused_banner_goes_once_the_fields_are_confirmed(qtbot, window) -> None:
    stage = window.stages["capture"]
    stage.form.code.setText("P32")
    assert not stage.start_recording()
    assert stage.banner_text().startswith("Record refused")
    _confirm(stage, "P32")
    assert stage.banner_text() == ""


def test_speed_is_typed_in_km_h_or_m_s_and_logged_in_m_s(qtbot, window, settings) -> None:
    """Issue 25 item 6: 10 typed as km/h is logged as 2.778 m/s (it used to be taken as 10 m/s = 36 km/h)."""
    phases = window.stages["capture"].phases
    phases.exercise.setCurrentText("treadmill")
    phases.speed_unit.setCurrentText("km/h")
    speed = phases.spins["speed_m_s"]
    assert speed.suffix() == " km/h" and speed.maximum() == 36.0
    speed.setValue(10.0)
    assert dict(phases.parameters())["speed_m_s"] == pytest.approx(2.778)
    phases.speed_unit.setCurrentText("m/s")  # the speed set is converted, not reinterpreted
    assert speed.value() == pytest.approx(2.78) and dict(phases.parameters())["speed_m_s"] == pytest.approx(2.78)
    phases.speed_unit.setCurrentText("km/h")
    assert settings.value("capture/speed_unit") == "km/h"   # the choice is remembered for the next start
    phases.pick("treadmill", speed_m_s=3.0)                 # scripts give m/s whatever is shown
    assert speed.value() == pytest.approx(10.8) and dict(phases.parameters())["speed_m_s"] == pytest.approx(3.0)


def test_the_hr_plot_draws_the_strap_before_record(qtbot, window, tmp_path: Path) -> None:
    """Issue 25 item 6: the stream is drawn before Record (as LabRecorder and OpenSignals do); Record
    starts the recording's own plot."""
    stage = window.stages["capture"]
    replay = _strap(60.0, hr_bpm=77)
    _choose(qtbot, stage, replay.path)
    qtbot.waitUntil(lambda: stage.session.watching(replay.path), timeout=10_000)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 4, timeout=10_000)
    assert not stage.session.recording and set(stage.live._hr_bpm[np.isfinite(stage.live._hr_bpm)]) == {77.0}
    _confirm(stage, "P33")
    _record(qtbot, stage)
    assert not stage._plot_is_monitor  # the recording has its own plot, read from the session file
    _stop(qtbot, stage)
    _end(replay, thread)


def test_stop_without_a_sync_test_asks_while_video_is_recorded(qtbot, window, tmp_path: Path, monkeypatch) -> None:
    """Issue 25 item 6: Stop with video and no sync flash asks; No keeps recording (for F8); after F8
    Stop asks nothing."""
    from PySide6 import QtWidgets

    from .capture_helpers import make_numbered_video

    stage = window.stages["capture"]
    video = make_numbered_video(tmp_path / "cam.avi", n_frames=600, fps=30.0)
    replay = _strap(60.0)
    stage.preflight.set_choice(port=replay.path, protocol="lines", video_file=video)
    qtbot.waitUntil(lambda: stage.settled() and stage.preflight.missing() == [], timeout=10_000)
    _confirm(stage, "P34")
    _record(qtbot, stage)
    thread = start_replay_thread(replay)
    answers = iter([QtWidgets.QMessageBox.StandardButton.No])
    asked: list[str] = []
    monkeypatch.setattr(QtWidgets.QMessageBox, "question",
                        lambda parent, title, *a: (asked.append(title), next(answers))[1])
    assert not stage.stop_recording()
    assert asked == ["No sync test"] and stage.session.recording and "press F8" in stage.banner_text()
    stage.sync_test()
    assert not stage.session.needs_sync_reminder()
    _stop(qtbot, stage)  # no second question (the iterator would raise)
    assert asked == ["No sync test"]
    _end(replay, thread)


def test_a_recording_without_video_needs_no_sync_test_at_1280x800(qtbot, window) -> None:
    """Issue 25 item 6: the sync result was cut off at 1280x800; issue 36: a recording without video
    needs no sync test, and the summary panel says so (it stays until the next Record)."""
    window.resize(1280, 800)
    stage = window.stages["capture"]
    replay = _strap(30.0)
    _choose(qtbot, stage, replay.path)
    _confirm(stage, "P35")
    _record(qtbot, stage)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 2, timeout=10_000)
    _stop(qtbot, stage)
    _end(replay, thread)
    text = stage.banner_text()
    assert text.startswith("Saved, complete: P35_") and "No sync test" not in text
    assert stage.summary_sync.text() == "Sync test: no video: no sync needed"
    assert stage.banner.toolTip() == text
