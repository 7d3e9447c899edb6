"""Take the Capture stage's screenshots offscreen, with the sample lab's strap replayed on a pseudo-terminal.

    QT_QPA_PLATFORM=offscreen python docs/screenshots/make_capture_screenshots.py

Writes ``capture_<state>_<w>x<h>.png`` (states ``before``, ``during``, ``strap_lost``; sizes 1280x800
and 1920x1080) beside this file. The recording goes to a temporary lab folder (the sample lab is not
touched); the strap is P01's ANT+ serial log, its session video plays as the camera.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from PySide6 import QtCore, QtWidgets  # noqa: E402

from effortface.app import MainWindow  # noqa: E402
from effortface.capture_tool.participants import register  # noqa: E402
from effortface.capture_tool.replay import PtyReplay, load_timed_chunks, start_replay_thread  # noqa: E402
from effortface.capture_tool.session import read_session_info  # noqa: E402

OUT = Path(__file__).resolve().parent
SESSION = ROOT / "sample_sessions" / "P01_20260112-093000_cardio"
SIZES = ((1280, 800), (1920, 1080))
SPEED = 8.0


def _wait(seconds: float, until=lambda: False) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not until():
        QtWidgets.QApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 50)
        time.sleep(0.02)


def _grab(window: MainWindow, state: str) -> None:
    for w, h in SIZES:
        window.resize(w, h)
        _wait(0.6)
        path = OUT / f"capture_{state}_{w}x{h}.png"
        window.grab().save(str(path), "PNG")
        print(path)
    window.resize(*SIZES[0])  # plot labels are laid out at the size they are drawn in: keep the first
    _wait(0.3)


def main() -> int:
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    lab = Path(tempfile.mkdtemp(prefix="effortface-shots-"))
    register(lab / "participants.tsv", read_session_info(SESSION).participant)
    settings = QtCore.QSettings(str(lab / "settings.ini"), QtCore.QSettings.Format.IniFormat)
    window = MainWindow(lab, settings)
    window.resize(*SIZES[0])
    window.show()
    stage = window.show_stage("capture")
    chunks = load_timed_chunks(SESSION / "serial" / "ant.serlog")
    replay = PtyReplay(chunks, speed=SPEED, unplug_after_s=150.0)
    thread = start_replay_thread(replay)
    stage.form.registry.setCurrentText("P01")
    stage.preflight.set_choice(port=replay.path, protocol="ant", video_file=SESSION / "video.avi")
    _wait(15, lambda: stage.settled() and stage.live.hr_label.value.text() != "--")
    _wait(2)
    _grab(window, "before")

    stage.notes.setPlainText("P01 first treadmill session; strap moistened at 09:28")
    stage.toggle_recording()
    _wait(10, lambda: stage.session.recording and stage.settled())
    panel = stage.phases
    panel.request_phase("rest")
    _wait(4)
    panel.pick("treadmill_walk", speed_m_s=1.5, grade_pct=1.0)
    panel.request_exercise()
    _wait(3)
    panel.marker_text.setText("water")
    panel.request_marker()
    _wait(2)
    panel.pick("treadmill_run", speed_m_s=3.4, grade_pct=1.0)
    panel.request_exercise()
    _wait(2)
    panel.pick("treadmill_run", speed_m_s=3.6, grade_pct=1.0)
    panel.request_parameters()
    _wait(2)
    panel.marker_text.setText("side stitch, slowing")
    _grab(window, "during")

    _wait(30, lambda: stage.session.recorder.link.state == "reconnecting")
    _wait(1.5)
    _grab(window, "strap_lost")
    stage.phases.marker_text.clear()
    stage.stop_now()
    replay.stop()
    thread.join(5)
    replay.close()
    window.shutdown()
    window.hide()
    shutil.rmtree(lab, ignore_errors=True)
    app.processEvents()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
