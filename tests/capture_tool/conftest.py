"""Fixtures the capture stage's GUI tests share (test_capture_gui.py, test_capture_stage_daily.py, and the
lab-stage fixtures of the layout, participant and heart-rate import tests through :func:`capture_stage_on`)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

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


def capture_stage_on(qtbot: Any, lab: Path, settings_file: Path,
                     size: tuple[int, int] = (1280, 800)) -> Iterator[Any]:
    """The Capture stage of a main window on ``lab`` at ``size`` once it has settled (a fixture's body:
    ``yield from``); a recording a failed test left running is stopped, never asked about."""
    from PySide6 import QtCore

    from effortface.app import MainWindow

    win = MainWindow(lab, QtCore.QSettings(str(settings_file), QtCore.QSettings.Format.IniFormat))
    win.resize(*size)
    win.show()
    qtbot.waitExposed(win)
    stage = win.show_stage("capture")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    yield stage
    if stage.session.recording:
        stage.stop_now()
    win.shutdown()
    win.hide()
    win.deleteLater()
