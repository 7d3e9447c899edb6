"""The Capture stage driven offscreen through the real main window (pytest-qt).

A real Zephyr HxM capture is replayed on a pseudo-terminal behind a stable symlink (unplugged and
replugged mid-recording), a generated MJPG file plays as the camera, phases are added by hotkey,
and the session folder written is compared with what was fed in.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from effortface.capture_tool.camera import index_video, read_frame
from effortface.capture_tool.capture_session import CaptureSession, CsvTail, measure_sync, store_sync_result
from effortface.capture_tool.gui.detect import detect_protocol
from effortface.capture_tool.gui.live_view import hr_zones
from effortface.capture_tool.sync import flash_offset_s
from effortface.core.session.hr_csv import read_hr_csv
from effortface.capture_tool.replay import PtyReplay, TimedChunk, start_replay_thread
from effortface.core.session.folder import (
    Event,
    EventWriter,
    Participant,
    SessionInfo,
    create_session,
    read_events,
    read_session,
    read_session_info,
    read_video_frames,
    validate_session,
)
from effortface.app import MainWindow
from tests.capture_tool.capture_helpers import content, frame_number, hxm_chunks, make_numbered_video

#: the offscreen platform warns that it cannot size a top-level window: harmless here
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")
SPEED = 5.0  # replay speed-up: 60 s of the real strap recording plays in 12 s


# --------------------------------------------------------------------------------- fixtures
@pytest.fixture
def camera_file(tmp_path: Path) -> Path:
    """A 25 s numbered MJPG clip at 12 fps (160x120) played as the camera."""
    return make_numbered_video(tmp_path / "camera.avi", n_frames=300, fps=12.0)


def _fill_form(stage, code: str = "P07") -> None:
    form = stage.form
    form.code.setText(code)
    form.sex.setCurrentText("male")
    form.age.setValue(34)
    form.height_m.setValue(1.81)
    form.mass.setValue(77.5)
    form.training_level.setValue(5.0)
    form.hr_rest.setValue(55)
    form.hr_max.setValue(188)


def _record(qtbot, stage) -> Path:
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: stage.session.recording and stage.settled(), timeout=10_000)
    return stage.session.recorder.path


def _stop(qtbot, stage) -> Path:
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not stage.session.recording and stage.settled(), timeout=20_000)
    return stage.session.last_session


def _key(qtbot, window: MainWindow, key: QtCore.Qt.Key) -> None:
    qtbot.keyClick(window.focusWidget() or window, key)


def _repoint(link: Path, target: str) -> None:
    """Point the stable device path at a new pseudo-terminal (a replug)."""
    tmp = link.with_name(link.name + ".new")
    tmp.symlink_to(target)
    os.replace(tmp, link)


def _fed(replay: PtyReplay) -> list[tuple[float, bytes]]:
    """The chunks a replay actually wrote."""
    return [(replay.chunks[i].t_s, replay.chunks[i].data) for _, i in replay.write_times]


def _reference(parts: list[list[tuple[float, bytes]]], protocol: str = "hxm") -> list[tuple]:
    """Decode what was fed as the link does: one decoder, ``finish()`` at each unplug."""
    from effortface.capture_tool.protocols import get_decoder

    decoder = get_decoder(protocol)
    samples = []
    for part in parts:
        for t_s, data in part:
            samples += decoder.feed(data, t_s)
        samples += decoder.finish()
    return content(samples)


# ------------------------------------------------------------------------------ end to end
def test_record_unplug_replug_phases_stop(qtbot, window, tmp_path, shared_data, camera_file) -> None:
    """Record the real HxM strap + a video file, unplug and replug, phases by hotkey, stop."""
    stage = window.stages["capture"]
    chunks = [TimedChunk(t, d) for t, d in hxm_chunks(shared_data, 0.0, 60.0)]
    first = [c for c in chunks if c.t_s < 30.0]
    second = [TimedChunk(c.t_s - 30.0, c.data) for c in chunks if c.t_s >= 30.0]
    link = tmp_path / "ttyEF0"
    replay1 = PtyReplay(first, speed=SPEED, unplug_after_s=first[-1].t_s + 1.0)
    link.symlink_to(replay1.path)
    _fill_form(stage)
    stage.preflight.set_choice(port=str(link), protocol="hxm", video_file=camera_file)
    qtbot.waitUntil(lambda: stage.settled() and not stage.preflight.missing(), timeout=10_000)

    path = _record(qtbot, stage)
    start_replay_thread(replay1)
    _key(qtbot, window, QtCore.Qt.Key.Key_F1)                     # rest
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 5, timeout=10_000)
    stage.phases.pick("treadmill_walk", speed_m_s=1.4)
    _key(qtbot, window, QtCore.Qt.Key.Key_F2)                     # the exercise picked, with its speed
    qtbot.waitUntil(lambda: stage.session.recorder.link.state == "reconnecting", timeout=15_000)
    qtbot.waitUntil(lambda: stage.banner.isVisible() and "Strap lost" in stage.banner.text(), timeout=5_000)
    assert stage.live.hr_label.value.text() == "--"  # no stale heart rate while the strap is gone

    replay2 = PtyReplay(second, speed=SPEED)
    _repoint(link, replay2.path)                                  # replug: same path, new pty
    thread2 = start_replay_thread(replay2)
    qtbot.waitUntil(lambda: stage.session.recorder.link.state == "connected", timeout=10_000)
    stage.phases.pick("treadmill_walk", speed_m_s=1.6, back_kg=10)
    _key(qtbot, window, QtCore.Qt.Key.Key_F7)                     # a speed and load change
    stage.phases.marker_text.setText("water")
    _key(qtbot, window, QtCore.Qt.Key.Key_F6)                     # marker
    _key(qtbot, window, QtCore.Qt.Key.Key_F8)                     # sync flash
    thread2.join(timeout=30)
    _key(qtbot, window, QtCore.Qt.Key.Key_F3)                     # recovery
    qtbot.waitUntil(lambda: not stage.banner.isVisible() or "Strap lost" not in stage.banner.text(),
                    timeout=5_000)
    qtbot.wait(300)
    assert _stop(qtbot, stage) == path
    replay2.close()

    # the session folder is complete and valid
    assert validate_session(path) == []
    session = read_session(path)
    assert session.info.complete
    assert session.participant == Participant("P07", "male", 34, 1.81, 77.5, 5.0, 55, 188)
    # heart rate equals what was fed in, across the unplug
    assert content(session.heart_rate) == _reference([_fed(replay1), _fed(replay2)])
    assert len(session.heart_rate) >= 50
    # events: phases by hotkey, load and speed, marker, sync, gap and reconnect, in time order
    events = [(e.kind, e.label) for e in session.events]
    for expected in [("phase_start", "rest"), ("phase_end", "rest"), ("phase_start", "treadmill_walk"),
                     ("speed", "treadmill_walk"), ("device_gap", "hxm"), ("reconnect", "hxm"),
                     ("load", "back_kg"), ("marker", "water"), ("sync", "flash"), ("phase_end", "treadmill_walk"),
                     ("phase_start", "recovery"), ("phase_end", "recovery")]:
        assert expected in events, expected
    order = [events.index(k) for k in [("phase_start", "rest"), ("phase_start", "treadmill_walk"),
                                         ("device_gap", "hxm"), ("reconnect", "hxm"), ("load", "back_kg")]]
    assert order == sorted(order)
    speeds = [e.value for e in session.events if e.kind == "speed"]
    assert speeds == ["1.4", "1.6"]
    assert [e.t_s for e in session.events] == sorted(e.t_s for e in session.events)
    # video: every frame written has a time, and frame k of the file is frame k of the camera clip
    n_frames = len(session.frame_times_s)
    assert n_frames == index_video(path / "video.avi") > 50
    assert session.info.extra["stats"]["dropped_frames"] == 0
    for k in (0, n_frames // 2, n_frames - 1):
        assert frame_number(read_frame(path / "video.avi", k)) == k
    # the sync test was measured and stored (a video file cannot see the screen flash)
    sync = read_session_info(path).extra["sync"]
    assert len(sync["flashes_t_s"]) == 1 and sync["video_offset_s"] is None
    # what the screen showed is what is on disk
    assert stage.live.n_samples() == sum(s.valid for s in session.heart_rate)
    assert "complete" in stage.session_label.text()


def test_closing_while_recording_asks(qtbot, window, monkeypatch) -> None:
    """Closing during a recording asks; 'No' keeps recording, 'Yes' stops and saves the session."""
    stage = window.stages["capture"]
    _fill_form(stage, "P02")
    stage.preflight.set_choice(port="loop://", protocol="lines")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    asked: list[str] = []
    answers = iter([QtWidgets.QMessageBox.StandardButton.No,     # close? no
                    QtWidgets.QMessageBox.StandardButton.Yes])   # close? yes
    monkeypatch.setattr(QtWidgets.QMessageBox, "question",
                        lambda parent, title, text, *a: (asked.append(title), next(answers))[1])
    path = _record(qtbot, stage)
    assert asked == []  # "No video" chosen on purpose: Record asks nothing
    window.close()
    assert asked[-1] == "Recording in progress"
    assert window.isVisible() and stage.session.recording
    assert read_session_info(path).complete is False
    window.close()
    assert not window.isVisible() and not stage.session.recording
    assert read_session_info(path).complete is True
    assert window.settings.value("main_window/geometry") is not None


def test_full_rate_stream_keeps_gui_responsive(qtbot, window, tmp_path) -> None:
    """A strap flooding the port: decoding and writing stay off the GUI thread, every line is kept."""
    stage = window.stages["capture"]
    n_lines = 150_000  # every 97th line reports no contact (HR 0): kept as valid=0, never 0 bpm
    lines = b"".join(b"%d,%d\n" % (0 if i % 97 == 96 else 60 + i % 90, 400 + i % 600) for i in range(n_lines))
    starts = range(0, len(lines), 4096)
    flood_s = 3.0  # paced over 3 s so the test does not depend on how fast this machine decodes
    replay = PtyReplay([TimedChunk(flood_s * k / len(starts), lines[i:i + 4096]) for k, i in enumerate(starts)],
                       speed=1.0)
    _fill_form(stage, "P03")
    stage.preflight.set_choice(port=replay.path, protocol="lines")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    assert stage.preflight.missing() == []  # "No video" chosen: nothing to ask
    ticks: list[float] = []
    ticker = QtCore.QTimer(interval=10, timeout=lambda: ticks.append(time.monotonic()))
    path = _record(qtbot, stage)
    ticker.start()
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: stage.session.recorder.status().samples >= n_lines, timeout=30_000)
    thread.join(5)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= n_lines - n_lines // 97, timeout=10_000)
    ticker.stop()
    _stop(qtbot, stage)
    replay.close()
    gaps = np.diff(ticks)
    print(f"\n{n_lines} lines: {len(ticks)} GUI ticks, longest GUI stall {gaps.max() * 1000:.0f} ms, "
          f"median tick {np.median(gaps) * 1000:.1f} ms")
    assert len(ticks) > 20  # the GUI event loop kept running (10 ms timer, >= 3 s flood) while it was decoded
    rows = read_hr_csv(path / "heart_rate.csv")
    assert len(rows) == n_lines
    no_contact = [r for r in rows if not r.valid]
    assert len(no_contact) == n_lines // 97 and all(r.hr_bpm is None for r in no_contact)
    assert stage.live.counters.labels["contact_loss"].text() == str(len(no_contact))
    assert stage.live.n_samples() == n_lines - len(no_contact)


def test_detect_button_sets_the_protocol(qtbot, window, shared_data) -> None:
    stage = window.stages["capture"]
    replay = PtyReplay([TimedChunk(t, d) for t, d in hxm_chunks(shared_data, 0.0, 30.0)], speed=15.0)
    stage.preflight.set_choice(port=replay.path, protocol="lines")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    stage.preflight.detect_seconds = 1.2
    thread = start_replay_thread(replay)
    qtbot.mouseClick(stage.preflight.detect_button, QtCore.Qt.MouseButton.LeftButton)
    assert stage.preflight.detect_button.text() == "Listening..."
    qtbot.waitUntil(lambda: stage.preflight.detect_button.isEnabled(), timeout=10_000)
    replay.stop()
    thread.join(5)
    replay.close()
    assert stage.preflight.protocol.currentText() == "hxm"
    assert "detected protocol: hxm" in stage.preflight.strap_status.text()


def test_lost_camera_shows_banner_and_recording_goes_on(qtbot, window, tmp_path, monkeypatch) -> None:
    """A camera that stops delivering frames (here a 2 s file) raises a banner; HR recording continues."""
    asked: list[str] = []
    monkeypatch.setattr(QtWidgets.QMessageBox, "question",  # Stop without a sync test asks (issue 25)
                        lambda parent, title, *a: (asked.append(title), QtWidgets.QMessageBox.StandardButton.Yes)[1])
    stage = window.stages["capture"]
    short = make_numbered_video(tmp_path / "short.avi", n_frames=24, fps=12.0)
    _fill_form(stage, "P04")
    stage.preflight.set_choice(port="loop://", protocol="lines", video_file=short)
    qtbot.waitUntil(lambda: stage.settled() and not stage.preflight.missing(), timeout=10_000)
    path = _record(qtbot, stage)
    qtbot.waitUntil(lambda: "camera stopped" in stage.banner.text() and stage.banner.isVisible(), timeout=10_000)
    assert stage.session.recording
    _key(qtbot, window, QtCore.Qt.Key.Key_F1)
    _stop(qtbot, stage)
    assert asked == ["No sync test"]
    assert ("phase_start", "rest") in [(e.kind, e.label) for e in read_events(path / "events.csv")]
    assert len(read_video_frames(path / "video_frames.csv")) == index_video(path / "video.avi") == 24
    assert window.settings.value("capture/port") == "loop://"
    again = MainWindow(tmp_path / "sessions", window.settings)  # the next start offers the last port
    again_stage = again.stages["capture"]
    qtbot.waitUntil(again_stage.settled, timeout=10_000)
    assert again_stage.preflight.port.currentText() == "loop://"
    again.shutdown()
    again.deleteLater()


def test_contact_loss_shows_banner_and_is_kept_as_invalid_rows(qtbot, window) -> None:
    stage = window.stages["capture"]
    replay = PtyReplay([TimedChunk(0.1 * i, line) for i, line in enumerate([b"HR:72\n"] * 3 + [b"HR:0\n"] * 3)])
    _fill_form(stage, "P08")
    stage.preflight.set_choice(port=replay.path, protocol="lines")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    assert stage.preflight.missing() == []  # "No video" chosen: nothing to ask
    path = _record(qtbot, stage)
    start_replay_thread(replay)
    qtbot.waitUntil(lambda: "No skin contact" in stage.banner.text() and stage.banner.isVisible(), timeout=10_000)
    qtbot.waitUntil(lambda: stage.live.counters.labels["contact_loss"].text() == "3", timeout=5_000)
    assert stage.live.hr_label.value.text() == "--"
    _stop(qtbot, stage)
    replay.close()
    rows = read_hr_csv(path / "heart_rate.csv")
    assert [(r.hr_bpm, r.valid) for r in rows] == [(72.0, True)] * 3 + [(None, False)] * 3


def test_form_validation_shows_message_and_blocks_record(qtbot, window) -> None:
    stage = window.stages["capture"]
    stage.form.code.setText("Jane Doe")
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    assert not stage.session.recording
    assert "participant code" in stage.form.message.text() and "never names" in stage.form.message.text()
    assert stage.banner.isVisible()
    stage.form.code.setText("P01")
    assert "sex, age, height, mass, training level" in stage.form.validate()  # nothing confirmed yet
    _fill_form(stage, "P01")
    stage.form.hr_rest.setValue(100)
    stage.form.hr_max.setValue(100)
    assert "hr_rest_bpm" in stage.form.validate()
    stage.form.hr_max.setValue(180)
    stage.form.label.setText("tread mill")
    assert "session label" in stage.form.validate()
    stage.form.label.setText("treadmill")
    assert stage.form.validate() == ""
    assert stage.form.session_preview.text().startswith("P01_") and stage.form.session_preview.text().endswith("_treadmill")


def test_missing_strap_is_shown_and_start_error_stays_in_window(qtbot, window, tmp_path, monkeypatch) -> None:
    stage = window.stages["capture"]
    _fill_form(stage)
    stage.preflight.set_choice(port=str(tmp_path / "ttyNONE"), protocol="hxm")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    assert stage.preflight.missing() == ["strap"]  # "No video" chosen on purpose is not missing
    assert "no such device" in stage.preflight.strap_status.text()
    asked: list[str] = []
    monkeypatch.setattr(QtWidgets.QMessageBox, "question",
                        lambda parent, title, *a: (asked.append(title), QtWidgets.QMessageBox.StandardButton.Yes)[1])
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(stage.settled, timeout=10_000)
    assert asked == ["Devices not ready"]  # one question; "No video" chosen never asks
    assert not stage.session.recording
    # in the app's words, not the command line's (--port)
    assert stage.banner.text() == (f"Could not start: strap port {tmp_path / 'ttyNONE'}: no such device: the "
                                   "receiver is unplugged, or another port is meant")
    assert stage.record_button.isEnabled() and not (tmp_path / "sessions").exists()


def test_crashed_session_is_offered_for_recovery(qtbot, tmp_path, settings, shared_data) -> None:
    """An incomplete session found at start is offered; Recover finishes it from its serial log."""
    from tests.capture_tool.capture_helpers import write_serlog

    out = tmp_path / "sessions"
    info = SessionInfo("P05_20260101-120000", Participant("P05"), {"heart_rate": {"protocol": "hxm"}})
    folder = create_session(out, info)
    write_serlog(folder / "serial" / "hxm.serlog", hxm_chunks(shared_data, 0.0, 10.0))
    EventWriter(folder / "events.csv").close()
    win = MainWindow(out, settings)
    qtbot.addWidget(win)
    stage = win.show_stage("capture")
    bar = stage.recovery_bar
    assert not bar.isHidden() and "P05_20260101-120000" in bar.text.text()
    qtbot.mouseClick(bar.button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: stage.settled() and bar.isHidden(), timeout=10_000)
    assert read_session_info(folder).complete
    assert len(read_hr_csv(folder / "heart_rate.csv")) >= 5
    assert "Recovered" in stage.banner.text()
    stage.shutdown()


# ------------------------------------------------------------------------------ pure parts
def test_detect_protocol_from_first_bytes(shared_data) -> None:
    hxm = b"".join(d for _, d in hxm_chunks(shared_data, 0.0, 5.0))
    assert detect_protocol(hxm) == "hxm"
    ant = (shared_data / "serial/derived/njcant_hrm1_ant_broadcast.bin").read_bytes()[:13 * 40]
    assert detect_protocol(ant) == "ant"
    assert detect_protocol(b"HR:72\nHR:73\nHR:75\n") == "lines"
    assert detect_protocol(bytes(range(256)) * 4) is None


def test_hr_zones_split_the_reserve() -> None:
    zones = hr_zones(60, 190)
    assert [z[0] for z in zones] == ["Z1", "Z2", "Z3", "Z4", "Z5"]
    assert zones[0][1] == pytest.approx(125.0) and zones[-1][2] == pytest.approx(190.0)
    assert all(a[2] == pytest.approx(b[1]) for a, b in zip(zones, zones[1:]))


def test_csv_tail_returns_only_complete_new_lines(tmp_path) -> None:
    path = tmp_path / "x.csv"
    tail = CsvTail(path)
    assert tail.read_rows() == []
    path.write_text("a,b\n1,2\n3,")
    assert tail.read_rows() == [["1", "2"]]
    with open(path, "a") as fh:
        fh.write('4\n5,"x,y"\n')
    assert tail.read_rows() == [["3", "4"], ["5", "x,y"]]
    assert tail.read_rows() == []


def test_flash_offset_found_in_a_real_video(tmp_path) -> None:
    """A bright frame in a recorded MJPG gives the video-to-HR offset, stored in session.json."""
    import cv2

    out = tmp_path / "sessions"
    folder = create_session(out, SessionInfo("P06_20260101-120000", Participant("P06"), complete=True))
    writer = cv2.VideoWriter(str(folder / "video.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    times = [0.1 * k + 0.013 for k in range(60)]
    for k in range(60):
        writer.write(np.full((48, 64, 3), 230 if 31 <= k <= 33 else 40, np.uint8))
    writer.release()
    (folder / "video_frames.csv").write_text("frame,t_s\n" + "".join(f"{k},{t:.4f}\n" for k, t in enumerate(times)))
    ev = EventWriter(folder / "events.csv")
    ev.write(Event(3.0, "sync", "flash"))
    ev.close()
    assert flash_offset_s(times, [40.0] * 60, 3.0) is None
    result = store_sync_result(folder)
    assert result["video_offset_s"] == pytest.approx(times[31] - 3.0, abs=1e-3)
    assert read_session_info(folder).extra["sync"]["video_offset_s"] == pytest.approx(0.113, abs=1e-3)
    assert measure_sync(folder)["offsets_s"] == [pytest.approx(0.113, abs=1e-3)]
    assert read_video_frames(folder / "video_frames.csv")[31] == pytest.approx(3.113)
    assert read_events(folder / "events.csv")[0].label == "flash"


def test_capture_session_refuses_marks_without_recording(tmp_path) -> None:
    from effortface.core.errors import UserError

    session = CaptureSession(tmp_path)
    with pytest.raises(UserError, match="expected a recording running"):
        session.mark("marker", "x")
    with pytest.raises(UserError, match="Stop: expected a recording running"):
        session.stop()
    assert session.incomplete_sessions() == []
    assert not any(tmp_path.iterdir())


def test_publish_to_lsl_toggle_streams_the_strap(qtbot, window, settings) -> None:
    """The Capture stage's LSL box: a real pylsl inlet receives the strap while it records."""
    import json

    import pylsl

    from effortface.capture_tool.lsl import hr_source_id

    stage = window.stages["capture"]
    replay = PtyReplay([TimedChunk(2.0 + 0.1 * i, f"HR:{70 + i}\n".encode()) for i in range(10)])
    _fill_form(stage, "P09")
    stage.preflight.set_choice(port=replay.path, protocol="lines")
    stage.preflight.camera.setCurrentText("No video")
    qtbot.waitUntil(stage.settled, timeout=10_000)
    stage.preflight.state["camera"] = "ready"
    stage.lsl_box.setChecked(True)
    assert settings.value("capture/lsl", type=bool) is True
    path = _record(qtbot, stage)
    found = pylsl.resolve_byprop("source_id", hr_source_id("lines", replay.path), 1, 10.0)
    assert found and found[0].type() == "HeartRate"
    inlet = pylsl.StreamInlet(found[0], recover=False)
    inlet.open_stream(10)
    start_replay_thread(replay)
    got: list[float] = []
    qtbot.waitUntil(lambda: got.extend(s[0] for s in inlet.pull_chunk(timeout=0.0)[0]) or len(got) >= 10,
                    timeout=15_000)
    _stop(qtbot, stage)
    replay.close()
    assert got == [70.0 + i for i in range(10)]
    assert "clock_offset_s" in json.loads((path / "session.json").read_text())["lsl"]


def test_csv_tail_reads_a_backlog_over_several_calls_losing_no_row(tmp_path) -> None:
    """A burst (a flooding port, a late poll) is read at most TAIL_READ_BYTES a call, so one GUI poll
    never parses all of it; every row arrives once, none torn."""
    from effortface.capture_tool.capture_session import TAIL_READ_BYTES

    path = tmp_path / "hr.csv"
    rows = [[f"{i / 50:.3f}", str(60 + i % 90)] for i in range(40_000)]
    path.write_text("t_s,hr_bpm\n" + "".join(f"{a},{b}\n" for a, b in rows))
    assert path.stat().st_size > 3 * TAIL_READ_BYTES
    tail = CsvTail(path)
    batches = [tail.read_rows()]
    while batches[-1]:
        batches.append(tail.read_rows())
    assert len(batches) > 3 and max(len(b) for b in batches) < len(rows)
    assert [r for b in batches for r in b] == rows
