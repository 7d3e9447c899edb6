"""The serial link: real reads from simulated ports, raw log, decoding, gaps and reconnects."""

from __future__ import annotations

import os
import queue
import time

import pytest
import serial

from effortface.core.errors import DeviceError, DeviceErrorReason
from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.replay import PtyReplay, TimedChunk, start_replay_thread
from effortface.capture_tool.serial_link import SerialLink, list_ports, open_port
from effortface.capture_tool.serlog import read_serlog

from .capture_helpers import content, decode, decode_parts, hxm_chunks, write_serlog


def _drain(q: queue.Queue) -> tuple[list, list]:
    samples, events = [], []
    while not q.empty():
        kind, obj = q.get()
        (samples if kind == "hr" else events).append(obj)
    return samples, events


def _wait_for(predicate, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def _link(port: str, q: queue.Queue, protocol: str = "hxm") -> SerialLink:
    t0 = time.monotonic()
    return SerialLink(port, get_decoder(protocol), q, lambda: time.monotonic() - t0, device=protocol)


def test_replay_url_to_samples_and_log(tmp_path, shared_data) -> None:
    chunks = hxm_chunks(shared_data, 0, 30)
    log = write_serlog(tmp_path / "in.serlog", chunks)
    q: queue.Queue = queue.Queue()
    link = _link(f"replay://{log}?speed=50", q)
    link.start(tmp_path / "hxm.serlog")
    _wait_for(lambda: link.bytes_in >= sum(len(d) for _, d in chunks))
    link.stop()
    samples, _ = _drain(q)
    assert content(samples) == content(decode(chunks))
    rec = read_serlog(tmp_path / "hxm.serlog")
    assert rec.data_bytes() == b"".join(d for _, d in chunks)
    assert rec.header["protocol"] == "hxm" and rec.header["port"].startswith("replay://")
    times = [t for t, _ in rec.data_chunks()]
    assert times == sorted(times) and [s.t_s for s in samples] == sorted(s.t_s for s in samples)
    assert link.state == "stopped"


def test_unplug_and_replug_through_a_stable_symlink(tmp_path, shared_data) -> None:
    first, second = hxm_chunks(shared_data, 0, 15), hxm_chunks(shared_data, 15, 30)
    link_path = tmp_path / "ttyEF0"
    q: queue.Queue = queue.Queue()
    rp1 = PtyReplay([TimedChunk(t, d) for t, d in first], speed=20, unplug_after_s=15)
    os.symlink(rp1.path, link_path)
    link = _link(str(link_path), q)
    link.start(tmp_path / "hxm.serlog")
    start_replay_thread(rp1).join(10)
    _wait_for(lambda: link.gaps == 1)
    rp2 = PtyReplay([TimedChunk(t, d) for t, d in second], speed=20)
    os.symlink(rp2.path, tmp_path / "tmp-link")
    os.replace(tmp_path / "tmp-link", link_path)  # the replug: same path, new device
    start_replay_thread(rp2).join(10)
    _wait_for(lambda: link.bytes_in == sum(len(d) for _, d in first + second))
    link.stop()
    rp2.close()
    samples, events = _drain(q)
    assert [e.kind for e in events] == ["device_gap", "reconnect"]
    assert link.reconnects == 1
    # nothing received before the unplug is lost; the cut frame is dropped, the strap state kept
    assert content(samples) == content(decode_parts([first, second]))
    assert content(decode(first)) == content(samples[: len(decode(first))])
    logged = read_serlog(tmp_path / "hxm.serlog")
    assert [r.event()["kind"] for r in logged.records if r.kind == 1] == ["device_gap", "reconnect"]


def test_link_writes_startup_bytes(tmp_path) -> None:
    """loop:// echoes what the link sends: the HRMI poll comes back and is logged."""
    q: queue.Queue = queue.Queue()
    link = _link("loop://", q, "hrmi")
    dec = link.decoder
    link.start(tmp_path / "hrmi.serlog")
    _wait_for(lambda: link.bytes_in >= len(dec.startup_bytes) + len(dec.poll_bytes))
    link.stop()
    assert read_serlog(tmp_path / "hrmi.serlog").data_bytes().startswith(dec.startup_bytes + dec.poll_bytes)


def test_missing_port_is_not_found(tmp_path) -> None:
    with pytest.raises(DeviceError, match=r"--port .*nope: expected a serial port, found no such device") as err:
        open_port(str(tmp_path / "nope"))
    assert err.value.reason is DeviceErrorReason.NOT_FOUND


def test_port_in_use_is_busy() -> None:
    with PtyReplay([]) as rp, serial.Serial(rp.path, exclusive=True):
        with pytest.raises(DeviceError, match="expected a free port, found it in use") as err:
            open_port(rp.path)
    assert err.value.reason is DeviceErrorReason.BUSY


@pytest.mark.skipif(os.geteuid() == 0, reason="root may open any device: permissions cannot be denied")
def test_unreadable_port_is_permission(tmp_path) -> None:
    with PtyReplay([]) as rp:
        os.chmod(rp.path, 0o000)
        with pytest.raises(DeviceError) as err:
            open_port(rp.path)
    assert err.value.reason is DeviceErrorReason.PERMISSION


def test_list_ports_gives_devices() -> None:
    ports = list_ports()
    assert all(set(p) == {"device", "description", "hwid"} for p in ports)
    assert [p["device"] for p in ports] == sorted(p["device"] for p in ports)


def test_startup_frames_are_sent_after_open(tmp_path) -> None:
    """loop:// echoes: the configuration frames then the decoder's startup bytes come back in order."""
    q: queue.Queue = queue.Queue()
    t0 = time.monotonic()
    frames = [b"\xa4\x01\x4a\x00\xef", b"\xa4\x02\x4b\x00\x01\xec"]
    link = SerialLink("loop://", get_decoder("ant"), q, lambda: time.monotonic() - t0, "ant", startup_frames=frames)
    link.start(tmp_path / "ant.serlog")
    _wait_for(lambda: link.bytes_in >= 11)
    link.stop()
    assert read_serlog(tmp_path / "ant.serlog").data_bytes() == b"".join(frames)


def test_real_ant_stick_needs_the_key_replays_do_not(monkeypatch, tmp_path) -> None:
    from effortface.capture_tool.protocols.ant_stick import ENV_VAR, open_sequence
    from effortface.capture_tool.recorder import device_startup_frames

    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    with PtyReplay([]) as rp:
        assert device_startup_frames("ant", rp.path) == []  # a replay: no key needed
    assert device_startup_frames("ant", "replay://x.serlog") == []
    assert device_startup_frames("hxm", "/dev/ttyUSB0") == []
    stick = tmp_path / "ttyUSB0"  # an existing port path: a missing one is reported before the key
    stick.touch()
    with pytest.raises(DeviceError, match="ANT\\+ Adopter") as err:
        device_startup_frames("ant", str(stick))
    assert err.value.reason is DeviceErrorReason.NO_KEY
    monkeypatch.setenv(ENV_VAR, "01 02 03 04 05 06 07 08")
    assert device_startup_frames("ant", str(stick)) == open_sequence(bytes(range(1, 9)))


def test_stop_from_two_threads_at_once_closes_the_log_once(tmp_path, shared_data) -> None:
    """Shutdown and a stage's own stop can race; neither may fail on the closed log."""
    import threading

    chunks = hxm_chunks(shared_data, 0, 10)
    log = write_serlog(tmp_path / "in.serlog", chunks)
    q: queue.Queue = queue.Queue()
    link = _link(f"replay://{log}?speed=50", q)
    link.start(tmp_path / "hxm.serlog")
    _wait_for(lambda: link.bytes_in >= sum(len(d) for _, d in chunks))
    errors: list[BaseException] = []

    def stop() -> None:
        try:
            link.stop()
        except BaseException as exc:  # noqa: BLE001 - the test reports it
            errors.append(exc)

    threads = [threading.Thread(target=stop) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    link.stop()  # and once more, afterwards
    assert errors == [] and link.state == "stopped"
    assert read_serlog(tmp_path / "hxm.serlog").data_bytes() == b"".join(d for _, d in chunks)
