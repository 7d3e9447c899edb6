"""Issue 17, capture side: nothing lost, every fault said plainly.

Case 1: a video write that fails (file-size limit, full disk) is seen, said in one line naming the
file, and never ends in a "complete" session whose video does not match its frame table. Case 2: a
serial log that cannot be written stops heart-rate recording plainly (not a device gap). Case 4: a
recording holds a lock that recover, the stages' lists, Annotate and Train respect. Case 7:
recover repairs NUL blocks and a damaged heart_rate.csv, and reads back what it wrote. Case 12:
leftover temporary files, folder fsync, files named in disk-full errors, a port with no valid
sample, the startup write after a reopen.
"""

from __future__ import annotations

import errno
import json
import os
import queue
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import serial

from effortface.capture_tool import serial_link
from effortface.capture_tool.camera import index_video
from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.recorder import DAMAGED_HR_CSV, Recorder, decode_serlog, recover_session
from effortface.capture_tool.replay import PtyReplay, TimedChunk, start_replay_thread
from effortface.capture_tool.serial_link import SerialLink
from effortface.capture_tool.serlog import read_serlog
from effortface.core.session.folder import (
    RECORDING_LOCK,
    Participant,
    list_sessions,
    read_events,
    read_session,
    read_session_info,
    recording_owner,
    validate_session,
)
from effortface.core import fileio
from effortface.core.errors import SessionFormatError
from effortface.core.locks import LockedError, acquire_lock, lock_owner

from .capture_helpers import BODY, content, effortface, hxm_chunks, make_numbered_video, start_replay, write_serlog
from .test_recover_partial import _crashed_session

SPEED = "10"
ROOT = Path(__file__).resolve().parents[2]


def _wait_for(predicate, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def _capture(port: str, out: Path, *extra: str, fsize_limit: int | None = None) -> subprocess.Popen:
    """``effortface capture`` as a subprocess, optionally under a file-size limit (RLIMIT_FSIZE)."""
    def limit() -> None:
        if fsize_limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize_limit, fsize_limit))

    cmd = effortface("capture", "--port", port, "--protocol", "hxm", "--participant", "P01", *BODY, "--out", out, *extra)
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace",
                            preexec_fn=limit, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def _hr_matches_serlog(path: Path) -> None:
    """Every heart-rate row is exactly what the session's serial log decodes to: nothing lost."""
    (log,) = sorted((path / "serial").glob("*.serlog"))
    assert content(read_session(path).heart_rate) == content(decode_serlog(log))


def _noise_video(path: Path, n_frames: int, fps: float = 30.0) -> Path:
    """An MJPG AVI of random 640 x 480 frames (about 0.3 MB each once encoded: fills a disk fast)."""
    import cv2

    rng = np.random.default_rng(0)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (640, 480))
    for _ in range(n_frames):
        writer.write(rng.integers(0, 255, (480, 640, 3), dtype=np.uint8))
    writer.release()
    return path


