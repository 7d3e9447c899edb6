"""Bluetooth LE heart-rate straps (issue 35): the 0x2A37 Heart Rate Measurement decoder on the field
layouts of the GATT Specification Supplement, a notification log replayed through ``capture --ble
replay://LOG`` giving the rows of ``effortface decode`` (R-R included), and fuzzed notifications (a
flipped flags byte, a notification cut short) counted and skipped, never a traceback."""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import random
import subprocess
from contextlib import redirect_stdout
from pathlib import Path

import pytest

from effortface.capture_tool.protocols import get_decoder
from effortface.capture_tool.protocols.ble_hrm import (NotificationError, build_measurement, frame,
                                                       parse_measurement)
from effortface.cli import main
from effortface.core.session.folder import read_session, validate_session

from .capture_helpers import BODY, content, decode, effortface, write_serlog

DATA = Path(__file__).resolve().parents[1] / "data" / "hr"


# ---------------------------------------------------------------- the characteristic's field layouts
@pytest.mark.parametrize(("hexbytes", "hr", "contact", "energy", "rr"), [
    ("0048", 72, None, None, ()),                      # uint8 rate, contact not supported
    ("0648", 72, True, None, ()),                      # contact supported and detected
    ("0448", 72, False, None, ()),                     # contact supported, not detected
    ("014801", 328, None, None, ()),                   # uint16 rate (0x0148)
    ("163c0004", 60, True, None, (1000.0,)),           # one R-R of 1024/1024 s
    ("1e50100000030004", 80, True, 16, (750.0, 1000.0)),  # energy 16 kJ, two R-R (768, 1024 units)
    ("1150000004", 80, None, None, (1000.0,)),          # uint16 rate and R-R
])
def test_field_layouts(hexbytes, hr, contact, energy, rr):
    m = parse_measurement(bytes.fromhex(hexbytes))
    assert (m.hr_bpm, m.contact, m.energy_kj, m.rr_ms) == (hr, contact, energy, rr)
    assert parse_measurement(build_measurement(hr, rr, contact=contact, energy_kj=energy,
                                               hr16=bool(bytes.fromhex(hexbytes)[0] & 1))) == m


@pytest.mark.parametrize(("hexbytes", "reason"), [
    ("", "empty"), ("20", "reserved_flags"), ("ff48", "reserved_flags"), ("01", "short"), ("0948", "short"),
    ("104800", "bad_rr"), ("10480004aa", "bad_rr"), ("064800", "extra_bytes"), ("1048", "bad_rr"),
])
def test_notifications_that_cannot_be_one(hexbytes, reason):
    with pytest.raises(NotificationError) as err:
        parse_measurement(bytes.fromhex(hexbytes))
    assert err.value.reason == reason


def test_decoder_rows_contact_and_limits():
    dec = get_decoder("ble_hrm")
    notes = [bytes.fromhex(h) for h in ("163c0004", "0448", "06ff", "0600", "0648")]
    rows = []
    for k, n in enumerate(notes):
        rows += dec.feed(frame(n), float(k))
    assert [(r.hr_bpm, r.valid, r.rr_ms) for r in rows] == [
        (60.0, True, (1000.0,)), (None, False, ()), (None, False, ()), (None, False, ()), (72.0, True, ())]
    assert dec.stats.frames_ok == 5 and dec.stats.detail["no_contact"] == 1
    assert dec.stats.detail["implausible_hr"] == 1     # 255 bpm: a strap artefact, not a rate


# ---------------------------------------------------------------- a strap's notifications, logged and replayed
def h10_log(path: Path, n_beats: int = 240) -> Path:
    """The real R-R series of tests/data/hr (Polar Sensor Logger layout) sent as an H10 sends it: one
    notification a second with its rate and the beats that ended in that second, logged at arrival."""
    with open(DATA / "polar-h10-sensor-logger_RR.txt", newline="") as fh:
        rows = list(csv.DictReader(fh, delimiter=";"))[:n_beats]
    t0 = dt.datetime.fromisoformat(rows[0]["Phone timestamp"])
    beats = [((dt.datetime.fromisoformat(r["Phone timestamp"]) - t0).total_seconds(), float(r["RR-interval [ms]"]))
             for r in rows]
    chunks, second = [], 1.0
    while second <= beats[-1][0] + 1:
        rr = tuple(v for t, v in beats if second - 1 < t <= second)
        hr = round(60000 / rr[-1]) if rr else round(60000 / beats[0][1])
        chunks.append((second, frame(build_measurement(hr, rr, contact=True))))
        second += 1.0
    return write_serlog(path, chunks, protocol="ble_hrm")


