"""Recovery of sessions a crash cut very early, and recovery that fails part-way.

A crash in the first second can leave ``video.avi`` without one whole frame (a few hundred bytes of
header, or nothing at all). Such a session recovers with no video, its bytes kept under another
name; a recovery that cannot finish leaves the folder exactly as it was.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from effortface.capture_tool import recorder
from effortface.capture_tool.camera import index_video, read_frame
from effortface.core.errors import SessionFormatError
from effortface.capture_tool.recorder import (
    UNRECOVERABLE_AVI,
    UNRECOVERABLE_FRAMES_CSV,
    decode_serlog,
    recover_session,
)
from effortface.core.session.folder import (
    EventWriter,
    FrameTimeWriter,
    HrWriter,
    Participant,
    SessionInfo,
    create_session,
    read_session,
    read_session_info,
    validate_session,
)

from .capture_helpers import (
    content,
    effortface,
    frame_number,
    hxm_chunks,
    make_numbered_video,
    write_serlog,
)

N_FRAMES = 30
#: what each early-crash case leaves of video.avi: its first 300 bytes, nothing, no file
VIDEO_CUTS = {"300-bytes": 300, "0-bytes": 0, "missing": None}


def _crashed_session(root: Path, shared_data: Path) -> Path:
    """An incomplete session as a crash leaves it: 4 of the logged HR rows flushed, a torn event,
    a 30-frame video with a time for each frame."""
    info = SessionInfo("P09_20260301-100000", Participant("P09"),
                       {"heart_rate": {"protocol": "hxm"}, "camera": {"source": "file"}})
    folder = create_session(root, info)
    log = write_serlog(folder / "serial" / "hxm.serlog", hxm_chunks(shared_data, 0.0, 10.0))
    hr = HrWriter(folder / "heart_rate.csv")
    for sample in decode_serlog(log)[:4]:
        hr.write(sample)
    hr.close()
    EventWriter(folder / "events.csv").close()
    with open(folder / "events.csv", "a", encoding="utf-8") as fh:
        fh.write("0.0100,sync,session_sta")  # torn: the process died mid-line
    make_numbered_video(folder / "video.avi", N_FRAMES)
    frames = FrameTimeWriter(folder / "video_frames.csv")
    for k in range(N_FRAMES):
        frames.write(k, 0.05 + k / 30)
    frames.close()
    return folder


def _cut_video(folder: Path, keep: int | None) -> bytes | None:
    """Cut video.avi to its first ``keep`` bytes (None: delete it); return what is left."""
    avi = folder / "video.avi"
    if keep is None:
        avi.unlink()
        return None
    avi.write_bytes(avi.read_bytes()[:keep])
    return avi.read_bytes()


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative name: bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _run_recover(folder: Path) -> subprocess.CompletedProcess:
    """Run ``effortface recover FOLDER`` (OpenCV may print raw bytes of a broken AVI on stderr)."""
    return subprocess.run(effortface("recover", folder), capture_output=True, text=True, errors="replace",
                          timeout=120)


@pytest.fixture
def crashed(tmp_path: Path, shared_data: Path) -> Path:
    return _crashed_session(tmp_path / "out", shared_data)


@pytest.mark.parametrize("cut", list(VIDEO_CUTS))
def test_video_without_a_whole_frame_recovers_with_no_video(crashed, cut) -> None:
    frames_before = (crashed / "video_frames.csv").read_bytes()
    video_left = _cut_video(crashed, VIDEO_CUTS[cut])
    note = recover_session(crashed)
    assert any("no whole frame" in line and "0 video frames" in line for line in note["done"]), note
    s = read_session(crashed)
    assert s.info.complete and s.info.extra["recovered"] == note
    assert validate_session(crashed) == [] and s.frame_times_s == [] and s.video_path is None
    # nothing lost: the video's bytes and its frame times are kept under other names
    kept = crashed / UNRECOVERABLE_AVI
    assert (kept.read_bytes() if kept.exists() else None) == video_left
    assert (crashed / UNRECOVERABLE_FRAMES_CSV).read_bytes() == frames_before
    # the rest of the recovery still happened
    assert content(s.heart_rate) == content(decode_serlog(crashed / "serial" / "hxm.serlog"))
    assert [e.label for e in s.events] == []  # the torn event line was dropped
    assert not list(crashed.glob(".*"))  # no scratch file left


@pytest.mark.parametrize("cut", list(VIDEO_CUTS))
def test_recover_cli_on_a_video_without_a_whole_frame(crashed, cut) -> None:
    _cut_video(crashed, VIDEO_CUTS[cut])
    proc = _run_recover(crashed)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stdout.startswith(f"recovered {crashed}") and "no whole frame" in proc.stdout
    assert read_session_info(crashed).complete


def test_failure_while_rewriting_the_video_leaves_the_folder_as_it_was(crashed, monkeypatch) -> None:
    """The video is repaired last but written first: a full disk there must not leave the
    heart-rate and event files repaired while the video and session.json are not."""
    _cut_video(crashed, (crashed / "video.avi").stat().st_size // 2)  # needs a rewrite
    before = _snapshot(crashed)

    def disk_full(src: Path, dst: Path, max_frames: int | None = None) -> int:
        Path(dst).write_bytes(b"RIFF half a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(recorder, "rewrite_video", disk_full)
    with pytest.raises(OSError, match="No space left"):
        recover_session(crashed)
    assert _snapshot(crashed) == before
    monkeypatch.undo()
    note = recover_session(crashed)  # and with space again it recovers
    assert "rewrote" in "\n".join(note["done"]) and validate_session(crashed) == []


def test_unreadable_serial_log_fails_before_changing_anything(crashed) -> None:
    log = crashed / "serial" / "hxm.serlog"
    log.write_bytes(b"not a serial log\n")
    before = _snapshot(crashed)
    with pytest.raises(SessionFormatError) as err:
        recover_session(crashed)
    assert str(err.value).startswith(str(log)) and "\n" not in str(err.value)
    assert _snapshot(crashed) == before
    proc = _run_recover(crashed)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "hxm.serlog" in lines[0], proc.stderr
    assert _snapshot(crashed) == before


def test_recovery_interrupted_while_renaming_finishes_on_a_second_attempt(crashed, monkeypatch) -> None:
    """A crash between two renames leaves the session incomplete; recovering again completes it."""
    _cut_video(crashed, (crashed / "video.avi").stat().st_size // 2)
    real_replace, calls = recorder.os.replace, []

    def fail_on_third(src: object, dst: object) -> None:
        calls.append(dst)
        if len(calls) == 3:
            raise OSError(5, "Input/output error")
        real_replace(src, dst)

    monkeypatch.setattr(recorder.os, "replace", fail_on_third)
    with pytest.raises(OSError):
        recover_session(crashed)
    monkeypatch.undo()
    assert json.loads((crashed / "session.json").read_text())["complete"] is False
    recover_session(crashed)
    s = read_session(crashed)
    assert validate_session(crashed) == []
    assert content(s.heart_rate) == content(decode_serlog(crashed / "serial" / "hxm.serlog"))
    n = index_video(crashed / "video.avi")
    assert 0 < n == len(s.frame_times_s) < N_FRAMES
    assert frame_number(read_frame(crashed / "video.avi", n - 1)) == n - 1
    assert not list(crashed.glob(".*"))
