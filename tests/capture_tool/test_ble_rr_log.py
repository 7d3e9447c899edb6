"""A Polar H10 read over Bluetooth by another program (issue 35): its log of decoded 0x2A37 notifications
(kbre93/dont-hold-your-breath's ``sample_data_ibi.csv``: arrival time and R-R interval, rounded up to
whole ms from the strap's 1/1024 s counts) rebuilt into notifications by ``tools/rr_log_to_serlog.py``,
then replayed through the real decoding and recording path (``capture --ble replay://LOG``). The
rows recorded equal an independent decode of the log's bytes (struct, no effortface code), whose R-R
intervals round up to the source file's milliseconds, one notification per arrival.

No recording of the raw notification bytes of a strap with a licence that allows copying it was found
(tests/data/hr/README.md): the flags and rate bytes here are the tool's (0x10, the rate of the mean
interval), the R-R counts and the arrival times the strap's."""

from __future__ import annotations

import csv
import json
import math
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.core.session.folder import read_session, validate_session

from .capture_helpers import BODY, effortface

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "tests" / "data" / "hr" / "polar-h10-ble-rr_dont-hold-your-breath.csv"
sys.path.insert(0, str(ROOT / "tools"))
import rr_log_to_serlog  # noqa: E402


def source_rows() -> list[tuple[float, float]]:
    """(arrival s, R-R ms) of the source file, with the csv module."""
    with open(SRC, newline="") as fh:
        return [(float(t), float(rr)) for t, rr in csv.reader(fh)]


def decode_serlog(path: Path) -> tuple[dict, list[tuple[float, int, int, tuple[float, ...]]]]:
    """(header, [(arrival s, flags, rate, R-R ms)]) read with struct: the serlog layout (magic, JSON
    line, records ``<BdI`` + payload) and the 0x2A37 layout (flags, uint8 rate, uint16 counts of
    1/1024 s) by hand, frames ``B1 E5 <length>`` one per record."""
    blob = path.read_bytes()
    assert blob.startswith(b"EFSERLOG 1\n")
    end = blob.index(b"\n", 11)
    header = json.loads(blob[11:end])
    at, out = end + 1, []
    while at < len(blob):
        kind, t_s, n = struct.unpack_from("<BdI", blob, at)
        payload = blob[at + 13:at + 13 + n]
        at += 13 + n
        assert kind == 0 and payload[:2] == b"\xb1\xe5" and payload[2] == n - 3
        note = payload[3:]
        counts = struct.unpack(f"<{(len(note) - 2) // 2}H", note[2:])
        out.append((t_s, note[0], note[1], tuple(round(c * 1000 / 1024, 3) for c in counts)))
    return header, out


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> Path:
    log = tmp_path_factory.mktemp("rrlog") / "h10.serlog"
    assert rr_log_to_serlog.main([str(SRC), str(log), "--device", "polar_h10"]) == 0
    return log


def test_conversion_keeps_every_interval_and_arrival(converted):
    rows = source_rows()
    header, notes = decode_serlog(converted)
    assert header["protocol"] == "ble_hrm" and header["device"] == "polar_h10"
    assert len(rows) == 620 and len(notes) == 587                        # 33 notifications carried two beats
    assert sum(len(rr) for *_, rr in notes) == len(rows)
    flat = [(t, rr) for t, _, _, rrs in notes for rr in rrs]
    # each interval is a 1/1024 s count whose ms, rounded up as the source's logger did, are the row's
    assert [math.ceil(rr) for _, rr in flat] == [ms for _, ms in rows]
    assert all(ms - 1 < rr <= ms for (_, rr), (_, ms) in zip(flat, rows))
    firsts = [t for k, (t, _) in enumerate(rows) if k == 0 or t - rows[k - 1][0] >= rr_log_to_serlog.SAME_NOTIFICATION_S]
    assert [t for t, *_ in notes] == firsts                              # arrival times kept, s
    assert {f for _, f, _, _ in notes} == {0x10}
    assert all(r == round(60000 / (sum(rr) / len(rr))) for _, _, r, rr in notes)   # the mean interval's rate


def test_replay_records_the_independent_decode(converted, tmp_path):
    """``capture --ble replay://`` (the real port, decoder and recorder) records one row per notification:
    the rate and R-R intervals of the independent decode, the 10 minutes of beats whole."""
    _, notes = decode_serlog(converted)
    done = subprocess.run(effortface("capture", "--ble", f"replay://{converted}?speed=100", "--participant", "P01",
                                     *BODY, "--out", tmp_path / "lab", "--no-video", "--duration", "10"),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.splitlines()[0])
    assert validate_session(folder) == []
    rows = read_session(folder).heart_rate
    assert [(r.hr_bpm, r.rr_ms, r.valid) for r in rows] == [(float(hr), rr, True) for _, _, hr, rr in notes]
    stats = json.loads((folder / "session.json").read_text())["stats"]["decoder"]
    assert stats["frames_ok"] == 587 and stats["frames_bad"] == 0
    assert rows[-1].t_s - rows[0].t_s == pytest.approx((notes[-1][0] - notes[0][0]) / 100, abs=1.0)


@pytest.mark.parametrize(("text", "expected"), [
    ("0.5,800\nx,900\n", "row 2: expected two numbers"),
    ("0.5,800\n0.2,900\n", "never go backwards"),
    ("0.5,800\n1.5,70000\n", "R-R of 0-63999 ms"),
    ("", "found none"),
])
def test_bad_logs_one_line_nothing_written(tmp_path, capsys, text, expected):
    src, dst = tmp_path / "in.csv", tmp_path / "out.serlog"
    src.write_text(text)
    assert rr_log_to_serlog.main([str(src), str(dst)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "in.csv" in err[0] and expected in err[0], err
    assert not dst.exists()


def test_rounding_is_reversed_for_every_interval():
    for rounding, to_ms in rr_log_to_serlog.ROUNDING.items():
        for ms in range(200, 2001):
            count = rr_log_to_serlog.rr_count(ms, rounding)
            assert to_ms(count * 1000 / 1024) == ms and not to_ms((count - 1) * 1000 / 1024) == ms
