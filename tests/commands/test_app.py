"""The main window: stage switching, screenshots, settings, the global exception hooks."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.core.errors import UserError
from effortface.core.session.folder import Participant, SessionInfo, create_session
import effortface.app as app_module
from effortface.app import STAGES, MainWindow, QtPlaceholderStage, install_exception_hooks, main

ROOT = Path(__file__).resolve().parents[2]

#: the offscreen platform warns that it cannot size a top-level window: harmless here
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


@pytest.fixture
def settings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> QtCore.QSettings:
    path = tmp_path / "settings.ini"
    monkeypatch.setenv("EFFORTFACE_SETTINGS", str(path))  # never touch the user's own settings
    return QtCore.QSettings(str(path), QtCore.QSettings.Format.IniFormat)


@pytest.fixture
def sessions(tmp_path: Path) -> Path:
    """A folder with one complete and one incomplete session."""
    out = tmp_path / "sessions"
    create_session(out, SessionInfo("P01_20260101-100000_cardio", Participant("P01"), complete=True))
    create_session(out, SessionInfo("P02_20260101-110000", Participant("P02"), complete=False))
    return out


def _args(folder: Path, screenshot: Path | None = None, stage: str = "capture") -> argparse.Namespace:
    return argparse.Namespace(dir=str(folder), screenshot=None if screenshot is None else str(screenshot),
                              stage=stage)


@pytest.mark.parametrize("stage", list(STAGES))
def test_screenshot_renders_each_stage(qapp, tmp_path, sessions, settings, stage) -> None:
    out = tmp_path / f"{stage}.png"
    assert main(_args(sessions, out, stage)) == 0
    image = QtGui.QImage(str(out))
    assert image.width() >= 1400 and image.height() >= 900  # a stage may need more than the doc size
    pixels = {image.pixel(x, y) for x in range(0, image.width(), 7) for y in range(0, image.height(), 7)}
    assert len(pixels) > 20  # drawn widgets and text, not a blank image


@pytest.mark.parametrize(("message", "kwargs"), [
    (r"--stage: expected one of capture, annotate, train, synthesize, found 'paint'", {"stage": "paint"}),
    (r"--screenshot .*shot\.jpg: expected a path ending in \.png, found '\.jpg'", {"screenshot": "shot.jpg"}),
    (r"--screenshot .*old\.png: expected a new file, found one exists", {"screenshot": "old.png"}),
    (r"--screenshot .*nowhere/x\.png: expected an existing folder for the PNG, found nothing",
     {"screenshot": "nowhere/x.png"}),
    (r"DIR: expected a folder of sessions, found a file '.*old\.png'", {"dir": "old.png"}),
])
def test_bad_options_are_user_errors(qapp, tmp_path, settings, message, kwargs) -> None:
    (tmp_path / "old.png").write_bytes(b"png")
    args = _args(tmp_path)
    for key, value in kwargs.items():
        setattr(args, key, str(tmp_path / value) if key in ("screenshot", "dir") else value)
    with pytest.raises(UserError, match=message):
        main(args)
    assert (tmp_path / "old.png").read_bytes() == b"png"  # never overwritten


def test_no_display_is_a_user_error(qapp, tmp_path, monkeypatch) -> None:
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(UserError, match=r"display: expected \$DISPLAY .* found neither \(use --screenshot"):
        main(_args(tmp_path))


def test_command_line_screenshot_and_error(tmp_path, sessions) -> None:
    """``effortface app DIR --screenshot`` as users run it: a PNG, or one error line and status 2."""
    env = {"EFFORTFACE_SETTINGS": str(tmp_path / "s.ini"), "QT_QPA_PLATFORM": "offscreen", "PATH": "/usr/bin:/bin"}
    out = tmp_path / "annotate.png"
    cmd = [sys.executable, "-m", "effortface", "app", str(sessions), "--screenshot", str(out)]
    done = subprocess.run(cmd + ["--stage", "annotate"], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert out.stat().st_size > 10_000 and done.stdout.strip() == str(out)
    bad = subprocess.run(cmd + ["--stage", "paint"], capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "effortface app: error: --stage: expected one of capture, annotate, train, synthesize, found 'paint'"]


def test_stage_list_switches_and_placeholders_list_sessions(qtbot, sessions, settings, monkeypatch) -> None:
    """A stage whose code cannot load shows why and lists the sessions; the others still work."""
    real = app_module.make_stage

    def make_stage(key, sessions_dir, settings_):
        if key == "annotate":
            raise ImportError("No module named 'effortface.annotate.gui.annotate_stage'")
        return real(key, sessions_dir, settings_)

    monkeypatch.setattr(app_module, "make_stage", make_stage)
    window = MainWindow(sessions, settings)
    qtbot.addWidget(window)
    assert set(window.stages) == {"capture"}  # the others are built when first shown
    assert window.stack.currentWidget().layout().itemAt(0).widget() is window.stages["capture"]
    window.stage_list.setCurrentRow(1)
    annotate = window.stages["annotate"]
    assert isinstance(annotate, QtPlaceholderStage) and annotate.isVisibleTo(window)
    assert "No module named" in annotate.findChild(QtWidgets.QLabel).text()
    rows = [annotate.sessions.item(i).text() for i in range(annotate.sessions.count())]
    assert rows[0].startswith("P01_20260101-100000_cardio") and rows[0].endswith("complete")
    assert rows[1].startswith("P02_20260101-110000") and "INCOMPLETE" in rows[1]
    assert window.show_stage("capture") is window.stages["capture"]
    assert window.stage_list.currentRow() == 0
    with pytest.raises(UserError, match="--stage: expected one of"):
        window.show_stage("nope")
    # the capture stage offers the incomplete session for recovery at start
    assert not window.stages["capture"].recovery_bar.isHidden()
    window.shutdown()


def test_window_geometry_is_remembered(qtbot, tmp_path, settings) -> None:
    window = MainWindow(tmp_path, settings)
    qtbot.addWidget(window)
    window.show()
    window.resize(1200, 760)
    qtbot.waitUntil(lambda: window.size() == QtCore.QSize(1200, 760))
    window.close()
    again = MainWindow(tmp_path, QtCore.QSettings(settings.fileName(), QtCore.QSettings.Format.IniFormat))
    qtbot.addWidget(again)
    # the offscreen screen is 800 px wide, so restoreGeometry clamps the width; the height is kept
    fresh = MainWindow(tmp_path, QtCore.QSettings(str(tmp_path / "fresh.ini"), QtCore.QSettings.Format.IniFormat))
    qtbot.addWidget(fresh)
    assert again.height() == 760 != fresh.height()
    again.shutdown()
    fresh.shutdown()


def test_exception_hooks_log_and_report_from_any_thread(qtbot, caplog) -> None:
    shown: list[tuple[str, str]] = []
    old_hooks = (sys.excepthook, threading.excepthook)
    restore = install_exception_hooks(show=lambda summary, details: shown.append((summary, details)))
    try:
        worker = threading.Thread(target=lambda: 1 / 0, name="camera-writer")
        worker.start()
        worker.join()
        qtbot.waitUntil(lambda: len(shown) == 1)
        assert shown[0][0] == "Unexpected error in thread 'camera-writer': ZeroDivisionError: division by zero"
        assert "Traceback" in shown[0][1]
        try:
            raise RuntimeError("boom")
        except RuntimeError:
            sys.excepthook(*sys.exc_info())
        qtbot.waitUntil(lambda: len(shown) == 2)
        assert shown[1][0] == "Unexpected error in the application: RuntimeError: boom"
        assert any("boom" in r.getMessage() for r in caplog.records if r.name == "effortface.app")
    finally:
        restore()
    assert (sys.excepthook, threading.excepthook) == old_hooks


def test_window_is_safe_from_the_pyside_reference_leak(qtbot, tmp_path, settings) -> None:
    """PySide6-Essentials 6.12.0 on CPython 3.11 drops a reference to None on every void call and
    to True on every ``Signal.emit``: a window redrawing for minutes would abort with "Fatal Python
    error: none_dealloc". Either this PySide6 does not leak, or the main window neutralised it."""
    import PySide6

    window = MainWindow(tmp_path, settings)
    qtbot.addWidget(window)
    label, source = QtWidgets.QLabel(), _Emitter()
    none_before, true_before = sys.getrefcount(None), sys.getrefcount(True)
    for _ in range(200):
        label.setText("x")
        source.ping.emit()
    leaks = none_before - sys.getrefcount(None) >= 100 or true_before - sys.getrefcount(True) >= 100
    guarded = min(sys.getrefcount(None), sys.getrefcount(True)) > 1 << 30
    assert not leaks or guarded, f"PySide6 {PySide6.__version__} leaks references and no guard is on"
    window.shutdown()


