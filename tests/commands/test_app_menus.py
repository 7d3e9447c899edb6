"""The main window's menu bar, status bar, Ctrl+1..4, and remembered geometry and splitters (issue 16, 13)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets
from PySide6.QtTest import QTest

from effortface import __version__
from effortface.app import STAGES, MainWindow
from effortface.core.docs import DESIGN, SCIENCE, doc_path

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")

ROOT = Path(__file__).resolve().parents[2]
SESSION = "P01_20260112-093000_cardio"
Ctrl = QtCore.Qt.KeyboardModifier.ControlModifier


def _settings(path: Path) -> QtCore.QSettings:
    return QtCore.QSettings(str(path), QtCore.QSettings.Format.IniFormat)


@pytest.fixture
def settings_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path / "settings.ini"
    monkeypatch.setenv("EFFORTFACE_SETTINGS", str(path))  # never the user's own settings
    return path


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    lab = tmp_path / "lab"
    shutil.copytree(ROOT / "sample_sessions" / SESSION, lab / SESSION,
                    ignore=shutil.ignore_patterns("serial", "work.csv"))
    return lab


def _window(qtbot, lab: Path, settings_path: Path) -> MainWindow:
    win = MainWindow(lab, _settings(settings_path))
    qtbot.addWidget(win)
    win.show()
    qtbot.waitExposed(win)
    win.activateWindow()
    qtbot.waitUntil(win.isActiveWindow)  # window shortcuts need the active window
    return win


def _menu(window: MainWindow, title: str) -> QtWidgets.QMenu:
    return next(a.menu() for a in window.menuBar().actions() if a.text().replace("&", "") == title)


def test_menu_bar_has_file_edit_view_help(qtbot, lab, settings_path) -> None:
    window = _window(qtbot, lab, settings_path)
    assert [a.text().replace("&", "") for a in window.menuBar().actions()] == ["File", "Edit", "View", "Help"]
    assert [a.text() for a in _menu(window, "View").actions()] == list(STAGES.values())
    helps = [a.text().replace("&", "") for a in _menu(window, "Help").actions() if a.text()]
    assert helps[0] == "Keyboard map" and helps[-1] == "About effortface"
    assert any(DESIGN in h for h in helps) and any(SCIENCE in h for h in helps)
    window.shutdown()


def test_ctrl_1_to_4_switch_stages(qtbot, lab, settings_path) -> None:
    window = _window(qtbot, lab, settings_path)
    for row in (3, 1, 2, 0):  # Synthesize, Annotate, Train, Capture
        QTest.keyClick(QtWidgets.QApplication.focusWidget() or window, QtCore.Qt.Key(QtCore.Qt.Key.Key_1 + row),
                       Ctrl)
        key = list(STAGES)[row]
        assert window.stage_list.currentRow() == row and window.stack.currentIndex() == row
        assert window.stages[key].isVisibleTo(window)
        assert window.stage_label.text().startswith(STAGES[key])  # the status bar names the stage
        assert [a.isChecked() for a in window.stage_actions.values()] == [i == row for i in range(4)]
    window.shutdown()


def test_edit_menu_undo_and_redo_call_the_annotate_model(qtbot, lab, settings_path) -> None:
    window = _window(qtbot, lab, settings_path)
    window.undo()  # Capture has no undo: a status message, nothing else
    assert "nothing to undo here" in window.statusBar().currentMessage()
    window.show_stage("annotate")
    stage = window.stages["annotate"]
    editor = stage.open_session(lab / SESSION, "R9")
    assert editor is not None, stage.status.text()
    model = editor.session
    assert window.undo_target() is model
    window.edit_menu.aboutToShow.emit()
    assert not window.undo_action.isEnabled() and not window.redo_action.isEnabled()
    model.set_frame(5)
    model.set_key(0.7)
    keys = model.track.keys
    assert len(keys) == 1
    window.edit_menu.aboutToShow.emit()
    assert window.undo_action.isEnabled()
    window.undo_action.trigger()  # the menu's Undo
    assert model.track.keys == () and model.can_redo
    assert window.redo_action.isEnabled()
    window.redo_action.trigger()
    assert model.track.keys == keys and not window.redo_action.isEnabled()
    window.shutdown()


def test_geometry_and_splitters_restored_from_settings(qtbot, lab, settings_path) -> None:
    window = _window(qtbot, lab, settings_path)
    window.resize(1200, 760)
    qtbot.waitUntil(lambda: window.size() == QtCore.QSize(1200, 760))
    window.show_stage("train")
    # the Train stage's second splitter (plots beside the run log): the first is held by its panes' minima
    splitter = window.stages["train"].findChildren(QtWidgets.QSplitter)[1]
    assert splitter is not None
    total = sum(splitter.sizes())
    splitter.setSizes([total // 5, total - total // 5])
    saved = splitter.sizes()
    window.close()
    again = _window(qtbot, lab, settings_path)
    # the offscreen screen is 800 px wide, so restoreGeometry clamps the width; the height is kept
    assert again.height() == 760
    again.resize(1200, 760)  # as wide as when saved, so the splitter gets the same room
    qtbot.waitUntil(lambda: again.size() == QtCore.QSize(1200, 760))
    again.show_stage("train")
    assert again.stages["train"].findChildren(QtWidgets.QSplitter)[1].sizes() == saved
    fresh = _window(qtbot, lab, settings_path.with_name("fresh.ini"))
    fresh.resize(1200, 760)
    qtbot.waitUntil(lambda: fresh.size() == QtCore.QSize(1200, 760))
    fresh.show_stage("train")
    assert fresh.stages["train"].findChildren(QtWidgets.QSplitter)[1].sizes() != saved
    again.shutdown()
    fresh.shutdown()


def test_keyboard_map_and_about(qtbot, lab, settings_path) -> None:
    window = _window(qtbot, lab, settings_path)
    keys = window.show_keyboard_map()
    text = keys.text()
    for expected in ("Ctrl+1 .. Ctrl+4", "F1", "phase: Rest", "F8", "sync test", "Ctrl+Z / Ctrl+Y", "Space"):
        assert expected in text, expected
    keys.close()
    about = window.show_about()
    assert f"effortface {__version__}" in about.text()
    assert str(doc_path(DESIGN)) in about.text() and doc_path(DESIGN).is_file()
    about.close()
    window.shutdown()


def test_open_lab_folder_reopens_the_stages(qtbot, lab, settings_path, tmp_path) -> None:
    window = _window(qtbot, lab, settings_path)
    window.show_stage("annotate")
    old = window.stages["annotate"]
    other = tmp_path / "other"
    other.mkdir()
    assert window.open_folder(other)
    assert window.sessions_dir == other and str(other) in window.windowTitle()
    assert window.stages["annotate"] is not old and window.current_key() == "annotate"
    assert str(other.resolve()) in window.folder_label.text()
    window.shutdown()
