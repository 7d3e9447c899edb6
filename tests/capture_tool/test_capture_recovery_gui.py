"""The Capture stage's recovery bar, offscreen: every incomplete session can be reached, a failed
one is not offered again, and Record / Recover are disabled while a recovery runs."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest
from PySide6 import QtCore

from effortface.core.session.folder import (
    EventWriter,
    Participant,
    SessionInfo,
    create_session,
    read_session_info,
)
from effortface.app import MainWindow
from tests.capture_tool.capture_helpers import hxm_chunks, write_serlog

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")
BROKEN = "P01_20260201-100000"  # sorts first: the one offered first
GOOD = ("P02_20260301-100000", "P03_20260302-100000")


@pytest.fixture
def settings(tmp_path: Path) -> QtCore.QSettings:
    return QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)


def _incomplete(out: Path, session_id: str, shared_data: Path) -> Path:
    """An incomplete session whose heart rate is only in its serial log (it recovers)."""
    info = SessionInfo(session_id, Participant(session_id[:3]), {"heart_rate": {"protocol": "hxm"}})
    folder = create_session(out, info)
    write_serlog(folder / "serial" / "hxm.serlog", hxm_chunks(shared_data, 0.0, 5.0))
    EventWriter(folder / "events.csv").close()
    return folder


def _broken(out: Path) -> Path:
    """An incomplete session whose recovery fails: heart_rate.csv has a wrong header."""
    folder = create_session(out, SessionInfo(BROKEN, Participant("P01"), {"heart_rate": {"protocol": "hxm"}}))
    (folder / "heart_rate.csv").write_text("time,bpm\n1.0,70\n", encoding="utf-8")
    return folder


@pytest.fixture
def lab(tmp_path: Path, shared_data: Path) -> Path:
    out = tmp_path / "sessions"
    _broken(out)
    for session_id in GOOD:
        _incomplete(out, session_id, shared_data)
    return out


@pytest.fixture
def stage(qtbot, lab: Path, settings: QtCore.QSettings):
    win = MainWindow(lab, settings)
    qtbot.addWidget(win)
    capture = win.show_stage("capture")
    qtbot.waitUntil(capture.settled, timeout=10_000)
    yield capture
    capture.shutdown()


def _offered(stage) -> str:
    return Path(stage.recovery_bar.current()).name


def _recover_offered(qtbot, stage) -> None:
    qtbot.mouseClick(stage.recovery_bar.button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: stage.settled() and not stage._busy, timeout=20_000)


def test_failed_recovery_moves_on_to_the_next_session(qtbot, stage, lab) -> None:
    bar = stage.recovery_bar
    assert not bar.isHidden() and _offered(stage) == BROKEN
    before = (lab / BROKEN / "heart_rate.csv").read_bytes()
    _recover_offered(qtbot, stage)
    # the bar moves on and never offers it again; the error names the session and the file
    assert not bar.isHidden() and _offered(stage) == GOOD[0] and BROKEN not in bar.text.text()
    assert "1 could not be recovered" in bar.text.text()
    banner = stage.banner.text()
    assert f"Recovery of {BROKEN} failed" in banner and "heart_rate.csv" in banner and "\n" not in banner
    assert (lab / BROKEN / "heart_rate.csv").read_bytes() == before
    _recover_offered(qtbot, stage)
    assert read_session_info(lab / GOOD[0]).complete and f"Recovered {GOOD[0]}" in stage.banner.text()
    assert _offered(stage) == GOOD[1]
    _recover_offered(qtbot, stage)
    assert read_session_info(lab / GOOD[1]).complete
    assert bar.isHidden() and not read_session_info(lab / BROKEN).complete


def test_next_reaches_every_incomplete_session(qtbot, stage, lab) -> None:
    bar = stage.recovery_bar
    seen = [_offered(stage)]
    for _ in range(3):
        qtbot.mouseClick(bar.next, QtCore.Qt.MouseButton.LeftButton)
        seen.append(_offered(stage))
    assert seen == [BROKEN, *GOOD, BROKEN] and "(2 of 3 incomplete)" not in bar.text.text()
    qtbot.mouseClick(bar.next, QtCore.Qt.MouseButton.LeftButton)
    assert "(2 of 3 incomplete)" in bar.text.text()
    _recover_offered(qtbot, stage)  # the skipped-to session, not the first one
    assert read_session_info(lab / GOOD[0]).complete and not read_session_info(lab / BROKEN).complete
    assert _offered(stage) == GOOD[1]  # then the one after it


def test_record_and_recover_are_disabled_while_recovering(qtbot, stage, lab, monkeypatch) -> None:
    release, started = threading.Event(), threading.Event()
    real = stage.session.recover

    def slow_recover(folder: str) -> dict:
        started.set()
        release.wait(60)
        return real(folder)

    monkeypatch.setattr(stage.session, "recover", slow_recover)
    bar = stage.recovery_bar
    assert stage.record_button.isEnabled() and bar.button.isEnabled() and bar.next.isEnabled()
    qtbot.mouseClick(bar.next, QtCore.Qt.MouseButton.LeftButton)
    qtbot.mouseClick(bar.button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(started.is_set, timeout=10_000)
    assert not stage.record_button.isEnabled() and stage.record_button.text() == "Recovering..."
    assert not bar.button.isEnabled() and not bar.next.isEnabled()
    stage.toggle_recording()  # a hotkey or a stray call does nothing either
    assert not stage.session.recording and not stage.may_close()
    release.set()
    qtbot.waitUntil(lambda: stage.settled() and not stage._busy, timeout=20_000)
    assert read_session_info(lab / GOOD[0]).complete
    assert stage.record_button.isEnabled() and "Record" in stage.record_button.text()
    assert bar.button.isEnabled() and bar.next.isEnabled()