def _decode_cli(log: Path) -> list[dict]:
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["decode", "--protocol", "ble_hrm", str(log)]) == 0
    return list(csv.DictReader(io.StringIO(buf.getvalue())))


def test_capture_ble_replay_equals_decode(tmp_path):
    log = h10_log(tmp_path / "h10.serlog")
    from effortface.capture_tool.serlog import read_serlog

    chunks = list(read_serlog(log).data_chunks())
    expected = decode(chunks, "ble_hrm")
    assert sum(len(s.rr_ms) for s in expected) >= 200
    done = subprocess.run(effortface("capture", "--ble", f"replay://{log}?speed=40", "--participant", "P01", *BODY,
                                     "--out", tmp_path / "lab", "--no-video", "--duration", "8"),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.splitlines()[0])
    s = read_session(folder)
    assert validate_session(folder) == [] and s.devices["heart_rate"]["protocol"] == "ble_hrm"
    assert content(s.heart_rate) == content(expected)
    cli_rows = _decode_cli(log)
    assert [(float(r["hr_bpm"]) if r["hr_bpm"] else None, tuple(map(float, r["rr_ms"].split()))) for r in cli_rows] \
        == [(s.hr_bpm, s.rr_ms) for s in read_session(folder).heart_rate]
    assert list(folder.glob("serial/*.serlog"))   # every notification logged raw with its arrival time


