"""Issue 17: the Capture stage shows a fault (a file that cannot be written) as an error banner
naming the file, above any device warning."""

from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore

from effortface.app import MainWindow
from effortface.capture_tool.gui.capture_stage import _BANNER_STYLE


def test_a_fault_is_an_error_banner_naming_the_file(qtbot, tmp_path: Path) -> None:
    settings = QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)
    win = MainWindow(tmp_path / "sessions", settings)
    qtbot.addWidget(win)
    stage = win.show_stage("capture")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    fault = "/lab/P01_x/serial/hxm.serlog: could not write the serial log (No space left on device)"
    stage._update_banner("failed", camera_ended=True, contact_ok=False, fault=fault)
    assert stage.banner.text().startswith(fault) and stage.banner.styleSheet() == _BANNER_STYLE["error"]
    stage._update_banner("reconnecting", camera_ended=False, contact_ok=True)
    assert stage.banner.text().startswith("Strap lost") and stage.banner.styleSheet() == _BANNER_STYLE["warn"]
