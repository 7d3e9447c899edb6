"""The Annotate stage offscreen: key a sample session with keyboard and mouse, save, reopen, undo;
blind raters; a killed annotator loses no saved key; the reliability round; export."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore
from PySide6.QtTest import QTest

from effortface.annotate.agreement import agreement_report, gather_ratings
from effortface.annotate.agreement import format_ci as ag_format_ci
from effortface.annotate.gui.annotate_stage import QtAnnotateStage
from effortface.annotate.keyframes import read_annotations
from effortface.annotate.reliability import read_ratings
from effortface.core.fileio import remove_stale_temps

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P01_20260112-093000_cardio"
Key = QtCore.Qt.Key
Left = QtCore.Qt.MouseButton.LeftButton


def _open_by_mouse(qtbot, stage: QtAnnotateStage, rater: str):
    rect = stage.sessions.visualItemRect(stage.sessions.item(0))
    QTest.mouseClick(stage.sessions.viewport(), Left, pos=rect.center())
    stage.rater.clear()
    qtbot.keyClicks(stage.rater, rater)
    qtbot.mouseClick(stage.open_button, Left)
    assert stage.editor is not None, stage.status.text()
    return stage.editor


def _press(widget, key, modifier=QtCore.Qt.KeyboardModifier.NoModifier, times: int = 1) -> None:
    for _ in range(times):
        QTest.keyClick(widget, key, modifier)


def _view_point(timeline, scene_pos: QtCore.QPointF) -> QtCore.QPoint:
    return timeline.mapFromScene(scene_pos)


def _clicked_time(timeline, point: QtCore.QPoint) -> float:
    """The session time under a widget pixel (what a click there means)."""
    return timeline._curve_box.mapSceneToView(timeline.mapToScene(point)).x()


def _double_click(widget, pos: QtCore.QPoint) -> None:
    """Press, release, double-click, release: what Qt sends a widget for a double click."""
    from PySide6 import QtGui, QtWidgets

    QTest.mouseClick(widget, Left, pos=pos)
    event = QtGui.QMouseEvent(QtCore.QEvent.Type.MouseButtonDblClick, QtCore.QPointF(pos),
                              QtCore.QPointF(widget.mapToGlobal(pos)), Left, Left,
                              QtCore.Qt.KeyboardModifier.NoModifier)
    QtWidgets.QApplication.sendEvent(widget, event)
    QTest.mouseRelease(widget, Left, pos=pos)


def _drag(timeline, start: QtCore.QPointF, end: QtCore.QPointF) -> None:
    viewport = timeline.viewport()
    a, b = _view_point(timeline, start), _view_point(timeline, end)
    QTest.mousePress(viewport, Left, pos=a)
    for f in np.linspace(0.1, 1.0, 8):
        QTest.mouseMove(viewport, QtCore.QPoint(round(a.x() + f * (b.x() - a.x())), round(a.y() + f * (b.y() - a.y()))))
    QTest.mouseRelease(viewport, Left, pos=b)


def _on_disk(editor) -> dict:
    return read_annotations(editor.session.path).to_dict()


def test_key_a_session_end_to_end(qtbot, stage: QtAnnotateStage, lab: Path) -> None:
    r1_before = (lab / SESSION / "annotations" / "R1.json").read_bytes()
    editor = _open_by_mouse(qtbot, stage, "R9")
    m, view = editor.session, editor.video_view
    # blind: the other raters' files are there, but nothing of theirs is loaded or drawn
    assert all(len(t) == 0 for t in m.annotations.tracks.values())
    assert len(editor.timeline.keys.data) == 0
    view.setFocus()
    # keyboard: digits key the current frame, arrows step exactly, Shift steps ten
    _press(view, Key.Key_3)
    _press(view, Key.Key_Right, times=5)
    _press(view, Key.Key_Right, QtCore.Qt.KeyboardModifier.ShiftModifier)
    assert m.frame == 15
    _press(view, Key.Key_7)
    _press(view, Key.Key_Up)  # 0.7 + 0.05
    assert [(k.frame, k.weight) for k in m.track.keys] == [(0, 0.3), (15, 0.75)]
    assert editor.protocol.number.value() == pytest.approx(0.75)
    _press(view, Key.Key_End)
    _press(view, Key.Key_2)
    assert "mouth_stretch" in m.passes_done and "press N for mouth_open" in stage.status.text()
    assert "background" in editor.protocol.next_button.styleSheet()  # the next blendshape is offered
    assert _on_disk(editor) == m.annotations.to_dict()  # saved on every key
    _press(view, Key.Key_N)
    assert (m.blendshape, m.frame) == ("mouth_open", 0)
    # the number box and the Set key button
    editor.protocol.number.lineEdit().selectAll()
    qtbot.keyClicks(editor.protocol.number, "0.45")
    _press(editor.protocol.number, Key.Key_Return)
    assert m.track.get(0).weight == pytest.approx(0.45)
    # mouse on the curve editor: click empty space = go to that time; double-click = add a key
    tl = editor.timeline
    at50 = _view_point(tl, tl.time_scene_pos(50.0, 0.9))
    QTest.mouseClick(tl.viewport(), Left, pos=at50)
    assert m.frame == m.times.frame_at(_clicked_time(tl, at50))
    at100 = _view_point(tl, tl.time_scene_pos(100.0, 0.6))
    _double_click(tl.viewport(), at100)
    f100 = m.times.frame_at(_clicked_time(tl, at100))
    assert m.track.get(f100) is not None and m.track.get(f100).weight == pytest.approx(0.6, abs=0.03)
    # back to mouth_stretch by clicking its row; drag its key from frame 15 to about t = 40 s, 0.5
    rect = editor.protocol.shapes.visualItemRect(editor.protocol.shapes.item(0))
    QTest.mouseClick(editor.protocol.shapes.viewport(), Left, pos=rect.center())
    assert m.blendshape == "mouth_stretch"
    _drag(tl, tl.key_point_scene_pos(15), tl.time_scene_pos(40.0, 0.5))
    moved = [k for k in m.track.keys if k.frame not in (0, m.n_frames - 1)]
    assert len(moved) == 1 and abs(m.times.t_at(moved[0].frame) - 40.0) < 0.5
    assert moved[0].weight == pytest.approx(0.5, abs=0.03) and m.track.get(15) is None
    assert tl.selected == moved[0].frame
    # undo the drag with Ctrl+Z, redo it with Ctrl+Y, undo again
    view.setFocus()
    _press(view, Key.Key_Z, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert m.track.get(15).weight == pytest.approx(0.75)
    _press(view, Key.Key_Y, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert m.track.get(15) is None
    _press(view, Key.Key_Z, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert _on_disk(editor) == m.annotations.to_dict()
    # copy the key on frame 15, paste it at frame 200, delete the one on frame 0
    m.set_frame(15)
    tl.select_key(None)
    _press(view, Key.Key_C, QtCore.Qt.KeyboardModifier.ControlModifier)
    m.set_frame(200)
    _press(view, Key.Key_V, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert m.track.get(200).weight == pytest.approx(0.75)
    _press(view, Key.Key_Home)
    _press(view, Key.Key_Delete)
    assert m.track.get(0) is None
    saved = m.annotations.to_dict()
    assert _on_disk(editor) == saved
    # reopen in a fresh stage: the same keys come back
    stage.close_session()
    again = QtAnnotateStage(lab)
    qtbot.addWidget(again)
    editor2 = again.open_session(lab / SESSION, "R9")
    assert editor2.session.annotations.to_dict() == saved
    again.shutdown()
    assert (lab / SESSION / "annotations" / "R1.json").read_bytes() == r1_before


def test_the_video_shows_the_exact_frame_and_playback_advances(qtbot, stage: QtAnnotateStage) -> None:
    editor = _open_by_mouse(qtbot, stage, "R1")
    m = editor.session
    editor.video_view.setFocus()
    _press(editor.video_view, Key.Key_Right, times=12)
    expected = editor.video.get(12, prefetch=False)
    shown = editor.video_view._image
    assert (shown.width(), shown.height()) == (expected.shape[1], expected.shape[0])
    rgb = np.frombuffer(shown.constBits(), np.uint8).reshape(shown.height(), shown.bytesPerLine())
    np.testing.assert_array_equal(rgb[:, :expected.shape[1] * 3].reshape(expected.shape)[:, :, ::-1], expected)
    assert editor.frame_box.value() == 12 and editor.time_box.value() == pytest.approx(m.t_s, abs=1e-3)
    # scrub: drag the cursor line of the heart-rate plot to about t = 120 s
    tl = editor.timeline
    hr_box = tl.hr_plot.getViewBox()
    y_mid = sum(hr_box.viewRange()[1]) / 2
    end = _view_point(tl, hr_box.mapViewToScene(QtCore.QPointF(120.0, y_mid)))
    _drag(tl, hr_box.mapViewToScene(QtCore.QPointF(m.t_s, y_mid)), hr_box.mapViewToScene(QtCore.QPointF(120.0, y_mid)))
    t_end = hr_box.mapSceneToView(tl.mapToScene(end)).x()
    # the line moves by the mouse's displacement from the press pixel, so the press's and the
    # release's rounding add up to at most one pixel (about 1 s over the sample lab's 10-minute sessions)
    s_per_px = hr_box.mapSceneToView(tl.mapToScene(end + QtCore.QPoint(1, 0))).x() - t_end
    assert m.times.frame_at(t_end - s_per_px) <= m.frame <= m.times.frame_at(t_end + s_per_px)
    assert abs(m.t_s - 120.0) < 0.5 + s_per_px
    editor.speed.setCurrentIndex(4)  # 4x
    _press(editor.video_view, Key.Key_Space)
    start = m.frame
    qtbot.waitUntil(lambda: m.frame > start + 20, timeout=10_000)
    _press(editor.video_view, Key.Key_Space)
    assert not editor.playing
    # go to a time typed in the time box: the frame on screen at that time, from the timestamps
    editor.time_box.lineEdit().selectAll()
    qtbot.keyClicks(editor.time_box, "57.5")
    _press(editor.time_box, Key.Key_Return)
    assert m.frame == m.times.frame_at(57.5)


def test_bad_rater_code_is_shown_in_the_stage(qtbot, stage: QtAnnotateStage) -> None:
    stage.rater.setText("Jane Doe")
    qtbot.mouseClick(stage.open_button, Left)
    assert stage.editor is None and "rater: expected a code" in stage.status.text()


def test_export_writes_weights_and_keyframes_and_never_overwrites(qtbot, stage: QtAnnotateStage, tmp_path: Path) -> None:
    editor = _open_by_mouse(qtbot, stage, "R2")
    csv = stage.export_weights(tmp_path / "w.csv")
    lines = csv.read_text().splitlines()
    assert lines[0] == "frame,t_s,mouth_stretch,mouth_open,eye_squint,brow_lower"
    assert len(lines) == 1 + editor.session.n_frames
    row = lines[700].split(",")
    expected = editor.session.weights(699)
    assert [float(v) for v in row[2:]] == pytest.approx(list(expected.values()), abs=1e-4)
    keys = stage.export_keyframes(tmp_path / "k.json")
    assert read_annotations(keys).to_dict() == editor.session.annotations.to_dict()
    assert stage.export_weights(tmp_path / "w.csv") is None
    assert "refusing to overwrite" in stage.status.text()


def test_reliability_report_matches_the_library(qtbot, stage: QtAnnotateStage, lab: Path) -> None:
    stage.rater.setText("R1")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    assert panel is not None and panel.report is not None  # R1 rated every pose in the lab's round
    ratings, source = gather_ratings(lab)
    expected = agreement_report(ratings, source=source)
    assert panel.per_shape.rowCount() == 5
    assert panel.per_shape.item(4, 3).text() == f"{expected.overall.icc_a1:.3f}"
    assert panel.per_shape.item(4, 4).text() == ag_format_ci(expected.overall.icc_a1_ci)
    assert panel.per_shape.item(4, 7).text() == f"{expected.overall.alpha:.3f}"
    flagged = [panel.per_pose.item(r, 0).text() for r in range(panel.per_pose.rowCount())
               if panel.per_pose.item(r, 2).text() == "FLAG"]
    assert flagged and sorted(flagged) == sorted(expected.flagged)
    assert flagged == [panel.per_pose.item(r, 0).text() for r in range(len(flagged))]  # the worst come first
    panel.threshold.setValue(10.0)
    assert panel.report.flagged == agreement_report(ratings, flag_pct=10.0).flagged


def test_a_new_rater_rates_blind_then_sees_the_report(qtbot, stage: QtAnnotateStage, lab: Path) -> None:
    stage.rater.setText("R4")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    assert panel.report is None and panel.per_pose.rowCount() == 0  # nothing shown before rating
    for row in range(18):
        panel.poses.setCurrentCell(row, 0)
        for i, spin in enumerate(panel.spins.values()):
            spin.setValue(((row + i) % 10) / 10)
        qtbot.mouseClick(panel.save_button, Left)
    assert panel.report is not None and panel.report.raters == ["R1", "R2", "R3", "R4"]
    mine = read_ratings(lab / "reliability" / "ratings_R4.csv")
    assert len(mine) == 72 and {r.rater for r in mine} == {"R4"}


def test_switching_rater_shows_the_new_raters_ratings_of_the_selected_pose(qtbot, stage: QtAnnotateStage,
                                                                           lab: Path) -> None:
    stage.rater.setText("R4")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    assert panel.save_button.isEnabled()  # R4 has not rated pose 1 yet
    stage.tabs.setCurrentIndex(0)
    stage.rater.setText("R1")
    stage.tabs.setCurrentIndex(1)
    pose = panel.round.poses[panel.poses.currentRow()]
    r1 = {r.blendshape: r.weight for r in read_ratings(lab / "reliability" / "ratings.csv")
          if r.rater == "R1" and r.pose_id == pose.pose_id}
    assert not panel.save_button.isEnabled()  # R1's ratings live in the lab's file: shown, locked
    assert {n: s.value() for n, s in panel.spins.items()} == pytest.approx(r1, abs=0.005)
    assert not any(s.isEnabled() for s in panel.spins.values())


ANNOTATOR = textwrap.dedent("""
    import sys
    from pathlib import Path
    from PySide6 import QtCore, QtWidgets
    from PySide6.QtTest import QTest
    from effortface.annotate.gui.annotate_stage import QtAnnotateStage
    app = QtWidgets.QApplication([])
    lab, session = Path(sys.argv[1]), sys.argv[2]
    stage = QtAnnotateStage(lab)
    stage.show()
    stage.activateWindow()
    QTest.qWaitForWindowActive(stage)
    editor = stage.open_session(lab / session, "R7")
    view, m = editor.video_view, editor.session
    view.setFocus()
    n = 0
    while True:  # key every third frame until killed
        QTest.keyClick(view, QtCore.Qt.Key.Key_Right, QtCore.Qt.KeyboardModifier.NoModifier)
        QTest.keyClick(view, QtCore.Qt.Key.Key_Right, QtCore.Qt.KeyboardModifier.NoModifier)
        QTest.keyClick(view, QtCore.Qt.Key.Key_Right, QtCore.Qt.KeyboardModifier.NoModifier)
        QTest.keyClick(view, getattr(QtCore.Qt.Key, f"Key_{n % 10}"), QtCore.Qt.KeyboardModifier.NoModifier)
        print(f"KEYED {m.frame} {m.track.get(m.frame).weight}", flush=True)
        n += 1
