"""The curve editor follows the play head (page mode), never shows negative time, grows with the window;
Enter in any numeric box hands the keyboard back to the video (offscreen, real widgets)."""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

SESSION = "P01_20260112-093000_cardio"
STAGE_SIZE = (1280, 800)
Key = QtCore.Qt.Key
Ctrl = QtCore.Qt.KeyboardModifier.ControlModifier


def _focus() -> QtWidgets.QWidget:
    widget = QtWidgets.QApplication.focusWidget()
    assert widget is not None
    return widget


@pytest.fixture
def editor(stage, lab: Path):
    stage.rater.setText("R1")
    stage.rater.editingFinished.emit()
    ed = stage.open_session(lab / SESSION, "R1")
    assert ed is not None, stage.status.text()
    stage.activateWindow()
    return ed


def _in_view(editor, frame: int) -> bool:
    lo, hi = editor.timeline.curve_plot.viewRange()[0]
    return lo <= editor.session.times.t_at(frame) <= hi


def test_go_to_and_playback_keep_the_cursor_on_screen(qtbot, editor) -> None:
    timeline = editor.timeline
    for _ in range(4):
        QTest.keyClick(_focus(), Key.Key_Plus)  # zoomed in at frame 0: no negative time
    lo, hi = timeline.curve_plot.viewRange()[0]
    assert lo >= 0.0 and hi - lo < 200 and _in_view(editor, 0)
    QTest.keyClick(_focus(), Key.Key_G, Ctrl)
    QTest.keyClicks(_focus(), "400")
    QTest.keyClick(_focus(), Key.Key_Return)
    assert editor.session.frame == 400 and _in_view(editor, 400) and _focus() is editor.video_view
    span = timeline.visible_span_s()
    for _ in range(200):  # stepping on, as playback does: the page turns with the cursor
        QTest.keyClick(_focus(), Key.Key_Right)
        assert _in_view(editor, editor.session.frame)
    assert timeline.visible_span_s() == pytest.approx(span, rel=1e-3)  # pages, not zoom
    QTest.keyClick(_focus(), Key.Key_End)
    assert _in_view(editor, editor.session.n_frames - 1)
    QTest.keyClick(_focus(), Key.Key_Home)
    assert _in_view(editor, 0) and timeline.curve_plot.viewRange()[0][0] >= 0.0


def test_the_weight_box_hands_the_keyboard_back_after_enter(qtbot, editor) -> None:
    box = editor.protocol.number
    box.setFocus()
    box.selectAll()
    QTest.keyClicks(box, "0.35")
    QTest.keyClick(box, Key.Key_Return)
    assert _focus() is editor.video_view
    frame = editor.session.frame
    QTest.keyClick(_focus(), Key.Key_Right)  # Right moves the frame, digits key it
    QTest.keyClick(_focus(), Key.Key_3)
    assert editor.session.frame == frame + 1 and editor.session.key_at().weight == 0.3
    tolerance = editor.accept_tolerance
    tolerance.setFocus()
    QTest.keyClick(tolerance, Key.Key_Escape)
    assert _focus() is editor.video_view


def test_the_curve_editor_grows_with_the_window(qtbot, stage, editor) -> None:
    qtbot.wait(10)
    small = editor.timeline.height()
    stage.resize(1920, 1080)
    qtbot.waitUntil(lambda: editor.timeline.height() > small)
    assert editor.timeline.height() - small >= 0.5 * (1080 - 800) * 2 / 3 - 10


def test_reopening_goes_back_where_the_rater_stopped(qtbot, tmp_path: Path, lab: Path) -> None:
    from effortface.annotate.gui.annotate_stage import QtAnnotateStage

    settings = QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)
    view = QtAnnotateStage(lab, settings=settings, cache_frames=64)
    qtbot.addWidget(view)
    view.resize(*STAGE_SIZE)
    view.show()
    try:
        editor = view.open_session(lab / SESSION, "R2")
        editor.session.set_blendshape("eye_squint")
        editor.session.set_frame(612)
        view.close_session()
        editor = view.open_session(lab / SESSION, "R2")
        assert (editor.session.blendshape, editor.session.frame) == ("eye_squint", 612)
        assert _in_view(editor, 612)
        other = view.open_session(lab / SESSION, "R3")  # another rater starts at the beginning
        assert (other.session.blendshape, other.session.frame) == ("mouth_stretch", 0)
    finally:
        view.shutdown()


