"""``effortface import xdf`` of files other apps write (issue 24): the XDF project's real example files
(tests/data/xdf, MIT, see README.md there) and, where no real file exists, files written here with the
tests' XDF writer (xdf_writer.py, read back with pyxdf) as ExciteOMeter, an R-R app or an EEG amplifier
lay their streams out. Heart rate is found by name, type, channel label or unit; R-R in ms becomes heart
rate with the R-R kept; a stream that is not in bpm is converted or refused in one line; no valid heart
rate is ever outside 25-250 bpm."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.interop.xdf_import import HR_RANGE_BPM, load_xdf, marker_events

from .xdf_writer import XdfStream, write_xdf

DATA = Path(__file__).resolve().parents[1] / "data" / "xdf"


def _import(xdf: Path, out: Path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "effortface", "import", "xdf", str(xdf), "--out", str(out),
                           "--participant", "P01", *map(str, args)], capture_output=True, text=True, timeout=300)


def _one_line(done: subprocess.CompletedProcess, *parts: str) -> None:
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    for part in parts:
        assert part in done.stderr, done.stderr


def _hr_rows(folder: Path) -> list[dict]:
    with open(folder / "heart_rate.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _assert_valid_in_range(rows: list[dict]) -> None:
    low, high = HR_RANGE_BPM
    for r in rows:
        if r["valid"] == "1":
            assert low <= float(r["hr_bpm"]) <= high, r


# --- the XDF project's real example files --------------------------------------------------------

def test_real_eeg_named_as_heart_rate_is_refused(tmp_path):
    """minimal.xdf's int16 'SendDataC' (EEG, three unlabelled channels: 192, 12, 13 ...) named with
    --hr-stream: no channel says heart rate, none is taken as one."""
    _one_line(_import(DATA / "minimal.xdf", tmp_path / "s", "--hr-stream", "SendDataC"),
              "stream 'SendDataC' (EEG): expected a channel labelled hr_bpm", "found labels ['', '', '']")
    assert not (tmp_path / "s").exists()


def test_real_file_without_heart_rate_is_one_line(tmp_path):
    _one_line(_import(DATA / "minimal.xdf", tmp_path / "s"), "expected a heart-rate stream",
              "'SendDataC' (EEG), 'SendDataString' (StringMarker)")


def test_real_empty_stream_is_one_line(tmp_path):
    _one_line(_import(DATA / "empty_streams.xdf", tmp_path / "s", "--hr-stream",
                      "Empty data stream: test stream 0 counter"),
              "stream 'Empty data stream: test stream 0 counter': expected heart-rate samples, found an empty stream")
    assert not (tmp_path / "s").exists()


def test_real_counter_stream_is_not_heart_rate(tmp_path):
    """A counter (0, 1, 2 ...) in a real file named as heart rate: refused, never imported as bpm."""
    _one_line(_import(DATA / "empty_streams.xdf", tmp_path / "s", "--hr-stream", "Data stream: test stream 0 counter"),
              "stream 'Data stream: test stream 0 counter' (data): expected heart rates of 25-250 bpm",
              "not imported as heart rate")


def test_real_string_markers_become_events():
    streams = {str(s["info"]["name"][0]): s for s in load_xdf(DATA / "minimal.xdf")}
    events = marker_events(streams["SendDataString"], 5.0)
    assert [e.label for e in events][1:5] == ["Hello", "World", "from", "LSL"]
    assert all(e.kind == "marker" for e in events)


# --- files written here as other apps lay them out (no real recording of these apps is public) -----

def _beats(rr_ms: list[float], t0: float = 100.0) -> list[float]:
    out, t = [], t0
    for rr in rr_ms:
        t += rr / 1000.0
        out.append(t)
    return out


RR_MS = [800.0, 810.0, 790.0, 805.0, 795.0, 800.0, 820.0, 780.0] * 5


def test_exciteometer_heart_rate_stream_is_found_by_name(tmp_path):
    """ExciteOMeter-style: streams named HeartRate and RRinterval, both typed by the app."""
    stamps = _beats(RR_MS)
    xdf = write_xdf(tmp_path / "eom.xdf", [
        XdfStream("HeartRate", "ExciteOMeter", [("HeartRate", "bpm")], stamps, [[60000.0 / r] for r in RR_MS]),
        XdfStream("RRinterval", "ExciteOMeter", [("RRinterval", "ms")], stamps, [[r] for r in RR_MS]),
        XdfStream("Markers", "Markers", [("event", ""), ("detail", "")], [stamps[3]], [["lap", "start 2"]],
                  fmt="string")])
    done = _import(xdf, tmp_path / "s")
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.strip())
    rows = _hr_rows(folder)
    assert len(rows) == len(RR_MS) and all(r["valid"] == "1" for r in rows)
    assert float(rows[0]["hr_bpm"]) == pytest.approx(75.0, abs=0.01)
    with open(folder / "events.csv", newline="") as fh:
        events = list(csv.DictReader(fh))
    assert [(e["kind"], e["label"], e["value"]) for e in events] == [("marker", "lap", "start 2")]  # both channels


@pytest.mark.parametrize("unit, scale", [("ms", 1.0), ("s", 0.001)])
def test_rr_stream_becomes_heart_rate_with_rr_kept(tmp_path, unit, scale):
    stamps = _beats(RR_MS)
    xdf = write_xdf(tmp_path / "rr.xdf", [XdfStream("Polar RR", "RR", [("RR", unit)], stamps,
                                                    [[r * scale] for r in RR_MS])])
    done = _import(xdf, tmp_path / "s")
    assert done.returncode == 0, done.stderr
    rows = _hr_rows(Path(done.stdout.strip()))
    assert [float(r["hr_bpm"]) for r in rows] == pytest.approx([60000.0 / r for r in RR_MS], abs=0.01)
    assert [float(r["rr_ms"]) for r in rows] == pytest.approx(RR_MS, abs=0.01)
    _assert_valid_in_range(rows)


def test_rr_stream_labelled_ms_named_as_heart_rate_is_converted(tmp_path):
    """The issue's case: an unlabelled channel in ms, chosen with --hr-stream, became 803 bpm."""
    stamps = _beats(RR_MS)
    xdf = write_xdf(tmp_path / "rr.xdf", [XdfStream("Band", "Physio", [("ch0", "ms")], stamps, [[r] for r in RR_MS])])
    done = _import(xdf, tmp_path / "s", "--hr-stream", "Band")
    assert done.returncode == 0, done.stderr
    rows = _hr_rows(Path(done.stdout.strip()))
    assert max(float(r["hr_bpm"]) for r in rows) < 80 and all(r["valid"] == "1" for r in rows)


def test_eeg_in_microvolts_named_as_heart_rate_is_refused(tmp_path):
    xdf = write_xdf(tmp_path / "eeg.xdf", [XdfStream("HR", "EEG", [("Cz", "uV")], [float(k) / 10 for k in range(50)],
                                                     [[80.0]] * 50, srate_hz=10)])
    _one_line(_import(xdf, tmp_path / "s"), "channel 'Cz': expected a unit of bpm, found 'uV'")


def test_values_outside_the_range_are_never_valid(tmp_path):
    hr = [70.0, 300.0, 72.0, 10.0, 74.0, 0.5, 76.0, 251.0, 78.0, 24.9]
    xdf = write_xdf(tmp_path / "hr.xdf", [XdfStream("Watch", "HeartRate", [("hr", "bpm")],
                                                    [float(k) for k in range(len(hr))], [[v] for v in hr])])
    done = _import(xdf, tmp_path / "s")
    assert done.returncode == 0, done.stderr
    rows = _hr_rows(Path(done.stdout.strip()))
    assert [r["valid"] for r in rows] == ["1", "0"] * 5
    _assert_valid_in_range(rows)