class _Emitter(QtCore.QObject):
    ping = QtCore.Signal()


def test_without_dir_outside_the_repo_the_app_writes_only_into_the_users_copy(qtbot, tmp_path, settings,
                                                                              monkeypatch) -> None:
    """``effortface app`` with no DIR, from a folder without ``sample_sessions``: the window opens on
    the user's copy of the sample lab in the user data folder, names it, and key-frames saved there
    leave the checkout (or site-packages) untouched."""
    from effortface.annotate.annotate_session import AnnotateSession
    from effortface.samplelab import repo_lab

    work, data = tmp_path / "work", tmp_path / "data"
    work.mkdir()
    monkeypatch.setenv("EFFORTFACE_DATA_DIR", str(data))
    env = {**os.environ, "EFFORTFACE_SETTINGS": str(tmp_path / "s.ini"), "QT_QPA_PLATFORM": "offscreen"}
    shot = tmp_path / "annotate.png"
    done = subprocess.run([sys.executable, "-m", "effortface", "app", "--screenshot", str(shot), "--stage",
                           "annotate"], capture_output=True, text=True, cwd=work, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    copy = data / "sample_sessions"
    assert f"copying the sample lab from {repo_lab()} into {copy}" in done.stderr
    assert shot.is_file() and list(work.iterdir()) == []  # nothing written where it was run
    window = MainWindow(copy, settings)
    qtbot.addWidget(window)
    assert window.folder_label.text() == (f"Recordings and key-frames are saved in {copy.resolve()} "
                                          "(your copy of the sample lab, in the user data folder)")
    assert MainWindow(tmp_path, settings).folder_label.text() == f"Recordings and key-frames are saved in {tmp_path}"
    session = sorted(p for p in copy.iterdir() if (p / "session.json").is_file())[0]
    AnnotateSession(session, "R7").set_key(0.5, frame=3)
    assert (session / "annotations" / "R7.json").is_file()
    assert not (repo_lab() / session.name / "annotations" / "R7.json").exists()
