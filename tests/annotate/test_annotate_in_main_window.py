"""The Annotate stage inside the main window: keyboard focus, session list and playback across stage
switches, and a 1280x800 screen."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from effortface.app import STAGES, MainWindow

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P01_20260112-093000_cardio"
LATER = "P02_20260112-113700_strength"
Key = QtCore.Qt.Key
Left = QtCore.Qt.MouseButton.LeftButton


def _copy_session(name: str, lab: Path) -> None:
    shutil.copytree(SAMPLES / name, lab / name, ignore=shutil.ignore_patterns("serial", "work.csv"))


@pytest.fixture
def window(qtbot, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> MainWindow:
    """The main window on a lab with one sample session, the Annotate stage open for R9."""
    settings_path = tmp_path / "settings.ini"
    monkeypatch.setenv("EFFORTFACE_SETTINGS", str(settings_path))  # never the user's own settings
    lab = tmp_path / "lab"
    _copy_session(SESSION, lab)
    win = MainWindow(lab, QtCore.QSettings(str(settings_path), QtCore.QSettings.Format.IniFormat))
    qtbot.addWidget(win)
    win.resize(1280, 800)
    win.show()
    qtbot.waitExposed(win)
    win.activateWindow()
    yield win
    win.shutdown()


def _click_stage(window: MainWindow, key: str) -> None:
    lst = window.stage_list
    rect = lst.visualItemRect(lst.item(list(STAGES).index(key)))
    QTest.mouseClick(lst.viewport(), Left, pos=rect.center())


def _open(window: MainWindow):
    _click_stage(window, "annotate")
    stage = window.stages["annotate"]
    editor = stage.open_session(window.sessions_dir / SESSION, "R9")
    assert editor is not None, stage.status.text()
    return stage, editor


def _key_to_focus(key) -> None:
    QTest.keyClick(QtWidgets.QApplication.focusWidget(), key)


def test_the_keyboard_reaches_the_editor_after_switching_stages(qtbot, window: MainWindow) -> None:
    stage, editor = _open(window)
    _click_stage(window, "capture")
    _click_stage(window, "annotate")
    assert QtWidgets.QApplication.focusWidget() is editor.video_view
    _key_to_focus(Key.Key_Right)
    _key_to_focus(Key.Key_Down)  # a weight nudge in the editor, not the next stage
    assert editor.session.frame == 1 and window.stage_list.currentRow() == list(STAGES).index("annotate")


def test_a_session_recorded_meanwhile_is_listed_when_annotate_is_shown_again(qtbot, window: MainWindow) -> None:
    stage, _ = _open(window)
    assert stage.sessions.count() == 1
    _click_stage(window, "capture")
    _copy_session(LATER, window.sessions_dir)  # what a recording in Capture leaves behind
    _click_stage(window, "annotate")
    assert [stage.sessions.item(i).text().split()[0] for i in range(stage.sessions.count())] == [SESSION, LATER]
    assert stage.sessions.currentItem().text().startswith(SESSION)  # the open session stays selected


def test_playback_pauses_when_another_stage_is_shown(qtbot, window: MainWindow) -> None:
    _, editor = _open(window)
    _key_to_focus(Key.Key_Space)
    assert editor.playing
    _click_stage(window, "capture")
    assert not editor.playing


def test_annotate_fits_a_1280x800_screen(qtbot, window: MainWindow, tmp_path: Path) -> None:
    stage, editor = _open(window)
    _key_to_focus(Key.Key_5)  # a saved key: the longest status text of the transport row
    assert editor.saved_label.text().startswith("\u2714 all keys saved")
    room = 1280 - window.stage_list.width()
    assert stage.minimumSizeHint().width() <= room
    stage.tabs.setCurrentIndex(1)
    assert stage.minimumSizeHint().width() <= room
    stage.tabs.setCurrentIndex(0)
    window.resize(1280, 800)
    QtWidgets.QApplication.processEvents()
    assert window.width() == 1280
    assert window.grab().save(str(tmp_path / "annotate_1280x800.png"))


def _settle() -> None:
    for _ in range(3):
        QtWidgets.QApplication.processEvents()


def test_the_protocol_panel_fits_1280x800_unscrolled(qtbot, window: MainWindow) -> None:
    """Blendshapes in keying order, Next, Weight, Set key and the weights at this frame, with no scroll
    bar, for every blendshape (two of them have a 'Keying ...' line on two lines)."""
    _, editor = _open(window)
    protocol, scroll = editor.protocol, editor.protocol_scroll
    for name in editor.session.blendshape_names:
        editor.session.set_blendshape(name)
        _settle()
        assert scroll.verticalScrollBar().maximum() == 0, name
        assert protocol.sizeHint().height() <= scroll.viewport().height(), name
        last = protocol.shapes.visualItemRect(protocol.shapes.item(protocol.shapes.count() - 1))
        assert last.bottom() < protocol.shapes.viewport().height(), name  # every blendshape in the list
        assert protocol.readout.geometry().bottom() <= scroll.viewport().height(), name


def test_phase_names_stay_inside_their_bands(qtbot, window: MainWindow) -> None:
    """Short bouts show their name elided (in full in the tooltip); zoomed in, in full."""
    _, editor = _open(window)
    _settle()
    timeline = editor.timeline
    view = timeline.hr_plot.vb

    def overflowing() -> list[str]:
        out = []
        for region, label, text in timeline.phase_labels:
            assert label.toolTip() == text
            right_px = view.mapViewToScene(QtCore.QPointF(region.getRegion()[1], 0)).x()
            if label.isVisible() and label.sceneBoundingRect().right() > right_px:
                out.append(label.textItem.toPlainText())
        return out

    assert len(timeline.phase_labels) == 8 and overflowing() == []
    shown = [label.textItem.toPlainText() for _, label, _ in timeline.phase_labels]
    assert "treadmill" in shown and any(s.endswith("\u2026") for s in shown)  # long bouts in full, short elided
    editor.session.go_to_time(300.0)  # inside the 60 s bout from 270 s
    timeline.zoom(8.0)
    _settle()
    assert overflowing() == []
    assert [label.textItem.toPlainText() for region, label, _ in timeline.phase_labels
            if region.getRegion()[0] == 270.0] == ["treadmill"]


def test_the_reliability_round_fits_1280x800(qtbot, window: MainWindow) -> None:
    """The report's tables need no scroll bar; the pose pictures are 4:3 from the first showing."""
    shutil.copytree(SAMPLES / "reliability", window.sessions_dir / "reliability")
    _click_stage(window, "annotate")
    stage = window.stages["annotate"]
    stage.tabs.setCurrentIndex(1)
    stage.rater.setText("R1")  # R1 finished the sample round: the report is shown
    QTest.keyClick(stage.rater, Key.Key_Return)
    panel = stage.reliability
    qtbot.waitUntil(lambda: panel.report is not None and panel.per_shape.isVisible())
    _settle()
    for table in (panel.per_shape, panel.pairs):
        assert table.horizontalScrollBar().maximum() == 0 and table.verticalScrollBar().maximum() == 0
        assert table.horizontalHeader().length() <= table.viewport().width()
    for picture in (panel.image, panel.face):
        assert abs(picture.height() - max(98, min(round(0.75 * picture.width()), 260))) <= 1


