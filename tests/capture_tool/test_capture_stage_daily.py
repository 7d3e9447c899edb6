"""The Capture stage for daily use (issue 16 items 1-5, issue 12 item 5), driven offscreen (pytest-qt).

Real pseudo-terminal straps, the real main window, the real ``effortface work`` on what was recorded.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from effortface.app import MainWindow
from effortface.capture_tool.capture_session import CaptureSession
from effortface.capture_tool.corrections import apply_corrections, correction_value
from effortface.capture_tool.gui.capture_stage import describe_sync
from effortface.capture_tool.gui.live_view import QtLiveView
from effortface.capture_tool.participants import read_registry
from effortface.capture_tool.replay import PtyReplay, TimedChunk, start_replay_thread
from effortface.core.session.folder import Event, Participant, read_events, read_session_info
from effortface.core.participant import LIMITS
from effortface.train.train_session import scan_sessions

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")
ROOT = Path(__file__).resolve().parents[2]


def _strap(seconds: float, hr_bpm: int = 72, rate_hz: float = 4.0) -> PtyReplay:
    """A 'lines' strap on a pseudo-terminal: ``HR:<bpm>`` at ``rate_hz`` for ``seconds``."""
    n = int(seconds * rate_hz)
    return PtyReplay([TimedChunk(i / rate_hz, b"HR:%d\n" % hr_bpm) for i in range(n)])


def _end(replay: PtyReplay, thread) -> None:
    """Stop playing, then pull the port (never close it under the playing thread)."""
    replay.stop()
    thread.join(5)
    replay.close()


def _confirm(stage, code: str = "P21") -> None:
    form = stage.form
    form.code.setText(code)
    form.sex.setCurrentText("female")
    form.age.setValue(41)
    form.height_m.setValue(1.68)
    form.mass.setValue(63.5)
    form.training_level.setValue(9.5)


def _choose(qtbot, stage, port: str) -> None:
    stage.preflight.set_choice(port=port, protocol="lines")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(lambda: stage.settled() and stage.preflight.missing() == [], timeout=10_000)


def _record(qtbot, stage) -> Path:
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: stage.session.recording and stage.settled(), timeout=10_000)
    return stage.session.recorder.path


def _stop(qtbot, stage) -> Path:
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not stage.session.recording and stage.settled(), timeout=20_000)
    return stage.session.last_session


def _key(qtbot, window: MainWindow, key: QtCore.Qt.Key) -> None:
    qtbot.keyClick(window.focusWidget() or window, key)


def _logged(stage, kind: str, label: str | None = None) -> list[Event]:
    return [e for e in stage.session.events if e.kind == kind and (label is None or e.label == label)]


# ------------------------------------------------------------------------- participant form
def test_untouched_defaults_are_never_written_and_record_waits_for_confirmed_fields(qtbot, window, tmp_path):
    stage = window.stages["capture"]
    form = stage.form
    # the form starts empty: nothing is a plausible made-up value
    assert {k: v for k, v in form.values().items() if k != "code"} == dict.fromkeys(
        ("sex", "age", "height_m", "mass_kg", "training_level", "hr_rest_bpm", "hr_max_bpm"))
    assert form.training_level.maximum() == LIMITS["training_level"].hi == 10.0  # TL 0-10, one limits table
    replay = _strap(30.0)
    _choose(qtbot, stage, replay.path)
    form.code.setText("P21")
    form.mass.setValue(63.5)
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.wait(200)
    assert not stage.session.recording and stage.session.state == "idle"
    assert "Record refused" in stage.banner_text() and "sex, age, height, training level" in stage.banner_text()
    assert "To confirm before Record: sex, age, height, training level" in form.confirmed.text()
    assert not (tmp_path / "sessions").exists() or not list((tmp_path / "sessions").glob("P21_*"))

    _confirm(stage)
    assert form.confirmed.text().startswith("All required fields confirmed")
    path = _record(qtbot, stage)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 3, timeout=10_000)
    _stop(qtbot, stage)
    _end(replay, thread)
    stored = json.loads((path / "session.json").read_text())["participant"]
    # exactly what was confirmed; the resting / maximal HR never touched are not written
    assert stored == {"code": "P21", "sex": "female", "age": 41, "height_m": 1.68, "mass_kg": 63.5,
                      "training_level": 9.5}
    # the participant is now in the lab registry, and picking the code fills and locks the form
    assert read_registry(tmp_path / "sessions" / "participants.tsv")["P21"] == Participant(
        "P21", "female", 41, 1.68, 63.5, 9.5)
    form.code.setText("P2")
    assert form.values()["mass_kg"] is None
    form.registry.setCurrentText("P21")
    assert form.code.text() == "P21" and form.values()["mass_kg"] == 63.5 and not form.mass.isEnabled()
    assert "(registry)" in form.confirmed.text()


def test_a_long_event_wraps_in_the_list(qtbot, window):
    """A link error's long text wraps in the fixed-width events list (no sideways scrolling)."""
    stage = window.stages["capture"]
    window.resize(1280, 800)
    stage._list_events([Event(14.0, "device_gap", "ant", "device reports readiness to read but returned no "
                              "data (device disconnected or multiple access on port?)")])
    QtWidgets.QApplication.processEvents()
    events = stage.event_list
    rect = events.visualItemRect(events.item(0))
    assert events.horizontalScrollBar().maximum() == 0 and rect.width() <= events.viewport().width()
    assert rect.height() >= 2 * events.fontMetrics().height()  # on two lines or more