@pytest.fixture
def small_disk(tmp_path: Path):
    """A real 8 MiB file system (tmpfs) the test can fill; skipped where mounting is not allowed."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mnt)], capture_output=True)
    if proc.returncode != 0:
        pytest.skip("cannot mount a small tmpfs here (needs root); the file-size-limit tests cover the rest")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(folder: Path) -> Path:
    """Fill the file system of ``folder`` to the last byte; return the filler file."""
    filler = folder / "filler.bin"
    with open(filler, "wb", buffering=0) as fh:
        for size in (1 << 20, 1 << 16, 1 << 12, 1 << 8, 1):
            try:
                while True:
                    fh.write(b"\0" * size)
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
    return filler


# ------------------------------------------------------------------------------ case 1: video
def test_a_file_size_limit_stops_the_video_cleanly_and_says_so(tmp_path, shared_data) -> None:
    replay, pty = start_replay(write_serlog(tmp_path / "in.serlog", hxm_chunks(shared_data, 0, 60)),
                               "--speed", SPEED)
    video = make_numbered_video(tmp_path / "in.avi", 240, fps=60.0)
    proc = _capture(pty, tmp_path / "out", "--video", video, "--duration", "6", fsize_limit=250_000)
    out, err = proc.communicate(timeout=120)
    replay.terminate()
    replay.wait(10)
    path = Path(out.splitlines()[0])
    assert proc.returncode == 2 and "Traceback" not in err, err
    fault = [line for line in err.splitlines() if line.startswith("capture: ")]
    assert len(fault) == 1 and str(path / "video.avi") in fault[0] and "file-size limit" in fault[0], err
    info = read_session_info(path)
    assert info.complete and info.extra["faults"] == [fault[0].removeprefix("capture: ")]
    assert validate_session(path) == []  # the video stopped between frames: it matches its table
    n = index_video(path / "video.avi")
    assert 0 < n == len(read_session(path).frame_times_s) < 240
    assert info.extra["stats"]["dropped_frames"] > 0
    gaps = [e for e in read_events(path / "events.csv") if e.kind == "device_gap"]
    assert [e.label for e in gaps] == ["camera"] and "file-size limit" in gaps[0].value
    _hr_matches_serlog(path)


_FAILING_WRITES = """
import json, resource, sys, time
from effortface.capture_tool import camera
camera.CameraSource._room_problem = lambda self: None  # as before issue 17: nothing stops it in time
from effortface.capture_tool.recorder import Recorder
from effortface.core.session.folder import Participant
resource.setrlimit(resource.RLIMIT_FSIZE, (150_000, 150_000))
rec = Recorder(sys.argv[1], Participant("P01"), "loop://", "lines", video=sys.argv[2])
path = rec.start()
rec.camera.wait_ended(60)
rec.stop()
print(json.dumps({"path": str(path), "faults": rec.faults, "frames": rec.camera.frames_written}))
"""


def test_failed_video_writes_are_seen_and_recover_repairs_the_session(tmp_path) -> None:
    video = make_numbered_video(tmp_path / "in.avi", 240, fps=60.0)
    proc = subprocess.run([sys.executable, "-c", _FAILING_WRITES, str(tmp_path / "out"), str(video)],
                          capture_output=True, text=True, errors="replace", timeout=120)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    path = Path(got["path"])
    # issue 29: the AVI writer raises on a failed write (no more silent OpenCV failures): named, one line
    assert any(f.startswith(str(path / "video.avi")) and "could not write" in f for f in got["faults"]), got
    info = read_session_info(path)
    assert not info.complete and info.extra["faults"] == got["faults"]  # never "complete" with a broken video
    assert any("complete is false" in p for p in validate_session(path))
    assert index_video(path / "video.avi") == len(read_session(path).frame_times_s)  # every logged frame decodes
    note = recover_session(path)
    assert any("rewrote" in line or "trimmed" in line for line in note["done"]), note
    assert validate_session(path) == [] and 0 < index_video(path / "video.avi") == len(read_session(path).frame_times_s)


def test_validation_and_recover_on_a_complete_session_whose_video_is_short(tmp_path) -> None:
    """A session an older capture marked complete over a broken video: validation says so, recover repairs it."""
    src = ROOT / "sample_sessions" / "P01_20260112-093000_cardio"
    path = Path(shutil.copytree(src, tmp_path / src.name))
    avi = path / "video.avi"
    avi.write_bytes(avi.read_bytes()[: avi.stat().st_size // 2])
    problems = validate_session(path)
    assert len(problems) == 1 and "video_frames.csv: lists" in problems[0] and "that decode in video.avi" in problems[0]
    note = recover_session(path)
    assert note["done"][0].startswith("session.json: was marked complete, but")
    assert validate_session(path) == []
    with pytest.raises(SessionFormatError, match="expected an incomplete session, found complete: true"):
        recover_session(path)  # a sound complete session is still refused


def test_a_full_disk_degrades_then_stops_plainly_and_recover_finishes(tmp_path, shared_data, small_disk) -> None:
    """Cases 1 and 2 on a real full disk: the video stops first (the heart rate goes on), then the
    serial log cannot be written: one line naming it, the capture stops, nothing written is lost."""
    replay, pty = start_replay(write_serlog(tmp_path / "in.serlog", hxm_chunks(shared_data, 0, 120)),
                               "--speed", SPEED)
    proc = _capture(pty, small_disk, "--video", _noise_video(tmp_path / "noise.avi", 90), "--duration", "60")
    path = Path(proc.stdout.readline().strip())
    events = path / "events.csv"
    _wait_for(lambda: "device_gap,camera" in events.read_text())
    rows_at_gap = len((path / "heart_rate.csv").read_text().splitlines())
    _wait_for(lambda: len((path / "heart_rate.csv").read_text().splitlines()) > rows_at_gap + 3)  # HR goes on
    filler = _fill(small_disk)
    out, err = proc.communicate(timeout=60)
    replay.terminate()
    replay.wait(10)
    assert proc.returncode == 2 and "Traceback" not in err and "reconnecting" not in err, err
    faults = [line for line in err.splitlines() if line.startswith("capture: ")]
    assert "disk is full" in faults[0] and str(path / "video.avi") in faults[0], err
    assert any(str(path / "serial" / "hxm.serlog") + ": could not write the serial log (No space left on device)"
               in f for f in faults), err
    assert "INCOMPLETE" in err and read_session_info(path).complete is False
    kept = read_session(path).heart_rate
    log = decode_serlog(path / "serial" / "hxm.serlog")
    assert content(kept) == content(log)[: len(kept)]  # everything written before is kept
    filler.unlink()
    rec = subprocess.run(effortface("recover", path), capture_output=True, text=True, errors="replace", timeout=120)
    assert rec.returncode == 0, rec.stderr
    assert validate_session(path) == []
    _hr_matches_serlog(path)
    assert not (path / RECORDING_LOCK).exists()


# ------------------------------------------------------------------------ case 2: serial log
def test_a_serial_log_write_failure_is_not_a_gap(tmp_path, shared_data) -> None:
    """The log's disk fills (/dev/full: a real ENOSPC): the link stops plainly, its thread does not
    die in silence, and it never shows 'reconnecting'."""
    chunks = hxm_chunks(shared_data, 0, 20)
    replay = PtyReplay([TimedChunk(t / 10, d) for t, d in chunks])
    player = start_replay_thread(replay)
    q: queue.Queue = queue.Queue()
    t0 = time.monotonic()
    link = SerialLink(replay.path, get_decoder("hxm"), q, lambda: time.monotonic() - t0, device="hxm")
    link.start(tmp_path / "hxm.serlog")
    _wait_for(lambda: link.bytes_in > 0)
    link._log._fh = open("/dev/full", "ab", buffering=0)  # from now on every write fails with ENOSPC
    _wait_for(lambda: link.state == "failed")
    assert link.fault.startswith(f"{tmp_path / 'hxm.serlog'}: could not write the serial log (No space left")
    assert link.gaps == 0 and not link._thread.is_alive()
    events = [obj for kind, obj in list(q.queue) if kind == "event"]
    assert [e.kind for e in events if e.kind in ("error", "device_gap")] == ["error"]
    link.stop()
    assert link.state == "failed"
    replay.stop()
    player.join(10)
    replay.close()


def test_a_failed_startup_write_after_a_reopen_is_a_gap_not_a_dead_thread(tmp_path, monkeypatch) -> None:
    q: queue.Queue = queue.Queue()
    link = SerialLink("loop://", get_decoder("hrmi"), q, time.monotonic, device="hrmi")
    link.start(tmp_path / "hrmi.serlog")
    calls = []

    def startup_fails_once() -> None:
        calls.append(1)
        if len(calls) == 1:  # the port vanished again right after the reopen
            raise serial.SerialException("write failed: [Errno 5] Input/output error")

    def unplugged(*_: object) -> bytes:
        raise serial.SerialException("device reports readiness to read but returned no data")

    monkeypatch.setattr(link, "_send_startup", startup_fails_once)
    monkeypatch.setattr(link._ser, "read", unplugged)  # the reader thread sees the unplug
    _wait_for(lambda: len(calls) >= 2 and link.state == "connected")
    link.stop()
    assert link.gaps == 2 and link.reconnects == 2 and link.fault is None and link.state == "stopped"


# -------------------------------------------------------------------------- case 4: the lock
def _recording(tmp_path: Path) -> Recorder:
    rec = Recorder(tmp_path / "out", Participant("P01"), "loop://", "lines")
    rec.start()
    return rec


def _controller() -> type:
    """The Capture stage's model class (Qt-free)."""
    from effortface.capture_tool.capture_session import CaptureSession
    return CaptureSession


