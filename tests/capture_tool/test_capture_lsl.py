"""``effortface capture --lsl`` (Must show): a replayed strap is received by a real pylsl inlet on
loopback with the same values as heart_rate.csv, on the session's LSL clock offset; the events
arrive as a marker stream; the stream description carries channels and units."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from pathlib import Path

import pylsl
from pylsl.util import LostError
import pytest


from effortface.capture_tool.lsl import hr_source_id
from effortface.core.session.folder import read_session

from .capture_helpers import BODY, decode, effortface, hxm_chunks, start_replay, write_serlog

LEAD_S = 40.0   # recording seconds of silence before the strap's bytes (4 s at 10x): time to connect
SPEED = "10"


def _resolve(prop: str, value: str, timeout_s: float = 15.0) -> pylsl.StreamInfo:
    found = pylsl.resolve_byprop(prop, value, 1, timeout_s)
    assert found, f"no LSL stream with {prop}={value}"
    return found[0]


def _pull_all(inlet: pylsl.StreamInlet, until, timeout_s: float = 40.0) -> tuple[list, list]:
    values, stamps = [], []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        chunk, ts = inlet.pull_chunk(timeout=0.2)
        values += chunk
        stamps += ts
        if until(values):
            break
    return values, stamps


def _pull_markers(inlet: pylsl.StreamInlet, label: str, timeout_s: float = 20.0) -> list[str]:
    """Marker strings until one has ``label`` (or the outlet closes: recover=False raises LostError)."""
    got: list[str] = []
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline and not any(label in m for m in got):
            got += [m[0] for m in inlet.pull_chunk(timeout=0.2)[0]]
    except LostError:
        pass
    return got


def _expected_rows(csv_text: str) -> list[tuple[float, list[float]]]:
    """heart_rate.csv rows -> (t_s, [hr_bpm, rr_ms]) as the stream carries them (one per R-R)."""
    out = []
    for line in csv_text.splitlines()[1:]:
        t_s, hr, rr, _, _, valid = line.split(",")
        hr_v = float(hr) if valid == "1" and hr else math.nan
        for r in (rr.split() or [None]):
            out.append((float(t_s), [hr_v, float(r) if r is not None else math.nan]))
    return out


def test_capture_lsl_publishes_heart_rate_csv_values(tmp_path: Path, shared_data: Path) -> None:
    chunks = [(0.0, b"\x00")] + [(t + LEAD_S, d) for t, d in hxm_chunks(shared_data, 20, 45)]
    replay, pty = start_replay(write_serlog(tmp_path / "strap.serlog", chunks), "--speed", SPEED)
    cap = subprocess.Popen(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P07", *BODY,
                                      "--no-video", "--lsl", "--out", tmp_path / "out"),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        path = Path(cap.stdout.readline().strip())
        source_id = hr_source_id("hxm", pty)
        hr_inlet = pylsl.StreamInlet(_resolve("source_id", source_id), max_buflen=60, recover=False)
        ev_inlet = pylsl.StreamInlet(_resolve("source_id", source_id + ":events"), max_buflen=60, recover=False)
        hr_inlet.open_stream(10)
        ev_inlet.open_stream(10)
        info = hr_inlet.info(10)
        n_lsl = sum(max(1, len(s.rr_ms)) for s in decode(chunks))
        values, stamps = _pull_all(hr_inlet, lambda v: len(v) >= n_lsl, 60)
        cap.send_signal(signal.SIGTERM)   # a clean stop pushes the session_stop marker
        markers = _pull_markers(ev_inlet, "session_stop")
    finally:
        cap.send_signal(signal.SIGTERM)
        assert cap.wait(20) == 0, cap.stderr.read()
        assert replay.wait(10) == 0
    expected = _expected_rows((path / "heart_rate.csv").read_text())
    assert len(expected) > 20 and len(values) == len(expected)
    for (t_s, want), got, stamp in zip(expected, values, stamps):
        assert got == pytest.approx(want, rel=1e-6, nan_ok=True)
    offset = read_session(path).info.extra["lsl"]["clock_offset_s"]
    for (t_s, _), stamp in zip(expected, stamps):
        assert stamp - offset == pytest.approx(t_s, abs=2e-3)   # the CSV's session time, on the LSL clock
    assert info.type() == "HeartRate" and info.channel_count() == 2
    assert info.nominal_srate() == pylsl.IRREGULAR_RATE and info.source_id() == source_id
    ch = info.desc().child("channels").child("channel")
    labels_units = []
    while not ch.empty():
        labels_units.append((ch.child_value("label"), ch.child_value("unit")))
        ch = ch.next_sibling()
    assert labels_units == [("hr_bpm", "bpm"), ("rr_ms", "ms")]
    assert {"kind": "sync", "label": "session_stop"}.items() <= json.loads(markers[-1]).items()


def test_capture_without_lsl_keeps_no_lsl_record(tmp_path: Path, shared_data: Path) -> None:
    replay, pty = start_replay(write_serlog(tmp_path / "s.serlog", hxm_chunks(shared_data, 20, 22)), "--speed", SPEED)
    out = subprocess.run(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P07", *BODY,
                                    "--no-video", "--duration", "1", "--out", tmp_path / "out"),
                         capture_output=True, text=True, timeout=60)
    replay.kill()
    replay.wait(10)
    assert out.returncode == 0, out.stderr
    assert "lsl" not in read_session(Path(out.stdout.splitlines()[0])).info.extra


def test_a_publishing_failure_never_stops_the_recording_thread() -> None:
    from effortface.capture_tool.lsl import LslPublisher
    from effortface.capture_tool.protocols import HrSample

    pub = LslPublisher("lines", "/dev/null-test", "P07", "P07_20260101-000000")
    pub("hr", HrSample(0.5, 70.0, (850.0,)))
    assert pub.pushed == 1 and pub.errors == 0
    pub("hr", object())          # not a sample: counted, not raised
    assert pub.errors == 1
    pub.close()