def test_rating_blind_the_pictures_get_the_report_s_room(qtbot, window: MainWindow) -> None:
    shutil.copytree(SAMPLES / "reliability", window.sessions_dir / "reliability")
    _click_stage(window, "annotate")
    stage = window.stages["annotate"]
    stage.tabs.setCurrentIndex(1)
    for rater in ("R1", "R8"):  # the report shown, then a new rater's blind round
        stage.rater.setText(rater)
        QTest.keyClick(stage.rater, Key.Key_Return)
        _settle()
        if rater == "R1":
            with_report = stage.reliability.image.width()
    panel = stage.reliability
    assert panel.report is None and panel.image.width() > 1.3 * with_report
    assert abs(panel.image.height() - min(round(0.75 * panel.image.width()), 260)) <= 1


def test_no_stage_shows_a_widget_before_it_has_a_parent(qtbot, window: MainWindow) -> None:
    """Visit every stage and open a pre-annotated session: nothing opens as a window of its own (such a
    window takes the keyboard from the main window: the machine row did, 797x23)."""
    from tests.annotate.machine_helpers import write_fake_machine
    from tests.annotate.test_machine_keys_gui import _WindowsShown

    write_fake_machine(window.sessions_dir / SESSION)
    spy = _WindowsShown()
    QtWidgets.QApplication.instance().installEventFilter(spy)
    try:
        for key in STAGES:
            _click_stage(window, key)
        stage, editor = _open(window)
    finally:
        QtWidgets.QApplication.instance().removeEventFilter(spy)
    assert editor.machine_row.isVisible() and spy.windows == []
    assert QtWidgets.QApplication.focusWidget() is editor.video_view
    frame = editor.session.frame
    _key_to_focus(Key.Key_Right)
    assert editor.session.frame == frame + 1
