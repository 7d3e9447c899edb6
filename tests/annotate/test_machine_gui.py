"""The machine rater in the Annotate stage offscreen: the reliability panel's machine table (hidden
while a rater rates blind), and the machine guide, no-face shading and "Accept machine" of the editor."""

from __future__ import annotations

import shutil
import threading
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore
from PySide6.QtTest import QTest

from effortface.annotate.agreement import HUMAN_MEAN, format_ci, gather_poses, gather_ratings, machine_ratings, machine_report
from effortface.annotate.gui.annotate_stage import QtAnnotateStage
from effortface.core.jobs import Cancelled
from tests.annotate.machine_helpers import write_fake_machine

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P01_20260112-093000_cardio"


@pytest.fixture
def lab(lab: Path) -> Path:
    """conftest.py's copy of one sample session and the reliability round, with a machine track."""
    write_fake_machine(lab / SESSION)
    return lab


@pytest.fixture
def stage(qtbot, lab: Path) -> QtAnnotateStage:
    widget = QtAnnotateStage(lab, cache_frames=64)
    qtbot.addWidget(widget)
    widget.resize(1400, 900)
    widget.show()
    qtbot.waitExposed(widget)
    yield widget
    widget.shutdown()


def test_reliability_panel_shows_the_machine_apart_once_the_round_is_rated(qtbot, stage: QtAnnotateStage,
                                                                           lab: Path) -> None:
    stage.rater.setText("R4")  # has not rated: blind, nothing of the others nor of the machine
    stage.tabs.setCurrentIndex(1)
    panel = stage.open_reliability()
    assert panel.report is None and not panel.machine_box.isVisible() and panel.machine_table.rowCount() == 0
    stage.rater.setText("R1")  # rated every pose: the report, and the machine apart
    stage.rater.editingFinished.emit()
    panel = stage.open_reliability()
    assert panel.report is not None and panel.machine_box.isVisible()
    assert "machine rater" in panel.machine_box.title().lower()
    assert "MediaPipe face landmarker" in panel.machine_note.text()
    assert panel.machine_note.text().startswith("<b>Machine against the human mean, all blendshapes:</b> n ")
    assert "machine" not in panel.report.raters
    ratings, _ = gather_ratings(lab)
    machine, no_face = machine_ratings(lab, gather_poses(lab))
    expected = machine_report(ratings, machine, no_face=no_face)
    assert panel.machine_table.rowCount() == len(expected.stats) == 4 * 5
    last = panel.machine_table.rowCount() - 1
    mean_all = expected.stats[-1]
    assert (mean_all.reference, mean_all.name) == (HUMAN_MEAN, "all")
    assert [panel.machine_table.item(last, c).text() for c in (0, 1, 3, 4)] == [
        HUMAN_MEAN, "all", f"{mean_all.icc_a1:.3f}", format_ci(mean_all.icc_a1_ci)]


def _open(stage: QtAnnotateStage, lab: Path, rater: str = "R1"):
    stage.rater.setText(rater)
    stage.rater.editingFinished.emit()
    editor = stage.open_session(lab / SESSION, rater)
    assert editor is not None, stage.status.text()
    return editor


def test_editor_draws_the_machine_guide_and_no_face_under_the_keys(qtbot, stage: QtAnnotateStage, lab: Path) -> None:
    editor = _open(stage, lab)
    timeline = editor.timeline
    guide = editor.session.machine
    assert editor.machine_row.isVisible()
    current = editor.session.blendshape
    assert timeline.machine_visible(current)
    x, y = timeline.machine_curves[current].getData()
    assert np.allclose(y[np.isfinite(y)], guide.curve(current)[np.isfinite(guide.curve(current))])
    assert timeline.machine_curves[current].zValue() < timeline.current_curve.zValue()
    assert timeline.machine_curves[current].opts["pen"].style() == QtCore.Qt.PenStyle.DashLine
    spans = guide.no_face_spans()
    assert len(spans) == 2 and len(timeline.no_face.opts["x0"]) == 2
    assert [label.toPlainText() for label in timeline.no_face_labels] == ["no face", "no face"]
    editor.machine_toggles[current].setChecked(False)  # the toggle per blendshape
    assert not timeline.machine_visible(current)
    editor.machine_toggles[current].setChecked(True)
    assert timeline.machine_visible(current)


