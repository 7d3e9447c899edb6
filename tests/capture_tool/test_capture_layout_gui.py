"""Capture at 1280x800 and 1920x1080, the real main window offscreen on a copy of the sample lab:
Record/Stop always in sight (a fixed action bar), the last recording's summary and plot stay after
Stop until the next Record, a recording without video needs no sync, one question before a doomed
Record, and the form is empty after Stop."""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets

from effortface.capture_tool.replay import start_replay_thread

from .test_capture_stage_daily import _choose, _end, _record, _stop, _strap
from .conftest import capture_stage_on
from .test_participant_truth import copy_sample_lab

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


@pytest.fixture(params=[(1280, 800), (1920, 1080)], ids=["1280x800", "1920x1080"])
def size(request) -> tuple[int, int]:
    return request.param


@pytest.fixture
def stage(qtbot, tmp_path: Path, size: tuple[int, int]):
    yield from capture_stage_on(qtbot, copy_sample_lab(tmp_path / "lab"), tmp_path / "settings.ini", size)


def _in_sight(widget: QtWidgets.QWidget) -> bool:
    """The whole widget is visible inside its window (not scrolled away, not below the fold)."""
    window = widget.window()
    top_left = widget.mapTo(window, QtCore.QPoint(0, 0))
    rect = QtCore.QRect(top_left, widget.size())
    return widget.isVisible() and window.rect().contains(rect) and not widget.visibleRegion().isEmpty() \
        and widget.visibleRegion().boundingRect().size() == widget.size()


def test_record_stays_in_sight_and_the_summary_stays_after_stop(qtbot, stage, size: tuple[int, int]) -> None:
    replay = _strap(60.0)
    _choose(qtbot, stage, replay.path)
    stage.form.registry.setCurrentText("P01")  # a registered participant: the form grows
    qtbot.wait(50)
    assert stage.form.validate() == "" and _in_sight(stage.record_button)
    assert not stage.summary.isVisible()
    _record(qtbot, stage)
    thread = start_replay_thread(replay)
    assert _in_sight(stage.record_button) and stage.record_button.text().endswith("Stop")
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 8, timeout=15_000)
    assert not stage.live.monitor_box.isVisible()  # while recording, the strap is in the big plot only
    stage.phases.marker_text.setText("water")
    stage.phases.pick("treadmill_run", speed_m_s=3.6, grade_pct=1.0)  # its parameters make the log taller
    path = _stop(qtbot, stage)
    recorded = stage.live.n_samples()
    qtbot.wait(50)
    assert stage.window().size() == QtCore.QSize(*size)  # the summary never makes the window taller
    assert stage.summary.isVisible() and _in_sight(stage.summary) and _in_sight(stage.record_button)
    summary = stage.summary_text.text()
    assert f"Saved, complete: <b>{path.name}</b>" in summary and "heart-rate samples" in summary
    assert "no video" in summary and "1 event logged" in summary
    assert stage.summary_sync.text() == "Sync test: no video: no sync needed"
    assert "No sync test" not in stage.banner_text()
    # the strap is watched again: its readout goes on, the recording's plot and summary stay
    qtbot.waitUntil(lambda: stage.session.watching(replay.path), timeout=10_000)
    qtbot.waitUntil(lambda: stage.live.n_monitor_samples() >= 2, timeout=10_000)
    qtbot.wait(1000)
    assert stage.summary.isVisible() and stage.live.n_samples() == recorded
    # the live strap in a place of its own, labelled, beside the readout: in sight with the recording's plot
    monitor = stage.live.monitor_box
    assert monitor.title() == "Live strap (not recording)" and _in_sight(monitor) and _in_sight(stage.live.plot.viewport())
    assert not monitor.geometry().intersects(stage.live.plot.geometry())
    assert _in_sight(stage.live.hr_label) and _in_sight(stage.live.counters)
    assert stage.window().size() == QtCore.QSize(*size)
    assert f"Saved, complete: <b>{path.name}</b>" in stage.summary_text.text()
    # the form is empty for the next participant
    assert stage.form.code.text() == "" and stage.form.registry.currentIndex() == 0
    assert stage.form.values()["sex"] is None
    # the next Record takes the summary away
    stage.form.registry.setCurrentText("P02")
    _record(qtbot, stage)
    assert not stage.summary.isVisible() and not stage.live.monitor_box.isVisible()
    _stop(qtbot, stage)
    _end(replay, thread)


def test_a_doomed_record_asks_once_and_fails_in_the_apps_words(qtbot, stage, tmp_path: Path, monkeypatch) -> None:
    stage.preflight.set_choice(port=str(tmp_path / "ttyUSB9"), protocol="hxm")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    stage.form.registry.setCurrentText("P01")
    asked: list[tuple[str, str]] = []
    monkeypatch.setattr(QtWidgets.QMessageBox, "question",
                        lambda parent, title, text, *a: (asked.append((title, text)),
                                                         QtWidgets.QMessageBox.StandardButton.Yes)[1])
    missing = stage.preflight.missing()
    assert "strap" in missing
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: stage.settled() and "Could not start" in stage.banner_text(), timeout=10_000)
    assert len(asked) == 1 and asked[0][0] == "Devices not ready"
    assert "heart-rate strap is not shown ready" in asked[0][1]
    assert ("camera chosen is not ready" in asked[0][1]) == ("camera" in missing)
    assert "--port" not in stage.banner_text() and "strap port" in stage.banner_text()
    assert not stage.session.recording
