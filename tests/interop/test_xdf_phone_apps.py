"""``effortface import xdf`` of Polar H10 phone apps' streams (issue 35), written with the tests' XDF
writer (read back by pyxdf) as those apps lay them out: heart rate as JSON text in a string stream
(earlier PolarBridge builds), two unlabelled R-R channels, and the H10's 130 Hz ECG, which is
recognised and refused as ECG, not heart rate, unless --keep-ecg copies it."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from effortface.cli import main

from .xdf_writer import XdfStream, write_xdf

BODY = ["--participant", "P01", "--sex", "female", "--age", "30", "--height", "1.7", "--mass", "60",
        "--training-level", "5"]
# the real resting R-R intervals of tests/data/hr (rhenanbartels/hrv rest_rri.txt), first 60 beats
RR_MS = [float(line.split(";")[1]) for line in
         (Path(__file__).resolve().parents[1] / "data" / "hr" / "polar-h10-sensor-logger_RR.txt")
         .read_text().splitlines()[1:61]]


def _beats(t0: float = 1000.0) -> list[float]:
    out, t = [], t0
    for rr in RR_MS:
        t += rr / 1000.0
        out.append(t)
    return out


def _import(tmp_path: Path, xdf: Path, *extra: str) -> int:
    return main(["import", "xdf", str(xdf), "--out", str(tmp_path / "lab"), *BODY, *extra])


def _rows(tmp_path: Path) -> list[dict]:
    (folder,) = [p for p in (tmp_path / "lab").iterdir() if p.is_dir()]
    with open(folder / "heart_rate.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _ecg(t0: float = 1000.0, seconds: float = 4.0) -> XdfStream:
    n = int(130 * seconds)
    return XdfStream("Polar H10 ECG", "ECG", [("ECG", "microvolts")], [t0 + k / 130 for k in range(n)],
                     [[400.0 * math.sin(k / 5.0)] for k in range(n)], srate_hz=130.0)


@pytest.mark.parametrize(("doc", "args"), [
    (lambda hr, rr: {"hr": hr, "rr": [rr]}, ["--rr-json-key", "rr"]),              # top-level key found alone
    (lambda hr, rr: {"device": "H10", "data": {"heart_rate": hr, "rr_ms": [rr]}},
     ["--hr-json-key", "data.heart_rate", "--rr-json-key", "data.rr_ms"]),
])
def test_heart_rate_in_json_text(tmp_path, doc, args):
    stamps = _beats()
    samples = [[json.dumps(doc(round(60000 / rr), rr))] for rr in RR_MS]
    xdf = write_xdf(tmp_path / "bridge.xdf", [XdfStream("PolarBridge", "HeartRate", [("json", "")], stamps, samples,
                                                        fmt="string")])
    assert _import(tmp_path, xdf, *args) == 0
    rows = _rows(tmp_path)
    assert [int(r["hr_bpm"]) for r in rows] == [round(60000 / rr) for rr in RR_MS]
    assert [float(r["rr_ms"]) for r in rows] == pytest.approx(RR_MS)


def test_json_key_that_is_not_there(tmp_path, capsys):
    xdf = write_xdf(tmp_path / "bridge.xdf", [XdfStream("PolarBridge", "HeartRate", [("json", "")], [1.0, 2.0],
                                                        [['{"pulse": 70}'], ['{"pulse": 71}']], fmt="string")])
    assert _import(tmp_path, xdf, "--hr-json-key", "data.hr") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--hr-json-key data.hr: expected a number at that key path, found none" in err[0]
    assert "['pulse']" in err[0] and not (tmp_path / "lab").exists()


def test_two_unlabelled_rr_channels(tmp_path):
    """One sample a second with up to two R-R intervals (0 where the second beat did not come)."""
    stamps, samples, k = [], [], 0
    t = 1000.0
    while k < len(RR_MS):
        pair = RR_MS[k:k + 2] if k % 3 == 0 else RR_MS[k:k + 1]
        k += len(pair)
        t += sum(pair) / 1000.0
        stamps.append(t)
        samples.append(pair + [0.0] * (2 - len(pair)))
    xdf = write_xdf(tmp_path / "rr.xdf", [XdfStream("H10 RR", "RR", [("", ""), ("", "")], stamps, samples)])
    assert _import(tmp_path, xdf) == 0
    rows = _rows(tmp_path)
    assert len(rows) == len(samples)
    assert [float(v) for r in rows for v in r["rr_ms"].split()] == pytest.approx(RR_MS)
    assert float(rows[0]["hr_bpm"]) == pytest.approx(60000 / samples[0][1 if samples[0][1] else 0])
    assert all(r["valid"] == "1" for r in rows)


def test_unlabelled_channels_that_are_not_rr_are_still_refused(tmp_path, capsys):
    xdf = write_xdf(tmp_path / "x.xdf", [XdfStream("H10 RR", "RR", [("", ""), ("", "")], [1.0, 2.0],
                                                   [[800.0, 12.0], [790.0, 0.0]])])
    assert _import(tmp_path, xdf) == 2
    assert "expected a channel labelled hr_bpm" in capsys.readouterr().err


def test_ecg_is_not_heart_rate(tmp_path, capsys):
    xdf = write_xdf(tmp_path / "ecg.xdf", [_ecg()])
    assert _import(tmp_path, xdf) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "stream 'Polar H10 ECG' (ECG, 130 Hz): ECG, not heart rate" in err[0]
    assert _import(tmp_path, xdf, "--hr-stream", "Polar H10 ECG") == 2
    assert "ECG, not heart rate" in capsys.readouterr().err
    assert not (tmp_path / "lab").exists()


def test_ecg_kept_when_asked_beside_the_heart_rate(tmp_path):
    stamps = _beats()
    xdf = write_xdf(tmp_path / "h10.xdf", [
        _ecg(), XdfStream("Polar H10 HR", "HeartRate", [("HR", "bpm"), ("RR", "ms")], stamps,
                          [[60000 / rr, rr] for rr in RR_MS])])
    assert _import(tmp_path, xdf) == 0            # the HR stream is chosen, the ECG left alone
    (folder,) = [p for p in (tmp_path / "lab").iterdir() if p.is_dir()]
    assert not (folder / "ecg.csv").exists()
    assert _import(tmp_path, xdf, "--keep-ecg", "--label", "ecg") == 0
    (kept,) = [p for p in (tmp_path / "lab").iterdir() if p.name.endswith("_ecg")]
    lines = (kept / "ecg.csv").read_text().splitlines()
    assert lines[0] == "t_s,ecg" and len(lines) == 1 + 130 * 4
    info = json.loads((kept / "session.json").read_text())
    assert info["devices"]["ecg"] == {"stream": "Polar H10 ECG", "unit": "microvolts", "samples": 520}
