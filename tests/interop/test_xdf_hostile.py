"""Issue 29: ``import xdf`` answers every hostile recording in one line, writes no half session, and
never marks out-of-range data as valid."""

from __future__ import annotations

import csv
import math
import struct
from pathlib import Path

import pytest

from effortface.cli import main

from .xdf_writer import XdfStream, _chunk, _varlen, write_xdf

T0 = 5000.0


def _hr(n: int = 20, hr: float = 80.0, stamps: list[float] | None = None) -> XdfStream:
    return XdfStream("Polar", "HeartRate", [("hr_bpm", "bpm"), ("rr_ms", "ms")],
                     stamps if stamps is not None else [T0 + k for k in range(n)], [[hr, 750.0]] * n)


def _marker(text: str, stamp: float = T0 + 1) -> XdfStream:
    return XdfStream("events", "Markers", [("event", "")], [stamp], [[text]], fmt="string")


def _import(tmp_path: Path, streams: list[XdfStream] | None = None, *extra: str, xdf: Path | None = None,
            capsys=None) -> tuple[int, str]:
    xdf = xdf or write_xdf(tmp_path / "r.xdf", streams or [])
    code = main(["import", "xdf", str(xdf), "--out", str(tmp_path / "s"), "--participant", "P06", *extra])
    return code, capsys.readouterr().err if capsys else ""


def _sessions(tmp_path: Path) -> list[Path]:
    out = tmp_path / "s"
    return sorted(out.iterdir()) if out.exists() else []


REFUSED = {
    "empty HR stream": ([XdfStream("Polar", "HeartRate", [("hr_bpm", "bpm")], [], [])],
                        "stream 'Polar': expected heart-rate samples, found an empty stream"),
    "NaN stamp": ([_hr(stamps=[T0, T0 + 1, math.nan, T0 + 3] + [T0 + k for k in range(4, 20)])],
                  "stream 'Polar': expected finite time stamps, found nan at sample 2"),
    "1-channel EffortWork": ([_hr(), XdfStream("w", "EffortWork", [("w_per_kg", "W/kg")], [T0, T0 + 1], [[1.0], [2.0]])],
                             "stream 'w': expected at least 2 work channel(s), found 1"),
    "work NaN": ([_hr(), XdfStream("w", "EffortWork", [("w_per_kg", "W/kg"), ("p_per_kg", "W/kg")], [T0, T0 + 1],
                                   [[1.0, 1.0], [math.nan, 2.0]])],
                 "stream 'w': w_per_kg: expected a number from -1000 to 1000 W/kg, found nan at sample 1"),
    "work inf": ([_hr(), XdfStream("w", "EffortWork", [("w_per_kg", "W/kg"), ("p_per_kg", "W/kg")], [T0, T0 + 1],
                                   [[1.0, math.inf], [1.0, 2.0]])],
                 "p_per_kg: expected a number from -1000 to 1000 W/kg, found inf at sample 0"),
    "marker at +1e15 s": ([_hr(), _marker("start", T0 + 1e15)],
                          "stream 'events': expected time stamps within 1e+06 s of the first, found 1e+15 s"),
    "marker at -1e15 s": ([_hr(), _marker("start", -1e15)], "stream 'Polar': expected time stamps within 1e+06 s"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_refused_in_one_line_with_no_session_left(tmp_path, capsys, case) -> None:
    streams, message = REFUSED[case]
    code, err = _import(tmp_path, streams, capsys=capsys)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert _sessions(tmp_path) == []  # nothing half-written (hidden staging folders included)


@pytest.mark.parametrize("offset", ["nan", "1e300", "-inf"])
def test_video_offset_must_be_a_finite_time(tmp_path, capsys, offset) -> None:
    video = tmp_path / "v.avi"
    video.write_bytes(b"x")
    code, err = _import(tmp_path, [_hr()], "--video", str(video), f"--video-offset={offset}", capsys=capsys)
    assert code == 2 and "--video-offset: expected a finite LSL time" in err and len(err.strip().splitlines()) == 1


def test_a_5000_bpm_rate_is_never_valid_and_a_deep_marker_is_text(tmp_path, capsys) -> None:
    deep = "[" * 200_000
    hr = _hr()
    hr.samples[5] = [5000.0, 750.0]  # one absurd sample among heart rates: written as not valid
    code, err = _import(tmp_path, [hr, _marker(deep)], capsys=capsys)
    assert code == 0, err
    (session,) = _sessions(tmp_path)
    with open(session / "heart_rate.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 20 and rows[5]["valid"] == "0" and rows[5]["hr_bpm"] == ""
    assert all(r["valid"] == "1" for k, r in enumerate(rows) if k != 5)
    assert deep in (session / "events.csv").read_text()


def test_a_stream_of_5000_bpm_is_refused_not_imported(tmp_path, capsys) -> None:
    code, err = _import(tmp_path, [_hr(hr=5000.0)], capsys=capsys)
    assert code == 2 and "expected heart rates of 25-250 bpm" in err and len(err.strip().splitlines()) == 1
    assert _sessions(tmp_path) == []


def _raw_xdf(path: Path, samples_chunk: bytes) -> Path:
    header = b'<?xml version="1.0"?><info><name>Polar</name><type>HeartRate</type><channel_count>1</channel_count>' \
             b"<nominal_srate>0</nominal_srate><channel_format>float32</channel_format></info>"
    data = b"XDF:" + _chunk(1, b'<?xml version="1.0"?><info><version>1.0</version></info>')
    data += _chunk(2, struct.pack("<I", 1) + header) + _chunk(3, struct.pack("<I", 1) + samples_chunk)
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("case", ["2^40 samples", "cut after 10 bytes", "0 channels"])
def test_damaged_files_are_one_line(tmp_path, capsys, case) -> None:
    if case == "2^40 samples":
        xdf = _raw_xdf(tmp_path / "r.xdf", _varlen(2 ** 40) + b"\x08" + struct.pack("<d", T0) + b"\0" * 4)
    elif case == "cut after 10 bytes":
        full = write_xdf(tmp_path / "full.xdf", [_hr()])
        xdf = tmp_path / "r.xdf"
        xdf.write_bytes(full.read_bytes()[:10])
    else:
        xdf = write_xdf(tmp_path / "r.xdf", [XdfStream("Polar", "HeartRate", [], [T0, T0 + 1], [[], []])])
    code, err = _import(tmp_path, xdf=xdf, capsys=capsys)
    assert code == 2 and "r.xdf" in err and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and _sessions(tmp_path) == []
