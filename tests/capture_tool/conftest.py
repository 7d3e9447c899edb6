"""Fixtures the capture stage's GUI tests share (test_capture_gui.py, test_capture_stage_daily.py)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def settings(tmp_path: Path):
    """The application's QSettings in a file of the test's own (nothing of the user's is read)."""
    from PySide6 import QtCore

    return QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)


@pytest.fixture
def window(qtbot, tmp_path: Path, settings):
    """The main window on an empty lab folder, showing the Capture stage once it has settled."""
    from effortface.app import MainWindow

    win = MainWindow(tmp_path / "sessions", settings)
    win.show()
    qtbot.waitExposed(win)
    win.activateWindow()
    stage = win.show_stage("capture")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    yield win
    # stopped here, never asked: a test that failed mid-recording must not leave a question open
    if stage.session.recording:
        stage.stop_now()
    win.shutdown()
    win.hide()
    win.deleteLater()