""")


def test_a_killed_annotator_loses_no_saved_key(lab: Path) -> None:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-c", ANNOTATOR, str(lab), SESSION], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, env=env, cwd=ROOT)
    keyed: list[tuple[int, float]] = []
    try:
        for line in proc.stdout:
            if line.startswith("KEYED"):
                _, frame, weight = line.split()
                keyed.append((int(frame), float(weight)))
            if len(keyed) >= 40:
                break
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(30)
    assert proc.returncode == -signal.SIGKILL and len(keyed) == 40
    track = read_annotations(lab / SESSION / "annotations" / "R7.json").tracks["mouth_stretch"]
    on_disk = {k.frame: k.weight for k in track.keys}
    assert all(on_disk.get(frame) == pytest.approx(weight) for frame, weight in keyed)
    # a kill during a save can leave that one save's temporary file, never more, and it is a
    # recognised temporary of R7.json: the next save removes it once stale (effortface.core.fileio)
    leftovers = list((lab / SESSION / "annotations").glob(".*.tmp"))
    assert len(leftovers) <= 1
    target = lab / SESSION / "annotations" / "R7.json"
    assert sorted(remove_stale_temps(target, min_age_s=0)) == sorted(leftovers)
    assert not list((lab / SESSION / "annotations").glob(".*.tmp"))


def test_the_pyside_none_leak_is_guarded(qtbot, stage: QtAnnotateStage) -> None:
    import sys

    from effortface.core.gui.qt_compat import pyside_leaks_none

    if pyside_leaks_none():  # PySide6 6.12.0 on CPython 3.11: void calls drop a reference to None
        assert sys.getrefcount(None) > 1 << 39
    for _ in range(20_000):  # far more than the ~19 000 references None starts with
        stage.status.setText("x")


# ------------------------------------------------------------------ review fixes (GUI audit)
def _wheel(widget, dy: int = 120) -> None:
    """A mouse-wheel notch over the middle of ``widget`` (spontaneous, as from a real mouse)."""
    from PySide6 import QtGui, QtWidgets

    pos = QtCore.QPointF(widget.width() / 2, widget.height() / 2)
    event = QtGui.QWheelEvent(pos, QtCore.QPointF(widget.mapToGlobal(pos.toPoint())), QtCore.QPoint(),
                              QtCore.QPoint(0, dy), QtCore.Qt.MouseButton.NoButton,
                              QtCore.Qt.KeyboardModifier.NoModifier, QtCore.Qt.ScrollPhase.NoScrollPhase, False)
    QtWidgets.QApplication.sendEvent(widget, event)


def test_typing_another_rater_code_hides_the_previous_raters_report(qtbot, stage: QtAnnotateStage) -> None:
    stage.rater.setText("R1")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    assert panel.isVisible() and panel.report is not None  # R1 has finished: their report is shown
    stage.rater.clear()
    qtbot.keyClicks(stage.rater, "R1")  # on the way to R12: must not show R1's round again
    assert not panel.isVisible() and stage.reliability_note.isVisible()
    qtbot.keyClicks(stage.rater, "2")
    assert not panel.isVisible()
    _press(stage.rater, Key.Key_Return)  # confirmed: R12's own, blind round
    assert panel.isVisible() and panel.rater == "R12" and panel.report is None
    assert panel.per_pose.rowCount() == 0 and not panel.results.currentIndex()
    assert all(s.text() == "unrated" and s.isEnabled() for s in panel.spins.values())  # never a silent 0


def test_typing_another_rater_code_hides_the_open_session(qtbot, stage: QtAnnotateStage, tmp_path: Path) -> None:
    editor = _open_by_mouse(qtbot, stage, "R1")
    assert editor.isVisible() and len(editor.session.track) > 0
    stage.rater.clear()
    qtbot.keyClicks(stage.rater, "R2")
    assert not editor.isVisible() and not editor.timeline.isVisible()  # R1's keys and title are gone
    assert stage.placeholder.isVisible() and "R2" in stage.placeholder.text()
    assert stage.export_keyframes(tmp_path / "k.json") is None  # nor exported for R2
    assert not (tmp_path / "k.json").exists()
    qtbot.mouseClick(stage.open_button, Left)  # R2 opens the session: only R2's keys
    assert stage.editor is not editor and stage.editor.isVisible() and stage.editor.session.rater == "R2"
    stage.rater.clear()
    qtbot.keyClicks(stage.rater, "R2")
    assert not stage.editor.isVisible()
    _press(stage.rater, Key.Key_Return)  # the same code confirmed: back to R2's session
    assert stage.editor.isVisible() and stage.editor.session.rater == "R2"


def _finish_the_round_as_r4(qtbot, stage: QtAnnotateStage):
    """Rate all 18 poses of the blind round as R4 (every weight 0.3); returns the reliability panel."""
    stage.rater.setText("R4")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    for row in range(18):
        panel.poses.setCurrentCell(row, 0)
        for spin in panel.spins.values():
            spin.setValue(0.3)
        qtbot.mouseClick(panel.save_button, Left)
    return panel


def test_a_rater_who_finished_the_round_cannot_change_a_rating(qtbot, stage: QtAnnotateStage, lab: Path) -> None:
    panel = _finish_the_round_as_r4(qtbot, stage)
    assert panel.report is not None
    before = (lab / "reliability" / "ratings_R4.csv").read_bytes()
    panel.poses.setCurrentCell(3, 0)
    assert not panel.save_button.isEnabled() and "locked" in panel.save_button.text()
    assert not any(s.isEnabled() for s in panel.spins.values())
    panel.save_pose()  # even if a save got through, it is refused with a clear message
    assert "finished the blind round" in panel.status.text()
    assert (lab / "reliability" / "ratings_R4.csv").read_bytes() == before


def test_the_mouse_wheel_over_the_protocol_panel_never_edits(qtbot, stage: QtAnnotateStage) -> None:
    editor = _open_by_mouse(qtbot, stage, "R9")
    m, p = editor.session, editor.protocol
    editor.video_view.setFocus()
    _press(editor.video_view, Key.Key_Right, times=7)
    for widget, dy in ((p.number, 120), (p.slider, 120), (p.interp, -120), (p.interp, 120)):
        _wheel(widget, dy)
    assert len(m.track) == 0 and not m.can_undo and m.interp == "linear"
    assert p.interp.currentText() == "linear" and p.number.value() == 0.0
    qtbot.mouseClick(p.number, Left)  # clicked into: now the wheel is meant for the box
    assert p.number.hasFocus()
    _wheel(p.number)
    assert m.key_at() is not None and m.key_at().weight == pytest.approx(0.01)


def test_delete_and_copy_act_on_the_current_frame_not_on_an_old_selection(qtbot, stage: QtAnnotateStage) -> None:
    editor = _open_by_mouse(qtbot, stage, "R9")
    m, view, tl = editor.session, editor.video_view, editor.timeline
    view.setFocus()
    _press(view, Key.Key_Right, times=2)
    _press(view, Key.Key_7)
    QTest.mouseClick(tl.viewport(), Left, pos=_view_point(tl, tl.key_point_scene_pos(2)))  # select it
    assert tl.selected == 2
    _press(view, Key.Key_Right, times=20)
    assert tl.selected is None  # moving away clears the selection
    _press(view, Key.Key_4)
    _press(view, Key.Key_C, QtCore.Qt.KeyboardModifier.ControlModifier)
    _press(view, Key.Key_Delete)
    assert m.track.get(22) is None and m.track.get(2).weight == pytest.approx(0.7)
    _press(view, Key.Key_Right)
    _press(view, Key.Key_V, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert m.track.get(23).weight == pytest.approx(0.4)  # Ctrl+C copied frame 22's key, not frame 2's
    _drag(tl, tl.key_point_scene_pos(2), tl.time_scene_pos(m.times.t_at(60), 0.5))  # dragging still works
    assert m.track.get(2) is None and tl.selected is not None and m.frame == tl.selected


def test_escape_in_the_frame_box_cancels_and_gives_the_keys_back(qtbot, stage: QtAnnotateStage) -> None:
    from PySide6 import QtWidgets

    editor = _open_by_mouse(qtbot, stage, "R9")
    m, view = editor.session, editor.video_view
    view.setFocus()
    _press(view, Key.Key_Right, times=4)
    _press(view, Key.Key_G, QtCore.Qt.KeyboardModifier.ControlModifier)
    assert QtWidgets.QApplication.focusWidget() is editor.frame_box
    qtbot.keyClicks(editor.frame_box, "123")
    _press(editor.frame_box, Key.Key_Escape)
    assert QtWidgets.QApplication.focusWidget() is view
    assert m.frame == 4 and editor.frame_box.text() == "4"
    _press(QtWidgets.QApplication.focusWidget(), Key.Key_Right)
    _press(QtWidgets.QApplication.focusWidget(), Key.Key_3)
    assert m.frame == 5 and m.key_at().weight == pytest.approx(0.3)


def test_rescan_lists_a_session_recorded_since_and_keeps_the_selection(qtbot, stage: QtAnnotateStage,
                                                                       lab: Path) -> None:
    assert stage.sessions.count() == 1
    new = "P02_20260112-113700_strength"
    shutil.copytree(SAMPLES / new, lab / new, ignore=shutil.ignore_patterns("serial", "work.csv"))
    stage.sessions.setFocus()
    _press(stage.sessions, Key.Key_F5)
    assert stage.sessions.count() == 2
    assert stage.sessions.currentItem().text().startswith(SESSION)  # still the one chosen before
    shutil.rmtree(lab / new)
    qtbot.mouseClick(stage.rescan_button, Left)
    assert stage.sessions.count() == 1
    shutil.copytree(SAMPLES / new, lab / new, ignore=shutil.ignore_patterns("serial", "work.csv"))
    stage.hide()
    stage.show()  # shown again (the main window's stage list does this): listed at once
    assert stage.sessions.count() == 2


def test_hiding_the_stage_pauses_playback(qtbot, stage: QtAnnotateStage) -> None:
    editor = _open_by_mouse(qtbot, stage, "R1")
    editor.video_view.setFocus()
    _press(editor.video_view, Key.Key_Space)
    assert editor.playing
    stage.hide()
    assert not editor.playing and not editor.play_button.isChecked()
    stage.show()
    qtbot.mouseClick(editor.play_button, Left)
    assert editor.playing
    stage.tabs.setCurrentIndex(1)  # the editor is out of sight on the other tab too
    assert not editor.playing


def test_a_finished_rating_is_corrected_with_a_reason_and_the_report_recomputes(qtbot, stage: QtAnnotateStage,
                                                                                lab: Path) -> None:
    panel = _finish_the_round_as_r4(qtbot, stage)
    assert panel.report is not None and panel.correct_box.isVisibleTo(panel)
    panel.poses.setCurrentCell(0, 0)
    pose = panel.round.poses[0].pose_id
    before = panel.report.overall.disagreement_pct
    panel.correct_shape.setCurrentText("mouth_open")
    panel.correct_value.setValue(0.9)
    qtbot.mouseClick(panel.correct_button, Left)  # no reason: refused, nothing written
    assert "expected a reason" in panel.status.text()
    assert not (lab / "reliability" / "corrections_R4.csv").exists()
    qtbot.keyClicks(panel.correct_reason, "typo")
    qtbot.mouseClick(panel.correct_button, Left)
    assert "corrected 0.30 -> 0.90" in panel.status.text()
    mine = {(r.pose_id, r.blendshape): r.weight for r in read_ratings(lab / "reliability" / "ratings_R4.csv")}
    assert mine[(pose, "mouth_open")] == 0.9
    log = (lab / "reliability" / "corrections_R4.csv").read_text().splitlines()
    assert log[0] == "time_utc,pose_id,blendshape,old,new,reason" and log[1].endswith(f",{pose},mouth_open,0.3000,0.9000,typo")
    assert panel.spins["mouth_open"].value() == pytest.approx(0.9)
    assert panel.report.overall.disagreement_pct != before  # recomputed


def test_a_correction_on_a_full_disk_is_stated_and_changes_nothing(qtbot, stage: QtAnnotateStage, lab: Path,
                                                                   monkeypatch) -> None:
    """Issue 37: the correction's log and ratings are written together; a full disk is one status line
    naming the file (it was an unhandled error, with the correction logged but not applied)."""
    from tests.annotate.test_outputs_together import fill_the_disk_on

    panel = _finish_the_round_as_r4(qtbot, stage)
    panel.poses.setCurrentCell(0, 0)
    ratings = lab / "reliability" / "ratings_R4.csv"
    before = ratings.read_bytes()
    fill_the_disk_on(monkeypatch, ratings.name)
    panel.correct_shape.setCurrentText("mouth_open")
    panel.correct_value.setValue(0.9)
    qtbot.keyClicks(panel.correct_reason, "typo")
    qtbot.mouseClick(panel.correct_button, Left)
    assert panel.status.text() == (f"{ratings}: could not save the correction (No space left on device); "
                                   "nothing was logged or changed")
    assert ratings.read_bytes() == before and not (lab / "reliability" / "corrections_R4.csv").exists()
