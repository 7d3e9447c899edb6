"""The Annotate stage for daily use (issue 16 items 6-9), offscreen with pytest-qt on the sample lab:
undo that names and shows what it undid, completeness in the session list and the Train table,
the expert editing basics, the blind round's unrated state and the reliability report's layout."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from effortface.annotate.gui.annotate_stage import QtAnnotateStage
from effortface.annotate.reliability import read_ratings

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P01_20260112-093000_cardio"
Key = QtCore.Qt.Key
Mod = QtCore.Qt.KeyboardModifier
Left = QtCore.Qt.MouseButton.LeftButton


#: the stage's window size in these tests
STAGE_SIZE = (1280, 800)


def _open(stage: QtAnnotateStage, rater: str):
    stage.rater.setText(rater)
    editor = stage.open_session(stage.sessions_dir / SESSION, rater)
    assert editor is not None, stage.status.text()
    editor.video_view.setFocus()
    return editor


def _press(widget, key, modifier=Mod.NoModifier, times: int = 1) -> None:
    for _ in range(times):
        QTest.keyClick(widget, key, modifier)


# ------------------------------------------------------------------------------------ item 6
def test_undo_after_next_switches_to_and_names_the_undone_blendshape(stage: QtAnnotateStage) -> None:
    editor = _open(stage, "R9")
    m, view = editor.session, editor.video_view
    assert not stage.undo_action.isEnabled() and not stage.redo_action.isEnabled()  # nothing yet
    _press(view, Key.Key_Right, times=12)
    _press(view, Key.Key_6)  # mouth_stretch at frame 12
    assert stage.undo_action.isEnabled() and "mouth_stretch key at frame 12" in stage.undo_action.toolTip()
    assert "set mouth_stretch key at frame 12 to 0.60" in stage.status.text()  # not a stale "0 keys"
    _press(view, Key.Key_N)
    assert m.blendshape == "mouth_open"
    _press(view, Key.Key_Z, Mod.ControlModifier)
    assert m.blendshape == "mouth_stretch" and m.frame == 12 and m.key_at(12) is None
    assert "undid: set mouth_stretch key at frame 12 to 0.60" in stage.status.text()
    assert editor.protocol.shapes.currentRow() == 0 and "mouth_stretch" in editor.timeline.title.toPlainText()
    assert not stage.undo_action.isEnabled() and stage.redo_action.isEnabled()
    # the history view: "(opened)" then the undone step greyed; clicking it redoes it
    assert [editor.history_view.item(i).text() for i in range(editor.history_view.count())] == [
        "(opened)", "set mouth_stretch key at frame 12 to 0.60"]
    assert editor.history_view.currentRow() == 0
    rect = editor.history_view.visualItemRect(editor.history_view.item(1))
    QTest.mouseClick(editor.history_view.viewport(), Left, pos=rect.center())
    assert m.key_at(12).weight == pytest.approx(0.6) and "redid" in stage.status.text()
    assert editor.history_view.currentRow() == 1 and stage.undo_action.isEnabled()


def test_confirming_the_rater_code_clears_the_press_enter_line(qtbot, stage: QtAnnotateStage) -> None:
    _open(stage, "R9")
    stage.rater.clear()
    qtbot.keyClicks(stage.rater, "R9")
    assert "press Enter" in stage.status.text()
    _press(stage.rater, Key.Key_Return)
    assert "press Enter" not in stage.status.text() and "R9" in stage.status.text()


# ------------------------------------------------------------------------------------ item 7
def test_the_session_list_shows_each_raters_complete_tracks(stage: QtAnnotateStage) -> None:
    assert stage.sessions.item(0).text().endswith("R1 4/4  R2 4/4  R3 4/4")
    editor = _open(stage, "R9")
    _press(editor.video_view, Key.Key_5)  # one key: R9 shows, with no complete track
    assert "R9 0/4" in stage.sessions.item(0).text()
    assert "mouth_stretch no key from" in stage.sessions.item(0).toolTip()


def test_the_train_table_shows_the_complete_tracks_column(qtbot) -> None:
    from effortface.train.gui.train_stage import QtTrainStage
    from effortface.train.train_session import TrainSession

    view = QtTrainStage(TrainSession(SAMPLES))
    qtbot.addWidget(view)
    try:
        table = view.picker.table
        col = [table.horizontalHeaderItem(c).text() for c in range(table.columnCount())].index("complete tracks")
        assert table.rowCount() and all(table.item(r, col).text() == "R1 4/4, R2 4/4, R3 4/4"
                                        for r in range(table.rowCount()))
        assert "no gap over 30 s" in table.item(0, col).toolTip()
    finally:
        view.shutdown()
        view.session.wait(30)


# ------------------------------------------------------------------------------------ item 8
def test_select_several_keys_move_scale_copy_a_range(stage: QtAnnotateStage) -> None:
    editor = _open(stage, "R9")
    m, view, tl = editor.session, editor.video_view, editor.timeline
    for frame, digit in ((10, Key.Key_2), (20, Key.Key_4), (30, Key.Key_6)):
        m.set_frame(frame)
        _press(view, digit)
    _press(view, Key.Key_A, Mod.ControlModifier)
    assert tl.selection == [10, 20, 30] and "3 selected" in tl.title.toPlainText()
    _press(view, Key.Key_Right, Mod.AltModifier)  # all three one frame on: one undo step
    assert [k.frame for k in m.track.keys] == [11, 21, 31] and tl.selection == [11, 21, 31]
    _press(view, Key.Key_BracketRight)  # stretched about their mean 0.4
    assert [k.weight for k in m.track.keys] == pytest.approx([0.15, 0.4, 0.65])
    _press(view, Key.Key_C, Mod.ControlModifier)
    assert "copied 3 keys of mouth_stretch (frames 11-31)" in stage.status.text()
    m.set_frame(100)
    _press(view, Key.Key_V, Mod.ControlModifier)
    assert [k.frame for k in m.track.keys][-3:] == [100, 110, 120]
    _press(view, Key.Key_Z, Mod.ControlModifier, times=3)  # paste, scale, move
    assert [(k.frame, k.weight) for k in m.track.keys] == [(10, 0.2), (20, 0.4), (30, 0.6)]
    # Shift+click adds one key to a selection without moving the frame
    tl.set_selection([10])
    pos = tl.mapFromScene(tl.key_point_scene_pos(30))
    QTest.mouseClick(tl.viewport(), Left, Mod.ShiftModifier, pos)
    assert tl.selection == [10, 30]


def test_keyboard_zoom_frame_all_loop_timecode_toggles_splitter(stage: QtAnnotateStage) -> None:
    editor = _open(stage, "R9")
    m, view, tl = editor.session, editor.video_view, editor.timeline
    whole = tl.visible_span_s()
    m.set_frame(500)
    _press(view, Key.Key_Plus)
    assert tl.visible_span_s() == pytest.approx(whole / 1.5, rel=0.02)
    lo, hi = tl.curve_plot.viewRange()[0]
    assert lo < m.t_s < hi  # about the cursor
    _press(view, Key.Key_F)
    assert tl.visible_span_s() == pytest.approx(whole, rel=0.03)
    # the timecode is drawn on the video
    minutes, seconds = divmod(m.t_s, 60)  # the frame's recorded time, h:mm:ss.mmm
    assert editor.video_view.overlay.startswith(f"0:{int(minutes):02d}:{int(seconds):02d}")
    assert editor.video_view.overlay.endswith("frame 500")
    # loop over a selection: reaching its end goes back to its start
    for frame in (100, 140):
        m.set_frame(frame)
        _press(view, Key.Key_5)
    tl.set_selection([100, 140])
    _press(view, Key.Key_L)
    assert editor.loop == (100, 140) and "loop" in editor.loop_label.text()
    editor.set_playing(True)
    assert m.frame == 100
    m.set_frame(140)
    editor._play_from = (m.t_s, time.perf_counter())
    editor._play_tick()
    assert m.frame == 100 and editor.playing
    editor.set_playing(False)
    # coloured curves, each can be hidden
    other = editor.curve_toggles["mouth_open"]
    assert tl.others["mouth_open"].isVisible()
    other.setChecked(False)
    assert not tl.others["mouth_open"].isVisible()
    assert tl.others["eye_squint"].opts["pen"].color().name() != tl.others["brow_lower"].opts["pen"].color().name()
    # the splitter lets the curve editor grow
    before = tl.height()
    editor.splitter.setSizes([200, 600])
    QtWidgets.QApplication.processEvents()
    assert tl.height() > before and tl.height() >= 150


# ------------------------------------------------------------------------------------ item 9
def test_an_unrated_shape_is_never_saved_and_keys_enter_the_ratings(qtbot, stage: QtAnnotateStage,
                                                                     lab: Path) -> None:
    stage.rater.setText("R9")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    pose = panel.round.poses[0].pose_id
    spins = list(panel.spins.values())
    assert all(s.text() == "unrated" for s in spins)
    face_before = panel.face._image
    spins[0].setFocus()
    spins[0].selectAll()
    qtbot.keyClicks(spins[0], "0.4")
    _press(spins[0], Key.Key_Return)  # Enter: next blendshape
    assert spins[1].hasFocus() and spins[0].value() == pytest.approx(0.4)
    assert panel.face._image is not None and panel.face._image != face_before  # the face follows the weights
    qtbot.keyClicks(spins[1], "0.7")
    _press(spins[1], Key.Key_Return)
    panel.save_pose()  # two of four rated
    assert "still unrated (not saved): eye_squint, brow_lower" in panel.status.text()
    saved = {r.blendshape: r.weight for r in read_ratings(lab / "reliability" / "ratings_R9.csv")}
    assert saved == {"mouth_stretch": 0.4, "mouth_open": 0.7}  # no zero for the untouched shapes
    assert panel.poses.currentRow() == 0 and not panel.round.is_done(pose)
    spins[2].setFocus()
    spins[2].selectAll()
    qtbot.keyClicks(spins[2], "0")
    _press(spins[2], Key.Key_Return)
    qtbot.keyClicks(spins[3], "0.1")
    _press(spins[3], Key.Key_Return)  # Enter after the last: saved, the next pose
    assert panel.round.is_done(pose) and panel.poses.currentRow() == 1
    assert all(s.text() == "unrated" for s in spins)


def test_the_report_fits_1280x800(qtbot, stage: QtAnnotateStage) -> None:
    stage.rater.setText("R1")  # R1 finished the round in the sample lab: the report is shown
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    qtbot.waitUntil(lambda: panel.report is not None and panel.per_shape.isVisible())
    QtWidgets.QApplication.processEvents()
    table = panel.per_shape
    header = table.horizontalHeader()
    last = table.columnCount() - 1
    assert table.horizontalHeaderItem(last).text() == "alpha"
    assert header.sectionViewportPosition(last) + header.sectionSize(last) <= table.viewport().width()
    assert header.sectionSize(last) >= 40
    assert panel.pairs.rowCount() == 3 and panel.pairs.item(0, 0).text() == "R1-R2"
    legend = panel.ba_plot.getPlotItem().legend
    lines = [i for i in panel.ba_plot.getPlotItem().items if i.__class__.__name__ == "InfiniteLine"]
    assert lines and legend.zValue() > max(i.zValue() for i in lines) and legend.opts["brush"].color().alpha() > 200
    assert panel.image.height() > 112 or panel.image.width() > 150


def test_moving_keys_at_either_end_of_the_track_refuses_and_says_why(stage: QtAnnotateStage) -> None:
    """Issue 25 item 4: a selection holding the last (or first) frame cannot move past it: nothing
    moves, the status line says which key and why; the keys keep their shape."""
    editor = _open(stage, "R9")
    m, view, tl = editor.session, editor.video_view, editor.timeline
    last = m.n_frames - 1
    for frame in (last - 63, last - 33, last):
        m.set_frame(frame)
        _press(view, Key.Key_5)
    _press(view, Key.Key_A, Mod.ControlModifier)
    _press(view, Key.Key_Right, Mod.AltModifier)
    assert [k.frame for k in m.track.keys] == [last - 63, last - 33, last]
    assert f"found key {last} within 1 frame of the last frame ({last}): nothing moved" in stage.status.text()
    _press(view, Key.Key_Left, Mod.AltModifier)  # the other way every key moves
    assert [k.frame for k in m.track.keys] == [last - 64, last - 34, last - 1]
    for k in list(m.track.keys):
        m.track.delete(k.frame)
    for frame in (0, 30, 63):
        m.set_frame(frame)
        _press(view, Key.Key_5)
    tl.set_selection([0, 30, 63])
    _press(view, Key.Key_Left, Mod.AltModifier)
    assert [k.frame for k in m.track.keys] == [0, 30, 63]
    assert "found key 0 within 1 frame of the first frame (0): nothing moved" in stage.status.text()


def test_the_curve_editor_is_tall_with_small_keys_at_1280x800(qtbot, lab: Path, tmp_path: Path) -> None:
    """Issue 25 item 6: the curve editor was about 110 px tall at 1280x800 and 266 keys hid the curve
    under 11 px dots; it now gets three quarters of the timeline, and dense tracks get smaller dots."""
    from effortface.annotate.gui.timeline import key_size
    from effortface.app import MainWindow

    settings = QtCore.QSettings(str(tmp_path / "s.ini"), QtCore.QSettings.Format.IniFormat)
    win = MainWindow(lab, settings)
    qtbot.addWidget(win)
    win.resize(1280, 800)
    win.show()
    qtbot.waitExposed(win)
    stage = win.show_stage("annotate")
    editor = _open(stage, "R1")
    qtbot.wait(50)
    timeline = editor.timeline
    assert timeline.curve_plot.vb.height() >= 150 > 110
    assert timeline.curve_plot.vb.height() > 2 * timeline.hr_plot.vb.height()
    n = len(editor.session.track.keys)
    assert n > 120 and set(timeline.keys.data["size"]) == {key_size(n)} == {4}  # R1 on P01 cardio: 266 keys (typed)
    assert key_size(10) == 8 and key_size(266) == 4
    win.shutdown()


def test_bland_altman_draws_one_pair_at_a_time(qtbot, stage: QtAnnotateStage) -> None:
    """Issue 25 item 6: the plot overlaid every rater pair under its legend; it now draws the pair
    chosen (the reading rater's pairs by default, a row of the pairs table picks one), all pairs on request."""
    from effortface.annotate.gui.reliability_panel import ALL_PAIRS

    stage.rater.setText("R1")
    stage.tabs.setCurrentIndex(1)
    panel = stage.reliability
    qtbot.waitUntil(lambda: panel.report is not None and panel.per_shape.isVisible())

    def drawn() -> list[str]:
        return [i.name() for i in panel.ba_plot.getPlotItem().listDataItems() if i.name()]

    pairs = [panel.pairs.item(r, 0).text() for r in range(panel.pairs.rowCount())]
    assert len(pairs) == 3 and [panel.ba_pair.itemText(i) for i in range(panel.ba_pair.count())] == [
        ALL_PAIRS, *pairs, "R1's pairs"]
    # by default the pairs of the rater reading the report (issue 36)
    mine = [p for p in pairs if "R1" in p.split("-")]
    assert panel.ba_pair.currentText() == "R1's pairs" and sorted(drawn()) == sorted(mine) and len(mine) == 2
    panel.ba_pair.setCurrentText(pairs[0])
    assert drawn() == [pairs[0]] and pairs[0] in panel.ba_plot.getPlotItem().titleLabel.text
    panel.pairs.setCurrentCell(2, 0)
    assert panel.ba_pair.currentText() == pairs[2] and drawn() == [pairs[2]]
    lines = [i for i in panel.ba_plot.getPlotItem().items if i.__class__.__name__ == "InfiniteLine"]
    assert len(lines) == 3  # that pair's bias and limits only
    panel.ba_pair.setCurrentText(ALL_PAIRS)
    assert sorted(drawn()) == sorted(pairs)
    panel.threshold.setValue(panel.threshold.value() + 1)  # a refreshed report keeps the choice
    assert panel.ba_pair.currentText() == ALL_PAIRS


def test_sync_flashes_and_reps_are_on_the_timeline(qtbot, tmp_path: Path) -> None:
    """Issue 25 item 6: the squats' repetitions and a sync flash logged while recording are drawn on
    the timeline's heart-rate plot (the real P02 strength session, one flash row appended)."""
    from effortface.core.session.folder import read_events

    name = "P02_20260112-113700_strength"
    lab = tmp_path / "lab"
    shutil.copytree(SAMPLES / name, lab / name, ignore=shutil.ignore_patterns("serial", "work.csv"))
    with (lab / name / "events.csv").open("a") as fh:
        fh.write("12.5000,sync,flash,\n")
    widget = QtAnnotateStage(lab, cache_frames=32)
    qtbot.addWidget(widget)
    widget.rater.setText("R9")
    editor = widget.open_session(lab / name, "R9")
    assert editor is not None
    timeline = editor.timeline
    reps = [e.t_s for e in read_events(lab / name / "events.csv") if e.kind == "reps"]
    assert len(reps) == 34 and list(timeline.rep_marks.data["x"]) == reps
    assert [line.value() for line in timeline.sync_lines] == [12.5]
    assert timeline.rep_marks in timeline.hr_plot.items and timeline.sync_lines[0] in timeline.hr_plot.items
    widget.shutdown()


def test_the_session_list_can_be_hidden_for_a_wider_timeline(qtbot, stage: QtAnnotateStage) -> None:
    """Issue 25 item 6: the session list hides (button or Ctrl+B) and the editor takes its width."""
    editor = _open(stage, "R1")
    qtbot.wait(50)
    wide = editor.timeline.width()
    assert stage.side.isVisible()
    qtbot.mouseClick(stage.side_button, Left)
    qtbot.waitUntil(lambda: editor.timeline.width() > wide + 100)
    assert not stage.side.isVisible() and stage.side_button.text().endswith("Sessions")
    _press(editor.video_view, Key.Key_B, Mod.ControlModifier)
    assert stage.side.isVisible()