def test_preannotate_progress_is_a_bar_with_the_time_left(qtbot, stage) -> None:
    from effortface.annotate.gui.annotate_stage import time_left

    assert time_left(30.0, 0.25) == "about 1 min 30 s left" and time_left(1.0, 0.5).startswith("estimating")
    import time

    stage._pre_started = time.perf_counter() - 20.0  # 20 s into a run, half done
    stage.pre_progress.show()
    stage._show_preannotate_progress(0.5, "P01 frame 476 of 953")
    assert stage.pre_progress.value() == 500
    assert stage.pre_progress.text() in ("50 %, about 20 s left", "50 %, about 21 s left")
    assert stage.status.text() == "pre-annotate: P01 frame 476 of 953"


def test_the_session_list_elides_at_the_end_with_the_whole_line_in_the_tooltip(stage) -> None:
    assert stage.sessions.textElideMode() == QtCore.Qt.TextElideMode.ElideRight
    item = stage.sessions.item(0)
    assert SESSION in item.toolTip() and "R1:" in item.toolTip()


@pytest.mark.parametrize("mode", ["page", "centre"])
def test_the_follow_control_keeps_the_cursor_on_screen_and_is_remembered(qtbot, tmp_path: Path, lab: Path,
                                                                         mode: str) -> None:
    """The Follow combo over the timeline (page | centre | off): both following modes keep the cursor on
    screen through Ctrl+G and stepping; centre keeps it in the middle; the choice is kept in QSettings."""
    from effortface.annotate.gui.annotate_stage import FOLLOW_KEY, QtAnnotateStage

    settings = QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)
    view = QtAnnotateStage(lab, settings=settings, cache_frames=64)
    qtbot.addWidget(view)
    view.resize(*STAGE_SIZE)
    view.show()
    qtbot.waitExposed(view)
    try:
        editor = view.open_session(lab / SESSION, "R1")
        assert editor is not None and editor.follow_box.currentText() == "page"  # the default
        assert editor.follow_box.isVisible() and editor.follow_box.focusPolicy() == QtCore.Qt.FocusPolicy.NoFocus
        editor.follow_box.setCurrentText("off")
        assert settings.value(FOLLOW_KEY) == "off"
        editor.follow_box.setCurrentText(mode)  # as the user picks it (a combo of its own)
        assert editor.timeline.follow == mode and settings.value(FOLLOW_KEY) == mode
        view.activateWindow()
        editor.video_view.setFocus()
        qtbot.waitUntil(lambda: QtWidgets.QApplication.focusWidget() is editor.video_view)
        for _ in range(3):
            QTest.keyClick(_focus(), Key.Key_Plus)
        QTest.keyClick(_focus(), Key.Key_G, Ctrl)
        QTest.keyClicks(_focus(), "400")
        QTest.keyClick(_focus(), Key.Key_Return)
        assert editor.session.frame == 400 and _in_view(editor, 400)
        for _ in range(120):
            QTest.keyClick(_focus(), Key.Key_Right)
            assert _in_view(editor, editor.session.frame)
        lo, hi = editor.timeline.curve_plot.viewRange()[0]
        t = editor.session.times.t_at(editor.session.frame)
        if mode == "centre":
            assert abs(t - (lo + hi) / 2) < 0.02 * (hi - lo)
        assert lo >= 0.0
        view.close_session()
        again = view.open_session(lab / SESSION, "R1")  # reopened: the mode is remembered
        assert again.follow_box.currentText() == mode and again.timeline.follow == mode
    finally:
        view.shutdown()