# ---------------------------------------------------------------- fuzz
def test_fuzzed_notifications_counted_and_skipped(tmp_path):
    rng = random.Random(35)
    notes = [build_measurement(rng.randint(50, 180), tuple(rng.uniform(400, 1200) for _ in range(rng.randint(1, 3))))
             for _ in range(400)]
    bad = 0
    fuzzed = []
    for n in notes:
        how = rng.random()
        if how < 0.2:      # flags byte flipped: every bit inverted sets the reserved bits
            n = bytes([n[0] ^ 0xFF]) + n[1:]
            bad += 1
        elif how < 0.4:    # cut short by one byte: the last R-R interval loses its high byte
            n = n[:-1]
            bad += 1
        fuzzed.append(n)
    dec = get_decoder("ble_hrm")
    rows = []
    for k, n in enumerate(fuzzed):
        rows += dec.feed(frame(n), float(k))
    assert dec.stats.frames_bad == dec.stats.detail["bad_notification"] == bad
    assert len(rows) == len(notes) - bad and all(r.valid for r in rows)
    # the same fuzzed log through the recorder: the rows of the good notifications, the bad ones counted
    log = write_serlog(tmp_path / "fuzz.serlog", [(1 + k * 0.05, frame(n)) for k, n in enumerate(fuzzed)], "ble_hrm")
    done = subprocess.run(effortface("capture", "--ble", f"replay://{log}?speed=20", "--participant", "P01", *BODY,
                                     "--out", tmp_path / "lab", "--no-video", "--duration", "4"),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    folder = Path(done.stdout.splitlines()[0])
    assert len(read_session(folder).heart_rate) == len(rows)
    stats = json.loads((folder / "session.json").read_text())["stats"]
    assert stats["decoder"]["frames_bad"] == stats["decoder"]["bad_notification"] == bad


def test_random_bytes_never_raise():
    rng = random.Random(7)
    dec = get_decoder("ble_hrm")
    for k in range(300):
        blob = bytes(rng.randrange(256) for _ in range(rng.randint(0, 40)))
        if rng.random() < 0.5:
            blob = frame(blob[:30])
        dec.feed(blob, float(k))
    dec.finish()
    assert dec.stats.bytes_in > 0


def test_capture_ble_bad_options(capsys, tmp_path):
    argv = ["capture", "--participant", "P01", *BODY, "--out", str(tmp_path / "lab"), "--no-video"]
    assert main([*argv, "--ble", "AA:BB", "--protocol", "hxm"]) == 2
    assert "a --ble strap speaks ble_hrm" in capsys.readouterr().err
    assert main([*argv, "--port", "loop://"]) == 2
    assert "--protocol: expected one of" in capsys.readouterr().err


def test_lost_strap_is_a_gap_and_a_reconnect(tmp_path):
    """The strap goes out of range (the replay's reads fail as a lost BLE link's do): the recorder logs a
    gap, re-opens the same strap and carries on, as for a pulled serial strap."""
    log = h10_log(tmp_path / "h10.serlog", n_beats=120)
    done = subprocess.run(effortface("capture", "--ble", f"replay://{log}?speed=20&unplug_after=40",
                                     "--participant", "P01", *BODY, "--out", tmp_path / "lab", "--no-video",
                                     "--duration", "5"), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    folder = Path(done.stdout.splitlines()[0])
    stats = json.loads((folder / "session.json").read_text())["stats"]
    assert stats["serial_gaps"] >= 1 and stats["serial_reconnects"] >= 1
    kinds = {(e.kind, e.label) for e in read_session(folder).events}
    assert {("device_gap", "ble_hrm"), ("reconnect", "ble_hrm")} <= kinds


def test_ble_port_reads_notifications_then_raises_when_lost():
    """The BLE port's own buffer: each notification one frame, readable in any chunking; a lost link
    raises as a pulled serial port does, once what arrived before is read."""
    import serial

    from effortface.capture_tool.ble_link import BlePort

    port = BlePort(timeout=0.05)   # not opened on a radio: fed as bleak's notify callback feeds it
    port.is_open = True
    notes = [build_measurement(70, (850.0,)), build_measurement(71, (840.0, 845.0))]
    for n in notes:
        port._notified(bytearray(n))
    assert port.in_waiting == sum(len(frame(n)) for n in notes)
    data = port.read(5) + port.read(100)
    assert data == b"".join(frame(n) for n in notes)
    assert port.read(10) == b""                      # nothing new: the read times out empty
    port._notified(bytearray(notes[0]))
    port._set_lost("BLE link lost")
    assert port.read(100) == frame(notes[0])         # what arrived before the loss is kept
    with pytest.raises(serial.SerialException, match="BLE link lost"):
        port.read(1)


def test_effortface_replay_serves_a_ble_log(tmp_path):
    """``effortface replay`` plays a BLE strap's log on a pseudo-terminal, as a serial strap's."""
    from .capture_helpers import start_replay

    log = h10_log(tmp_path / "h10.serlog", n_beats=60)
    from effortface.capture_tool.serlog import read_serlog

    expected = decode(list(read_serlog(log).data_chunks()), "ble_hrm")
    replay, pty = start_replay(log, "--speed", "20")
    done = subprocess.run(effortface("capture", "--port", pty, "--protocol", "ble_hrm", "--participant", "P01", *BODY,
                                     "--out", tmp_path / "lab", "--no-video", "--duration", "6"),
                          capture_output=True, text=True, timeout=120)
    replay.wait(20)
    assert done.returncode == 0, done.stderr
    rows = read_session(Path(done.stdout.splitlines()[0])).heart_rate
    assert content(rows) == content(expected)


@pytest.mark.parametrize(("target", "is_address"), [
    ("C4:7C:8D:6A:1B:2E", True), ("c4:7c:8d:6a:1b:2e", True), ("5B1F0E2A-9C3D-4E8F-A1B2-C3D4E5F60718", True),
    ("Polar H10 8A2C1D3E", False), ("TICKR-1A2B", False), ("C4:7C:8D", False),
])
def test_ble_target_is_an_address_or_a_name(target, is_address):
    from effortface.capture_tool.ble_link import ADDRESS_RE

    assert bool(ADDRESS_RE.fullmatch(target)) is is_address