def test_accept_machine_with_a_over_the_visible_range_is_one_undo_step(qtbot, stage: QtAnnotateStage,
                                                                       lab: Path) -> None:
    editor = _open(stage, lab, "R7")  # a new rater: no keys yet
    editor.session.set_blendshape("eye_squint")
    editor.timeline.frame_all()
    editor.video_view.setFocus()
    assert len(editor.session.track) == 0
    QTest.keyClick(editor.video_view, QtCore.Qt.Key.Key_A)
    keys = editor.session.track.keys
    assert len(keys) > 5
    guide = editor.session.machine
    assert not any(guide.no_face[k.frame] for k in keys)
    assert "accept machine eye_squint" in editor.session.undo_text
    assert editor.timeline.keys.data.size == len(keys)  # drawn
    QTest.keyClick(editor.video_view, QtCore.Qt.Key.Key_Z, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert len(editor.session.track) == 0


def test_a_larger_tolerance_gives_fewer_keys(qtbot, stage: QtAnnotateStage, lab: Path) -> None:
    editor = _open(stage, lab, "R7")
    editor.session.set_blendshape("brow_lower")
    editor.timeline.frame_all()
    counts = []
    for tol in (0.01, 0.1):
        editor.accept_tolerance.setValue(tol)
        qtbot.mouseClick(editor.accept_button, QtCore.Qt.MouseButton.LeftButton)
        counts.append(len(editor.session.track))
    assert counts[0] > counts[1] > 0


def _fake_rate(session_dir: Path, *, force: bool = False, progress=None, cancel=None) -> Path:
    """Test stand-in for the engine: reports progress, then writes a test track (raters' mean + noise)."""
    for i in range(3):
        if cancel is not None and cancel():
            raise Cancelled("cancelled")
        if progress is not None:
            progress(i + 1, 3)
    if force:
        (session_dir / "machine" / "face_landmarker.csv").unlink(missing_ok=True)
    return write_fake_machine(session_dir, seed=5)


def _stalled_rate(session_dir: Path, *, force: bool = False, progress=None, cancel=None) -> Path:
    """Reports progress until cancelled, writes nothing (a long video under way)."""
    wake = threading.Event()
    while not cancel():
        progress(1, 1000)
        wake.wait(0.02)
    raise Cancelled("cancelled")


def test_preannotate_in_the_background_then_the_guide_appears(qtbot, tmp_path: Path) -> None:
    lab = tmp_path / "bare"
    shutil.copytree(SAMPLES / SESSION, lab / SESSION, ignore=shutil.ignore_patterns("serial", "work.csv"))
    view = QtAnnotateStage(lab, cache_frames=64)
    qtbot.addWidget(view)
    view.resize(1400, 900)
    view.show()
    try:
        view.preannotate._rate = _fake_rate
        editor = _open(view, lab)
        assert not editor.machine_row.isVisible() and editor.session.machine is None
        view.sessions.setCurrentRow(0)
        view.preannotate_button.click()
        assert view.preannotate_button.text() == "Cancel pre-annotate"
        qtbot.waitUntil(lambda: view.preannotate_button.text() == "Pre-annotate", timeout=30_000)
        assert "pre-annotate: 1 session rated" in view.status.text()
        assert (lab / SESSION / "machine" / "face_landmarker.csv").is_file()
        assert editor.machine_row.isVisible() and editor.session.machine is not None
        view.confirm_replace = lambda n: False  # a second run keeps the track
        view.preannotate_button.click()
        qtbot.waitUntil(lambda: view.preannotate_button.text() == "Pre-annotate", timeout=30_000)
        assert "1 kept (a machine track exists)" in view.status.text()
    finally:
        view.shutdown()


def test_cancel_preannotate_writes_nothing(qtbot, tmp_path: Path) -> None:
    lab = tmp_path / "bare"
    shutil.copytree(SAMPLES / SESSION, lab / SESSION, ignore=shutil.ignore_patterns("serial", "work.csv"))
    view = QtAnnotateStage(lab, cache_frames=64)
    qtbot.addWidget(view)
    try:
        view.preannotate._rate = _stalled_rate
        view.sessions.setCurrentRow(0)
        view.preannotate_button.click()
        qtbot.waitUntil(lambda: "frame 1 of 1000" in view.status.text(), timeout=30_000)
        view.preannotate_button.click()  # the same button cancels
        qtbot.waitUntil(lambda: view.preannotate_button.text() == "Pre-annotate", timeout=30_000)
        assert "cancelled" in view.status.text()
        assert not (lab / SESSION / "machine").exists()
    finally:
        view.shutdown()


def test_the_report_tables_grow_with_the_window(qtbot, stage: QtAnnotateStage) -> None:
    stage.resize(1280, 800)
    stage.rater.setText("R1")
    stage.rater.editingFinished.emit()
    stage.tabs.setCurrentIndex(1)
    panel = stage.open_reliability()
    qtbot.waitUntil(lambda: panel.report is not None and panel.per_pose.isVisible())
    small = (panel.per_pose.height(), panel.machine_table.height(), panel.ba_plot.height())
    stage.resize(1920, 1080)
    qtbot.waitUntil(lambda: panel.per_pose.height() > small[0])
    grown = (panel.per_pose.height() - small[0], panel.machine_table.height() - small[1],
             panel.ba_plot.height() - small[2])
    assert grown[0] >= grown[2] > 0 and grown[1] > 0  # the tables take at least as much as the plot