# ------------------------------------------------------------------------ live heart rate
def test_live_heart_rate_before_record(qtbot, window, tmp_path):
    stage = window.stages["capture"]
    replay = _strap(60.0, hr_bpm=83)
    _choose(qtbot, stage, replay.path)
    qtbot.waitUntil(lambda: stage.session.watching(replay.path), timeout=10_000)
    thread = start_replay_thread(replay)  # the strap starts sending once the monitor has its port
    qtbot.waitUntil(lambda: stage.live.hr_label.value.text() == "83", timeout=10_000)
    qtbot.waitUntil(lambda: "Hz" in stage.live.counters.labels["rate"].text(), timeout=10_000)
    assert "s ago" in stage.live.counters.labels["last"].text()
    assert "not recording" in stage.live.counters.labels["link"].text()
    assert stage.live.counters.labels["contact"].text().startswith("yes")
    assert not stage.session.recording and not (tmp_path / "sessions").exists()
    stage.preflight.set_choice(port="")  # no strap chosen any more: the watch ends, no stale figure
    qtbot.waitUntil(lambda: stage.session.monitor is None and stage.live.hr_label.value.text() == "--",
                    timeout=10_000)
    _end(replay, thread)


# ------------------------------------------------------ app-wide hotkeys, picker, corrections
def test_hotkeys_from_another_stage_log_catalog_ids_that_work_accepts(qtbot, window, tmp_path):
    capture = window.stages["capture"]
    replay = _strap(40.0, rate_hz=4.0)
    _choose(qtbot, capture, replay.path)
    _confirm(capture, "P22")
    path = _record(qtbot, capture)
    thread = start_replay_thread(replay)
    capture.phases.pick("squats", back_kg=10.0)

    annotate = window.show_stage("annotate")
    assert window.stack.currentIndex() == 1 and not capture.isVisible()
    # the recording is shown in every stage, and is not offered for annotation or training
    qtbot.waitUntil(lambda: window.recording_indicator.isVisible(), timeout=5_000)
    assert "REC" in window.recording_indicator.text() and "P22" in window.recording_indicator.text()
    listed = [annotate.sessions.item(i).data(QtCore.Qt.ItemDataRole.UserRole) for i in range(annotate.sessions.count())]
    assert str(path) not in listed
    assert path not in [e.path for e in scan_sessions(tmp_path / "sessions")]

    _key(qtbot, window, QtCore.Qt.Key.Key_F1)        # rest, typed in Annotate
    qtbot.waitUntil(lambda: _logged(capture, "phase_start", "rest") != [], timeout=5_000)
    qtbot.wait(2200)  # work.csv is at 1 Hz: the rest phase covers whole seconds
    _key(qtbot, window, QtCore.Qt.Key.Key_F2)        # the exercise picked: squats with a 10 kg back load
    for _ in range(3):
        _key(qtbot, window, QtCore.Qt.Key.Key_F9)    # three repetitions
    qtbot.waitUntil(lambda: len(_logged(capture, "reps", "squats")) == 3, timeout=5_000)
    assert "squats" in window.recording_indicator.text()
    assert _logged(capture, "load", "back_kg")[0].value == "10"
    assert [e.value for e in _logged(capture, "reps")] == ["1", "2", "3"]

    window.show_stage("capture")
    # a mistaken key: the squats were lunges; corrected by a new row, never by rewriting history
    row = next(i for i in range(capture.event_list.count())
               if capture.event_list.item(i).data(QtCore.Qt.ItemDataRole.UserRole).label == "squats")
    capture.event_list.setCurrentRow(row)
    capture.correct_to.setCurrentText("lunges")
    qtbot.mouseClick(capture.correct_button, QtCore.Qt.MouseButton.LeftButton)
    assert "corrected: lunges" in capture.event_list.item(row).text()
    assert capture.session.current_exercise == "lunges"
    qtbot.wait(1200)
    _stop(qtbot, capture)
    _end(replay, thread)
    assert not window.recording_indicator.isVisible()

    events = read_events(path / "events.csv")
    assert ("phase_start", "squats") in [(e.kind, e.label) for e in events]  # history kept
    assert any(e.kind == "correction" and e.label == "lunges" for e in events)
    done = subprocess.run([sys.executable, "-m", "effortface", "work", str(path)], capture_output=True, text=True,
                          timeout=120, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    sources = {line.split(",")[3] for line in (path / "work.csv").read_text().splitlines()[1:]}
    assert {"log:rest", "log:lunges"} <= sources and "log:squats" not in sources
    # once finished, the session is offered to Annotate and Train again
    window.show_stage("annotate")
    assert path in [e.path for e in scan_sessions(tmp_path / "sessions")]


# ------------------------------------------------------------------------ the plan, at Stop
def test_a_plan_drives_phases_and_stop_logs_the_note_notes_and_warns_without_sync(qtbot, window, tmp_path):
    stage = window.stages["capture"]
    plan = tmp_path / "PLAN.csv"
    plan.write_text("start_s,end_s,exercise,cadence_per_min,back_kg\n0.5,1.5,rest,,\n1.5,3.0,squats,20,5\n")
    stage.load_plan(str(plan))
    assert "2 phases" in stage.phases.plan_label.text()
    replay = _strap(30.0)
    _choose(qtbot, stage, replay.path)
    _confirm(stage, "P23")
    path = _record(qtbot, stage)
    thread = start_replay_thread(replay)
    assert not stage.phases.plan_button.isEnabled()  # the plan cannot change while recording
    qtbot.waitUntil(lambda: _logged(stage, "phase_end", "squats") != [], timeout=10_000)
    assert "squats: stop" in stage.phases.plan_label.text()
    stage.notes.setPlainText("participant felt dizzy after squats")
    stage.phases.marker_text.setText("water break")      # typed, never sent with F6
    _stop(qtbot, stage)
    _end(replay, thread)
    events = [(e.kind, e.label, e.value) for e in read_events(path / "events.csv")]
    kinds = [(k, lab) for k, lab, _ in events]
    assert kinds.index(("phase_start", "rest")) < kinds.index(("phase_end", "rest")) \
        < kinds.index(("phase_start", "squats")) < kinds.index(("phase_end", "squats"))
    assert ("cadence", "squats", "20") in events and ("load", "back_kg", "5") in events
    assert ("marker", "water break", "") in events
    assert "water break" in stage.banner_text()
    info = read_session_info(path)
    assert info.extra["notes"] == "participant felt dizzy after squats"
    # recorded without video: nothing to synchronise, said in the summary that stays until the next Record
    assert "No sync test" not in stage.banner_text()
    assert stage.summary.isVisible() and stage.summary_sync.text() == "Sync test: no video: no sync needed"


def test_sync_result_is_described() -> None:
    assert describe_sync(None, has_video=False) == ("Sync test: no video: no sync needed", True)
    assert describe_sync(None) == ("Sync test: not done (no flash, F8): the video-to-heart-rate offset is unknown",
                                   False)
    text, ok = describe_sync({"flashes_t_s": [3.0], "offsets_s": [], "video_offset_s": None, "note": "flash not seen"})
    assert not ok and "FAILED" in text
    text, ok = describe_sync({"flashes_t_s": [3.0, 9.0], "offsets_s": [0.04, 0.05], "video_offset_s": 0.045})
    assert ok and "passed" in text and "+45 ms" in text and "2 of 2" in text


def test_model_refuses_unknown_exercise_and_counts_reps_only_in_a_phase(tmp_path) -> None:
    session = CaptureSession(tmp_path)
    with pytest.raises(Exception, match="warmup.*expected an id of the catalog"):
        session.start_phase("warmup")
    with pytest.raises(Exception, match="reps: expected a running exercise phase"):
        session.count_rep()
    session.shutdown()


# ------------------------------------------------------------------------------ the HR plot
def test_plot_zone_labels_gaps_contact_marks_crowding_zoom_and_fixed_banner(qtbot, window) -> None:
    stage = window.stages["capture"]
    live: QtLiveView = stage.live
    live.set_zones(60.0, 180.0)
    for item in live._zone_items:  # each label hangs below its band's upper line: inside its band
        label = next(c for c in item.lines[1].childItems() if hasattr(c, "anchors"))
        assert label.anchors == [(1, 0), (1, 0)]
    live.add_samples(np.array([0.0, 1.0, 2.0]), np.array([70.0, np.nan, 72.0]))
    assert live.n_samples() == 2
    x, y = live.curve.getData()
    assert np.isnan(y).sum() == 1  # drawn as a gap, never a line across it
    for t in (10.0, 10.5, 11.0):
        live.add_marker(t, f"m{t}")
    assert len({m.label_row for m in live._markers}) == 3  # close markers never share a label row
    live.plot.getViewBox().sigRangeChangedManually.emit([True, True])
    assert not live.follow and not live.follow_box.isChecked()
    live.add_samples(np.array([400.0]), np.array([80.0]))
    assert live.plot.viewRange()[0][1] < 400.0  # a zoomed plot is left where the user put it
    live.follow_box.setChecked(True)
    assert live.plot.viewRange()[0][1] >= 400.0
    # the banner keeps its height: a message never shifts the video
    y0, h0 = live.mapTo(stage, QtCore.QPoint(0, 0)).y(), stage.banner.height()
    stage.show_banner("Strap lost: reconnecting by itself. The recording goes on.", "warn")
    QtWidgets.QApplication.processEvents()
    assert (live.mapTo(stage, QtCore.QPoint(0, 0)).y(), stage.banner.height()) == (y0, h0)
    stage.clear_banner()


def test_contact_loss_is_marked_and_drawn_as_a_gap(qtbot, window) -> None:
    stage = window.stages["capture"]
    lines = [b"HR:72\n"] * 8 + [b"HR:0\n"] * 8 + [b"HR:74\n"] * 8
    replay = PtyReplay([TimedChunk(0.25 * i, line) for i, line in enumerate(lines)])
    _choose(qtbot, stage, replay.path)
    _confirm(stage, "P24")
    _record(qtbot, stage)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: "contact back" in stage.live.marker_labels(), timeout=15_000)
    assert "no contact" in stage.live.marker_labels()
    _x, y = stage.live.curve.getData()
    assert np.isnan(y).sum() == 8
    _stop(qtbot, stage)
    _end(replay, thread)


# ------------------------------------------------------------------------------ corrections
def test_corrections_relabel_the_phase_its_end_and_its_parameters_only() -> None:
    events = [Event(1.0, "phase_start", "squats"), Event(1.0, "load", "back_kg", "10"),
              Event(2.0, "reps", "squats", "1"), Event(3.0, "phase_end", "squats"),
              Event(4.0, "phase_start", "squats"), Event(5.0, "phase_end", "squats"),
              Event(6.0, "correction", "lunges", correction_value(1.0))]
    fixed = [(e.kind, e.label) for e in apply_corrections(events)]
    assert fixed[:6] == [("phase_start", "lunges"), ("load", "back_kg"), ("reps", "lunges"),
                         ("phase_end", "lunges"), ("phase_start", "squats"), ("phase_end", "squats")]
