"""Crash safety: ``kill -9`` of a running capture loses at most about a second, and
``effortface recover`` finishes the session with exact video seeks."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from effortface.capture_tool.camera import index_video, read_frame
from effortface.core.errors import SessionFormatError
from effortface.core.session.hr_csv import read_hr_csv
from effortface.capture_tool.recorder import decode_serlog, recover_session
from effortface.capture_tool.serlog import read_serlog
from effortface.core.session.folder import read_session, validate_session

from .capture_helpers import BODY, content, effortface, frame_number, hxm_chunks, make_numbered_video, start_replay, write_serlog


def _rows(path: Path) -> int:
    f = path / "heart_rate.csv"
    return max(0, len(f.read_text().splitlines()) - 1) if f.exists() else 0


@pytest.fixture(scope="module")
def killed_session(tmp_path_factory, shared_data) -> dict:
    """A capture (strap at 10x + 30 fps video) killed with SIGKILL mid-recording."""
    tmp = tmp_path_factory.mktemp("kill")
    chunks = hxm_chunks(shared_data, 0, 120)
    video = make_numbered_video(tmp / "face.avi", 600)
    replay, pty = start_replay(write_serlog(tmp / "strap.serlog", chunks), "--speed", "10")
    cap = subprocess.Popen(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P02", *BODY,
                                      "--video", video, "--out", tmp / "out"), stdout=subprocess.PIPE, text=True)
    path = Path(cap.stdout.readline().strip())
    deadline = time.monotonic() + 40
    while _rows(path) < 40:  # about 4 s of recording
        assert time.monotonic() < deadline and cap.poll() is None, "capture did not record"
        time.sleep(0.05)
    os.kill(cap.pid, signal.SIGKILL)
    cap.wait(10)
    replay.send_signal(signal.SIGTERM)
    replay.wait(10)
    on_disk = {
        "hr": read_hr_csv(path / "heart_rate.csv"),
        "frames": (path / "video_frames.csv").read_text().splitlines()[1:],
        "fed": decode_serlog(path / "serial" / "hxm.serlog"),
        "bytes_fed": read_serlog(path / "serial" / "hxm.serlog").data_bytes(),
    }
    return {"path": path, "source": b"".join(d for _, d in chunks), **on_disk}


def test_kill_9_loses_at_most_about_one_second(killed_session) -> None:
    s = killed_session
    assert json.loads((s["path"] / "session.json").read_text())["complete"] is False
    # the raw log holds exactly the bytes the strap sent, in order (nothing buffered in the process)
    assert s["source"].startswith(s["bytes_fed"]) and len(s["bytes_fed"]) > 0
    fed, hr = s["fed"], s["hr"]
    assert content(hr) == content(fed[: len(hr)])  # rows on disk are what was received
    lost = fed[len(hr):]
    if lost:
        assert fed[-1].t_s - lost[0].t_s <= 1.2, f"lost {len(lost)} rows spanning more than a second"
    assert len(s["frames"]) > 0


def test_recover_completes_the_session(killed_session) -> None:
    path = killed_session["path"]
    proc = subprocess.run(effortface("recover", path), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"recovered {path}")
    s = read_session(path)
    assert s.info.complete and validate_session(path) == []
    assert s.info.extra["recovered"]["done"]
    assert content(s.heart_rate) == content(killed_session["fed"])  # every received sample is back
    n = index_video(path / "video.avi")
    assert n == len(s.frame_times_s) > 0
    assert len(killed_session["frames"]) - n <= 30  # video lost to the kill: under a second at 30 fps
    for k in (0, n // 3, n // 2, n - 1):  # seeks land on the frame the table says
        assert frame_number(read_frame(path / "video.avi", k)) == k
    again = subprocess.run(effortface("recover", path), capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "expected an incomplete session, found complete: true" in again.stderr


def test_recover_drops_torn_lines_and_restores_rows(tmp_path, shared_data) -> None:
    """A session cut mid-write, built by hand: torn CSV lines, rows missing, AVI truncated."""
    from effortface.capture_tool.recorder import Recorder
    from effortface.core.session.folder import Participant

    chunks = hxm_chunks(shared_data, 0, 20)
    log = write_serlog(tmp_path / "in.serlog", chunks)
    video = make_numbered_video(tmp_path / "face.avi", 30)
    rec = Recorder(tmp_path / "out", Participant("P06"), f"replay://{log}?speed=40", "hxm", video=video)
    path = rec.start()
    while rec.status().samples < 19 or not rec.camera.ended:
        time.sleep(0.02)
    rec.stop()
    info = json.loads((path / "session.json").read_text())
    info["complete"] = False
    (path / "session.json").write_text(json.dumps(info))
    hr_lines = (path / "heart_rate.csv").read_text().splitlines()
    (path / "heart_rate.csv").write_text("\n".join(hr_lines[:8]) + "\n" + hr_lines[8][:7])  # torn row
    (path / "events.csv").write_text((path / "events.csv").read_text() + "3.2,mar")
    avi = (path / "video.avi").read_bytes()
    (path / "video.avi").write_bytes(avi[: len(avi) // 2])
    note = recover_session(path)
    text = "\n".join(note["done"])
    assert "heart_rate.csv: dropped a torn last line" in text and "restored" in text
    assert "events.csv: dropped a torn last line" in text and "rewrote" in text
    s = read_session(path)
    assert content(s.heart_rate) == content(decode_serlog(path / "serial" / "hxm.serlog"))
    n = index_video(path / "video.avi")
    assert 0 < n == len(s.frame_times_s) < 30
    assert frame_number(read_frame(path / "video.avi", n - 1)) == n - 1
    with pytest.raises(SessionFormatError, match="found complete: true"):
        recover_session(path)
