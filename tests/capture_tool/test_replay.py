"""Simulated ports: a raw pseudo-terminal and the replay:// URL play the real HxM capture's bytes."""

from __future__ import annotations

import threading

import pytest
import serial

import effortface.capture_tool.serial_link  # noqa: F401  (registers replay://)
from effortface.core.errors import UserError
from effortface.capture_tool.replay import PtyReplay, TimedChunk, load_timed_chunks, open_pty_replay, start_replay_thread

from .capture_helpers import HXM_DAT, hxm_chunks, write_serlog


def _read_until_silent(ser: serial.SerialBase, n_bytes: int) -> bytes:
    out = b""
    while len(out) < n_bytes:
        chunk = ser.read(4096)
        if not chunk:
            break
        out += chunk
    return out


def test_loads_serlog_and_raw_capture_alike(tmp_path, shared_data) -> None:
    raw = load_timed_chunks(shared_data / HXM_DAT)
    log = write_serlog(tmp_path / "x.serlog", [(c.t_s + 100.0, c.data) for c in raw])
    again = load_timed_chunks(log)
    assert again == raw  # times restart at 0, bytes identical
    assert sum(len(c.data) for c in raw) == 8521 and raw[0].t_s == 0.0


def test_pty_replays_bytes_exactly_in_raw_mode(shared_data) -> None:
    chunks = hxm_chunks(shared_data, 0, 30)
    data = b"".join(d for _, d in chunks)
    # bytes a cooked tty would mangle (CR, ^C, ^D, XOFF) must pass unchanged
    chunks.append((chunks[-1][0], b"\r\n\x03\x04\x13\x11\x00\xff"))
    with PtyReplay([TimedChunk(t, d) for t, d in chunks], speed=50) as rp:
        thread = start_replay_thread(rp)
        with serial.Serial(rp.path, timeout=1.0) as ser:
            got = _read_until_silent(ser, len(data) + 8)
        thread.join(5)
    assert got == data + b"\r\n\x03\x04\x13\x11\x00\xff"
    assert rp.bytes_written == len(got) and len(rp.write_times) == len(chunks)


def test_pty_unplug_makes_reads_fail(shared_data) -> None:
    rp = open_pty_replay(shared_data / HXM_DAT, speed=20, unplug_after_s=5.0)
    start_replay_thread(rp)
    with serial.Serial(rp.path, timeout=0.5) as ser:
        got = b""
        with pytest.raises(serial.SerialException):
            while True:  # read what is waiting, as the link does: a failing read returns nothing
                got += ser.read(max(1, ser.in_waiting))
    expected = b"".join(d for t, d in hxm_chunks(shared_data) if t <= 5.0)
    assert got == expected  # everything up to the unplug arrived, then the device vanished


def test_hold_returns_when_reader_closes() -> None:
    rp = PtyReplay([TimedChunk(0.0, b"B70\n")])
    done = threading.Event()

    def _run() -> None:
        rp.wait_for_reader(5)
        rp.play()
        rp.hold(timeout_s=10)
        done.set()

    threading.Thread(target=_run, daemon=True).start()
    with serial.Serial(rp.path, timeout=1.0) as ser:
        assert ser.read(4) == b"B70\n"
    assert done.wait(5)
    rp.close()


def test_replay_url_plays_and_unplugs(tmp_path, shared_data) -> None:
    log = write_serlog(tmp_path / "hxm.serlog", hxm_chunks(shared_data, 0, 20))
    with serial.serial_for_url(f"replay://{log}?speed=100", timeout=0.5) as ser:
        got = _read_until_silent(ser, 10**6)
        assert ser.write(b"poll") == 4 and ser.bytes_sent == 4
    assert got == b"".join(d for _, d in hxm_chunks(shared_data, 0, 20))
    with serial.serial_for_url(f"replay://{log}?speed=100&unplug_after=3", timeout=0.5) as ser:
        with pytest.raises(serial.SerialException, match="unplugged"):
            while True:
                ser.read(4096)


@pytest.mark.parametrize(
    ("match", "url"),
    [
        ("speed must be above 0", "replay://{log}?speed=0"),
        ("unknown option 'bogus'", "replay://{log}?bogus=1"),
        ("expected a readable capture file", "replay://{missing}"),
    ],
)
def test_replay_url_errors(tmp_path, match: str, url: str) -> None:
    log = write_serlog(tmp_path / "x.serlog", [(0.0, b"B70\n")], "lines")
    with pytest.raises(serial.SerialException, match=match):
        serial.serial_for_url(url.format(log=log, missing=tmp_path / "missing.serlog"))


def test_replay_rejects_bad_input(tmp_path) -> None:
    with pytest.raises(UserError, match="expected a readable capture file"):
        open_pty_replay(tmp_path / "missing.serlog")
    with pytest.raises(UserError, match="found a folder"):
        open_pty_replay(tmp_path)
    with pytest.raises(UserError, match="--speed: expected a number above 0"):
        PtyReplay([], speed=-1)


def test_play_ends_when_the_reader_leaves_in_mid_play() -> None:
    """A reader that closes the port before the recording ends (a capture stopped early) ends the
    replay: with no reader the pseudo-terminal's buffer fills and a write would block for ever."""
    rp = PtyReplay([TimedChunk(i * 0.001, b"x" * 200) for i in range(2000)])  # 400 kB over 2 s
    done = threading.Event()

    def _run() -> None:
        rp.wait_for_reader(5)
        rp.play()
        rp.hold(timeout_s=30)
        done.set()

    threading.Thread(target=_run, daemon=True).start()
    with serial.Serial(rp.path, timeout=1.0) as ser:
        assert len(ser.read(400)) == 400
    assert done.wait(20), "replay went on writing to a port nobody reads"
    assert rp.reader_left and rp.bytes_written < 2000 * 200
    rp.close()