def test_a_recording_session_is_locked_with_a_visible_owner(tmp_path) -> None:
    from effortface.annotate.annotate_session import AnnotateSession
    from effortface.train.dataset import expand_paths

    rec = _recording(tmp_path)
    path = rec.path
    try:
        owner = recording_owner(path)
        assert owner["pid"] == os.getpid() and owner["what"] == "capture" and owner["host"]
        with pytest.raises(LockedError, match=rf"being recorded by pid {os.getpid()} on .* since .*stop that"):
            recover_session(path)
        assert list_sessions(path.parent) == [] and list_sessions(path.parent, include_recording=True) == [path]
        assert _controller()(tmp_path / "out").incomplete_sessions() == []  # the Capture stage's recovery offer
        with pytest.raises(LockedError, match="to annotate it"):
            AnnotateSession(path, "R1")
        with pytest.raises(LockedError, match="to train on it"):
            expand_paths([path])
    finally:
        rec.stop()
    assert recording_owner(path) is None and not (path / RECORDING_LOCK).exists()
    assert list_sessions(path.parent) == [path]


def test_recover_refuses_a_running_capture_and_a_killed_ones_lock_is_stale(tmp_path, shared_data) -> None:
    replay, pty = start_replay(write_serlog(tmp_path / "in.serlog", hxm_chunks(shared_data, 0, 120)),
                               "--speed", "2")
    proc = _capture(pty, tmp_path / "out", "--no-video")
    path = Path(proc.stdout.readline().strip())
    _wait_for(lambda: len((path / "heart_rate.csv").read_text().splitlines()) > 2)
    refused = subprocess.run(effortface("recover", path), capture_output=True, text=True, timeout=60)
    lines = refused.stderr.strip().splitlines()
    assert refused.returncode == 2 and len(lines) == 1 and f"being recorded by pid {proc.pid}" in lines[0], refused
    assert read_session_info(path).complete is False
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    replay.terminate()
    replay.wait(10)
    assert (path / RECORDING_LOCK).exists() and recording_owner(path) is None  # stale: blocks nothing
    done = subprocess.run(effortface("recover", path), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and RECORDING_LOCK in done.stdout, done
    assert not (path / RECORDING_LOCK).exists() and validate_session(path) == []


def test_one_holder_at_a_time(tmp_path) -> None:
    lock = acquire_lock(tmp_path / "x.lock", "capture")
    with pytest.raises(LockedError, match=r"x.lock: expected no other program at work, found pid \d+"):
        acquire_lock(tmp_path / "x.lock", "capture")
    lock.release()
    assert lock_owner(tmp_path / "x.lock") is None
    with acquire_lock(tmp_path / "x.lock", "capture") as again:
        assert lock_owner(tmp_path / "x.lock") == again.owner


# ------------------------------------------------------------------------ case 7: read back
@pytest.fixture
def crashed(tmp_path: Path, shared_data: Path) -> Path:
    return _crashed_session(tmp_path / "out", shared_data)


def _zero_block(path: Path, start: int, n: int) -> None:
    blob = bytearray(path.read_bytes())
    blob[start:start + n] = b"\0" * n
    path.write_bytes(bytes(blob))


def test_a_nul_block_in_the_frame_table_is_repaired_and_read_back(crashed) -> None:
    frames = crashed / "video_frames.csv"
    lines = frames.read_text().splitlines()
    _zero_block(frames, len("\n".join(lines[:10])) + 1, len(lines[10]) + len(lines[11]) + 1)  # rows 9 and 10
    note = recover_session(crashed)
    done = "\n".join(note["done"])
    assert "NUL bytes" in done and "interpolated" in done, done
    s = read_session(crashed)
    assert len(s.frame_times_s) == index_video(crashed / "video.avi") == 30 and validate_session(crashed) == []
    assert s.frame_times_s[9] == pytest.approx(0.05 + 9 / 30, abs=1e-3)


def test_a_nul_block_in_events_is_repaired_and_read_back(crashed) -> None:
    events = crashed / "events.csv"
    events.write_bytes(events.read_bytes() + b"\0" * 300 + b"\n1.0000,marker,a,\n")
    note = recover_session(crashed)
    assert any("events.csv: dropped 1 line(s) holding NUL bytes" in line for line in note["done"]), note
    assert [e.label for e in read_session(crashed).events] == ["a"] and validate_session(crashed) == []


def test_an_unrepairable_file_fails_recovery_and_changes_nothing(crashed) -> None:
    frames = crashed / "video_frames.csv"
    frames.write_text(frames.read_text().replace("5,", "five,", 1))
    before = {p.name: p.read_bytes() for p in crashed.iterdir() if p.is_file()}
    with pytest.raises(SessionFormatError, match=r"video_frames.csv: expected frame,t_s rows, found 'five,"):
        recover_session(crashed)
    assert {p.name: p.read_bytes() for p in crashed.iterdir() if p.is_file()} == before


def test_one_bad_heart_rate_row_is_rebuilt_from_the_serial_log(crashed) -> None:
    hr = crashed / "heart_rate.csv"
    damaged = hr.read_text().replace("\n", "\nnot,a,row\n", 2).replace("\nnot,a,row\n", "\n", 1)
    hr.write_text(damaged)
    note = recover_session(crashed)
    assert any("rebuilt from the serial log" in line for line in note["done"]), note
    assert (crashed / DAMAGED_HR_CSV).read_text() == damaged  # nothing lost: the damaged file is kept
    assert content(read_session(crashed).heart_rate) == content(decode_serlog(crashed / "serial" / "hxm.serlog"))


# -------------------------------------------------------------------------------- case 12
def test_recover_removes_leftover_temporary_files(crashed) -> None:
    (crashed / ".session.json.k3j2.tmp").write_text("{half")
    (crashed / ".heart_rate.recovering.csv").write_text("half")
    note = recover_session(crashed)
    assert any("removed 1 leftover temporary file(s): .session.json.k3j2.tmp" in line for line in note["done"])
    assert not list(crashed.glob(".*"))


def test_atomic_write_cleans_stale_temps_fsyncs_the_folder_and_names_the_file(tmp_path, monkeypatch) -> None:
    target = tmp_path / "session.json"
    stale, young = tmp_path / ".session.json.old1.tmp", tmp_path / ".session.json.new1.tmp"
    stale.write_text("x")
    young.write_text("y")
    os.utime(stale, (time.time() - 2 * fileio.STALE_TMP_S,) * 2)
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(fileio.os, "fsync", lambda fd: (synced.append(os.fstat(fd).st_mode), real_fsync(fd))[1])
    fileio.write_json_atomic(target, {"v": 1})
    assert not stale.exists() and young.exists()
    assert any(os.path.stat.S_ISDIR(m) for m in synced)  # the folder, after the rename

    def disk_full(fh) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError) as err:
        fileio.atomic_write(target, disk_full)
    assert err.value.filename == str(target) and err.value.errno == errno.ENOSPC
    assert json.loads(target.read_text()) == {"v": 1}


def test_a_port_that_delivered_no_valid_sample_is_warned_about(tmp_path) -> None:
    rec = _recording(tmp_path)
    rec.stop()
    assert len(rec.warnings) == 1 and rec.warnings[0].startswith("loop://: delivered no valid heart-rate sample")
    assert read_session_info(rec.path).extra["stats"]["warnings"] == rec.warnings
    assert read_session_info(rec.path).complete


def test_the_serlog_of_a_failed_link_is_readable(tmp_path) -> None:
    """What a failed link wrote stays a readable serial log (kept, not truncated by the failure)."""
    q: queue.Queue = queue.Queue()
    link = SerialLink("loop://", get_decoder("lines"), q, time.monotonic, device="lines")
    link.start(tmp_path / "lines.serlog")
    link._ser.write(b"72,800\n")
    _wait_for(lambda: link.bytes_in == 7)
    link._log._fh = open("/dev/full", "ab", buffering=0)
    link._ser.write(b"73,810\n")
    _wait_for(lambda: link.state == "failed")
    link.stop()
    assert read_serlog(tmp_path / "lines.serlog").data_bytes() == b"72,800\n"
    assert serial_link.SerialLink is SerialLink
