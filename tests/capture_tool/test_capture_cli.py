"""End to end through pseudo-terminals: ``effortface replay`` feeding ``effortface capture`` (both
subprocesses), unplug and replug, and the one-line errors of the capture commands."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
import serial

from effortface.capture_tool.camera import index_video, read_frame
from effortface.capture_tool.replay import PtyReplay
from effortface.core.session.folder import read_session, validate_session

from .capture_helpers import (
    BODY,
    HXM_DAT,
    content,
    decode,
    decode_parts,
    effortface,
    frame_number,
    hxm_chunks,
    make_numbered_video,
    start_replay,
    write_serlog,
)

SPEED = "10"


def _start_capture(port: str, out: Path, *extra: str) -> subprocess.Popen:
    cmd = effortface("capture", "--port", port, "--protocol", "hxm", "--participant", "P01", *BODY,
                     "--out", out, *extra)
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _session_path(proc: subprocess.Popen) -> Path:
    line = proc.stdout.readline().strip()
    assert line, proc.stderr.read()
    return Path(line)


def _rows(path: Path) -> int:
    f = path / "heart_rate.csv"
    return max(0, len(f.read_text().splitlines()) - 1) if f.exists() else 0


def _wait_for(predicate, timeout_s: float = 40.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def _stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> None:
    proc.send_signal(sig)
    assert proc.wait(20) == 0, proc.stderr.read()


def test_replay_to_capture_no_video(tmp_path, shared_data) -> None:
    chunks = hxm_chunks(shared_data, 20, 50)
    expected = decode(chunks)
    replay, pty = start_replay(write_serlog(tmp_path / "excerpt.serlog", chunks), "--speed", SPEED)
    cap = _start_capture(pty, tmp_path / "out", "--no-video")
    path = _session_path(cap)
    _wait_for(lambda: _rows(path) >= len(expected))
    _stop(cap)  # SIGTERM: a clean stop
    assert replay.wait(10) == 0
    s = read_session(path)
    assert content(s.heart_rate) == content(expected)
    assert s.info.complete and validate_session(path) == []
    assert s.participant.sex == "female" and s.devices["heart_rate"]["port"] == pty


def test_replay_raw_capture_to_capture_with_video(tmp_path, shared_data) -> None:
    """The raw .dat with its timing csv, 30 s at 10x, plus a numbered video, stopped by Ctrl-C."""
    expected = decode(hxm_chunks(shared_data, 0, 30))
    video = make_numbered_video(tmp_path / "face.avi", 90)
    replay, pty = start_replay(shared_data / HXM_DAT, "--speed", SPEED, "--unplug-after", "30")
    cap = _start_capture(pty, tmp_path / "out", "--video", video)
    path = _session_path(cap)
    _wait_for(lambda: _rows(path) >= len(expected) and _rows_frames(path) >= 90)
    _stop(cap, signal.SIGINT)
    replay.wait(10)
    s = read_session(path)
    assert content(s.heart_rate[: len(expected)]) == content(expected)
    assert len(s.frame_times_s) == index_video(path / "video.avi") == 90
    assert frame_number(read_frame(path / "video.avi", 63)) == 63
    assert validate_session(path) == []


def _rows_frames(path: Path) -> int:
    f = path / "video_frames.csv"
    return max(0, len(f.read_text().splitlines()) - 1) if f.exists() else 0


def test_unplug_and_replug_keeps_recording(tmp_path, shared_data) -> None:
    first, second = hxm_chunks(shared_data, 0, 20), hxm_chunks(shared_data, 20, 40)
    link = tmp_path / "ttyEF0"
    rp1, pty1 = start_replay(write_serlog(tmp_path / "a.serlog", first), "--speed", SPEED, "--unplug-after", "20")
    os.symlink(pty1, link)
    cap = _start_capture(str(link), tmp_path / "out", "--no-video")
    path = _session_path(cap)
    assert rp1.wait(20) == 0  # pulled out after 20 s of the recording
    _wait_for(lambda: "device_gap" in (path / "events.csv").read_text())
    rp2, pty2 = start_replay(write_serlog(tmp_path / "b.serlog", second), "--speed", SPEED)
    os.symlink(pty2, tmp_path / "new")
    os.replace(tmp_path / "new", link)  # plugged back in: the same path, a new device
    expected = decode_parts([first, second])
    _wait_for(lambda: _rows(path) >= len(expected))
    _stop(cap)
    rp2.wait(10)
    s = read_session(path)
    kinds = [e.kind for e in s.events]
    assert kinds == ["sync", "device_gap", "reconnect", "sync"]
    gap, reconnect = s.events[1], s.events[2]
    assert reconnect.value == str(link)
    # nothing received before the unplug is lost: every row of the first stick comes before the gap
    n_first = len(decode(first))
    assert content(s.heart_rate) == content(expected)
    assert max(h.t_s for h in s.heart_rate[:n_first]) <= gap.t_s < reconnect.t_s <= s.heart_rate[n_first].t_s


@pytest.fixture
def busy_port():
    with PtyReplay([]) as rp, serial.Serial(rp.path, exclusive=True):
        yield rp.path


ERRORS = {
    "unknown protocol": (["capture", "--port", "loop://", "--protocol", "polar", "--participant", "P01", "--no-video"],
                         "--protocol: expected one of ant, ble_hrm, hrmi, hxm, lines, found 'polar'"),
    "missing port": (["capture", "--port", "{tmp}/ttyUSB9", "--protocol", "hxm", "--participant", "P01", "--no-video"],
                     "--port {tmp}/ttyUSB9: expected a serial port, found no such device"),
    "port in use": (["capture", "--port", "{busy}", "--protocol", "hxm", "--participant", "P01", "--no-video"],
                    "--port {busy}: expected a free port, found it in use by another program"),
    "name as code": (["capture", "--port", "loop://", "--protocol", "hxm", "--participant", "Jane Doe", "--no-video"],
                     "expected a capital letter then capitals"),
    "unreadable video": (["capture", "--port", "loop://", "--protocol", "hxm", "--participant", "P01", "--video", "{tmp}/none.avi"],
                         "--video {tmp}/none.avi: expected a video file, found nothing"),
    # OpenCV's own "[ WARN:0@...] can't open camera by index" lines came before ours (issue 16, 14)
    "missing camera": (["capture", "--port", "loop://", "--protocol", "hxm", "--participant", "P01", "--camera", "37"],
                       "--camera 37: expected a camera, found none at that index"),
    "unreadable log": (["replay", "{tmp}/none.serlog"], "{tmp}/none.serlog: expected a readable capture file"),
    "not a capture": (["replay", "{tmp}/notes.xyz"], "expected a .serlog, .pcap or raw"),
    "bad speed": (["replay", "{tmp}/notes.xyz", "--speed", "0"], "--speed: expected a number above 0, found 0"),
    "not a session": (["recover", "{tmp}"], "expected a session.json in the session folder, found none"),
}


@pytest.mark.parametrize("case", list(ERRORS))
def test_user_errors_are_one_line_exit_2(tmp_path, busy_port, case: str) -> None:
    (tmp_path / "notes.xyz").write_text("hello")
    args, message = ERRORS[case]
    fill = {"tmp": tmp_path, "busy": busy_port}
    args = [a.format(**fill) for a in args]
    if case == "bad speed":
        args[1] = str(shared_hxm())
    if args[0] == "capture":
        args += ["--out", str(tmp_path / "out"), *BODY]
    proc = subprocess.run(effortface(*args), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"effortface {args[0]}: error: "), proc.stderr
    assert message.format(**fill) in lines[0]
    assert not (tmp_path / "out").exists()  # nothing created on a failed start


def shared_hxm() -> Path:
    from tests.conftest import SHARED_DATA

    return SHARED_DATA / HXM_DAT


def test_replay_killed_while_waiting_exits_quietly() -> None:
    """issue 16, 14: SIGTERM before any reader claimed "no program opened the port within 60 s"."""
    proc, _ = start_replay(shared_hxm())
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0 and err == "", err


def test_replay_killed_while_playing_exits_quietly() -> None:
    proc, path = start_replay(shared_hxm())
    with serial.Serial(path, timeout=10) as port:
        assert port.read(1)  # playing
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0 and err == "", err


def test_ports_lists_devices() -> None:
    proc = subprocess.run(effortface("ports"), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("serial ports (") and "cameras (" in proc.stdout
    lines = proc.stdout.splitlines()
    if not lines[0].startswith("serial ports (0)"):  # issue 16, 14: the table has column headers
        assert lines[1].split() == ["DEVICE", "DESCRIPTION", "HARDWARE", "ID"], proc.stdout


def test_ports_tables_have_aligned_column_headers() -> None:
    from effortface.capture_tool.commands.ports import CAMERA_COLUMNS, PORT_COLUMNS, table

    lines = table(PORT_COLUMNS, [("/dev/ttyUSB0", "ANT USBStick2", "USB VID:PID=0FCF:1008"),
                                 ("/dev/ttyS0", "n/a", "n/a")])
    assert lines[0] == "  DEVICE        DESCRIPTION    HARDWARE ID"
    assert lines[2] == "  /dev/ttyS0    n/a            n/a"
    assert [line.index(lines[1].split()[1]) for line in lines[1:2]] == [lines[0].index("DESCRIPTION")]
    assert table(CAMERA_COLUMNS, [("/dev/video0", "--camera 0")])[0] == "  DEVICE       OPTION"
    assert table(CAMERA_COLUMNS, []) == []  # no header over an empty table
