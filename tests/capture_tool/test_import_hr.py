"""``effortface import hr`` (issue 35, Must show): every real heart-rate file in tests/data/hr/ (FIT
from Garmin Fenix 2/5, Suunto Spartan, Wahoo ELEMNT; TCX from a Garmin Edge 705 and Forerunner 405;
GPX from a Garmin Oregon 450; Polar HRM from an S610, an S725 and an S810 in R-R mode; PWX from a
Timex Global Trainer; phone-app tables: Polar Sensor Logger's HR export from a Verity Sense, an HRV
Logger R-R export, and Polar Sensor Logger HR and R-R layouts filled with real R-R) imports through
the CLI to a session whose median bpm equals an independent parse of the file (another library or
another traversal) within 1 bpm and whose time span is the file's. Bad input is one line, exit 2,
nothing written."""

from __future__ import annotations

import csv
import datetime as dt
import json
import re
import statistics
import xml.dom.minidom
from pathlib import Path

import pytest

from effortface.cli import main
from effortface.core.session.folder import read_session, validate_session

DATA = Path(__file__).resolve().parents[1] / "data" / "hr"
BODY = ["--sex", "female", "--age", "30", "--height", "1.70", "--mass", "60", "--training-level", "5"]


# ------------------------------------------------------------------ independent parses (no effortface code)
def _iso(text: str) -> float:
    return dt.datetime.fromisoformat(text.strip().replace("Z", "+00:00")).timestamp()


def fitparse_series(path: Path) -> tuple[list[float], list[float], int]:
    """(times, bpm, R-R count) with fitparse, a different FIT library than the importer's fitdecode."""
    import fitparse

    times, bpm, n_rr = [], [], 0
    for msg in fitparse.FitFile(str(path)).get_messages(["record", "hrv"]):
        values = msg.get_values()
        if msg.name == "record" and values.get("heart_rate") is not None:
            times.append(values["timestamp"].replace(tzinfo=dt.timezone.utc).timestamp())
            bpm.append(float(values["heart_rate"]))
        elif msg.name == "hrv" and times:
            n_rr += sum(1 for v in (values.get("time") or ()) if v is not None and v < 60)
    return times, bpm, n_rr


def dom_tcx(path: Path) -> tuple[list[float], list[float], int]:
    doc = xml.dom.minidom.parse(str(path))
    times, bpm = [], []
    for tp in doc.getElementsByTagName("Trackpoint"):
        hr = tp.getElementsByTagName("HeartRateBpm")
        if hr:
            times.append(_iso(tp.getElementsByTagName("Time")[0].firstChild.data))
            bpm.append(float(hr[0].getElementsByTagName("Value")[0].firstChild.data))
    return times, bpm, 0


def regex_gpx(path: Path) -> tuple[list[float], list[float], int]:
    times, bpm = [], []
    for point in re.findall(r"<trkpt.*?</trkpt>", path.read_text(encoding="utf-8"), re.S):
        hr = re.search(r"<(?:\w+:)?hr>([\d.]+)</", point)
        if hr:
            times.append(_iso(re.search(r"<time>([^<]+)</time>", point).group(1)))
            bpm.append(float(hr.group(1)))
    return times, bpm, 0


def dom_pwx(path: Path) -> tuple[list[float], list[float], int]:
    doc = xml.dom.minidom.parse(str(path))
    times, bpm = [], []
    for s in doc.getElementsByTagName("sample"):
        hr = s.getElementsByTagName("hr")
        if hr:
            times.append(float(s.getElementsByTagName("timeoffset")[0].firstChild.data))
            bpm.append(float(hr[0].firstChild.data))
    return times, bpm, 0


def lines_hrm(path: Path) -> tuple[list[float], list[float], int]:
    text = path.read_text(encoding="latin-1").replace("\r", "")
    interval = int(re.search(r"^Interval=(\d+)", text, re.M).group(1))
    rows = [int(line.split("\t")[0]) for line in text.split("[HRData]\n")[1].split("\n") if line.strip()]
    if interval == 238:  # R-R mode: beat times are the running sum, the rate 60000 / R-R
        elapsed, times = 0, []
        for rr in rows:
            elapsed += rr
            times.append(elapsed / 1000)
        return times, [60000 / rr for rr in rows], len(rows)
    kept = [(k * interval, hr) for k, hr in enumerate(rows) if hr > 0]
    return [t for t, _ in kept], [float(h) for _, h in kept], 0


def dictreader_table(path: Path) -> tuple[list[float], list[float], int]:
    """Polar Sensor Logger: ``Phone timestamp;HR [bpm]...`` (0 bpm: no skin contact) or ``...;RR-interval [ms]``."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh, delimiter=";"))
    if "HR [bpm]" in rows[0]:
        kept = [(_iso(r["Phone timestamp"]), float(r["HR [bpm]"])) for r in rows if float(r["HR [bpm]"]) > 0]
        return [t for t, _ in kept], [h for _, h in kept], 0
    times = [_iso(r["Phone timestamp"]) for r in rows]
    return times, [60000 / float(r["RR-interval [ms]"]) for r in rows], len(rows)


def hrv_logger_table(path: Path) -> tuple[list[float], list[float], int]:
    """HRV Logger's R-R export: ``timestamp, rr, since_start`` (Unix ms, ms, ms), one beat a row."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.DictReader(fh, skipinitialspace=True) if r["timestamp"]]
    return [int(r["timestamp"]) / 1000 for r in rows], [60000 / int(r["rr"]) for r in rows], len(rows)


#: file -> (independent parse, kind, device named in session.json, producer it contains, R-R kept)
SAMPLES = {
    "garmin-fenix2-run.fit": (fitparse_series, "fit", "garmin fenix2", "software 440", False),
    "garmin-fenix5-run.fit": (fitparse_series, "fit", "garmin fenix5", "software 410", True),
    "suunto-spartan.fit": (fitparse_series, "fit", "suunto 32", "", False),
    "wahoo-elemnt.fit": (fitparse_series, "fit", "wahoo_fitness 28", "software 204.92", False),
    "garmin-edge705.tcx": (dom_tcx, "tcx", "EDGE705 v2.4", "EDGE705", False),
    "garmin-forerunner405.tcx": (dom_tcx, "tcx", "Forerunner 405 Software Version 2.80", "", False),
    "garmin-oregon450.gpx": (regex_gpx, "gpx", "Oregon 450", "", False),
    "polar-s610.hrm": (lines_hrm, "hrm", "Polar S610 / S610i", "version 106", False),
    "polar-s725.hrm": (lines_hrm, "hrm", "Polar S725", "version 106", False),
    "polar-s810-rr.hrm": (lines_hrm, "hrm", "Polar S810 / S810i", "version 106", True),
    "timex-global-trainer.pwx": (dom_pwx, "pwx", "Timex Global Trainer", "winDeviceAgent", False),
    "polar-h10-sensor-logger_HR.txt": (dictreader_table, "csv", "polar-h10-sensor-logger_HR", "", False),
    "polar-h10-sensor-logger_RR.txt": (dictreader_table, "csv", "polar-h10-sensor-logger_RR", "", True),
    "polar-verity-sense-sensor-logger_HR.txt": (dictreader_table, "csv", "polar-verity-sense-sensor-logger_HR", "",
                                                False),
    "wearablehrv-rhythm_RR.csv": (hrv_logger_table, "csv", "wearablehrv-rhythm_RR", "", True),
}


def _import(tmp_path: Path, *files: Path, extra: tuple[str, ...] = ()) -> list[Path]:
    out = tmp_path / "lab"
    assert main(["import", "hr", *map(str, files), "--out", str(out), "--participant", "P01", *BODY, *extra]) == 0
    return sorted(p for p in out.iterdir() if p.is_dir())


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_real_file_imports_like_an_independent_parse(tmp_path, name):
    parse, kind, device, producer, rr_kept = SAMPLES[name]
    (folder,) = _import(tmp_path, DATA / name)
    assert validate_session(folder) == []
    session = read_session(folder)
    valid = [s for s in session.heart_rate if s.valid]
    times, bpm, n_rr = parse(DATA / name)
    assert len(valid) == len(bpm)
    assert abs(statistics.median(s.hr_bpm for s in valid) - statistics.median(bpm)) <= 1.0
    assert valid[-1].t_s - valid[0].t_s == pytest.approx(times[-1] - times[0], abs=0.01)
    assert sum(len(s.rr_ms) for s in session.heart_rate) == n_rr
    info = json.loads((folder / "session.json").read_text())
    hr_dev = info["devices"]["heart_rate"]
    assert (hr_dev["protocol"], hr_dev["device"]) == (kind, device)
    assert producer in hr_dev["producer"]
    assert info["import"]["rr_kept"] is rr_kept and info["import"]["start_time"]
    assert info["participant"]["code"] == "P01"


def test_start_time_and_registry(tmp_path):
    """The FIT's absolute start is kept (UTC) and names the folder; a new participant joins the registry,
    and a second import takes the demographics from it."""
    (folder,) = _import(tmp_path, DATA / "garmin-fenix5-run.fit")
    info = json.loads((folder / "session.json").read_text())
    assert info["import"]["start_time"] == "2017-06-11T14:34:09.000Z"
    assert folder.name == "P01_20170611-143409"
    assert "P01\tfemale" in (tmp_path / "lab" / "participants.tsv").read_text()
    assert main(["import", "hr", str(DATA / "polar-s610.hrm"), "--out", str(tmp_path / "lab"),
                 "--participant", "P01"]) == 0
    hrm = json.loads((tmp_path / "lab" / "P01_20030413-091656" / "session.json").read_text())
    assert hrm["import"]["start_time_zone"].startswith("unknown") and hrm["participant"]["mass_kg"] == 60


def test_phone_app_clocks(tmp_path):
    """A phone app's time without a zone (Polar Sensor Logger) is the phone's local time, kept without a
    zone; HRV Logger's Unix milliseconds are UTC. Both name the session folder by the file's start."""
    psl, hrvl = _import(tmp_path, DATA / "polar-verity-sense-sensor-logger_HR.txt", DATA / "wearablehrv-rhythm_RR.csv")
    assert psl.name == "P01_20220425-113902" and hrvl.name == "P01_20230630-115817"
    info = json.loads((psl / "session.json").read_text())["import"]
    assert (info["start_time"], info["start_time_zone"]) == ("2022-04-25T11:39:02.323", "unknown (device local time)")
    info = json.loads((hrvl / "session.json").read_text())["import"]
    assert (info["start_time"], info["start_time_zone"]) == ("2023-06-30T11:58:17.704Z", "UTC")
    rows = read_session(psl).heart_rate                   # the strap's 0 bpm (no contact): kept, not valid
    assert sum(not r.valid for r in rows) == 73 and all(r.hr_bpm is None for r in rows if not r.valid)


def test_hrv_logger_dates(tmp_path):
    """HRV Logger's iOS R-R export (``date, rr, since start``, dates to the second with ``+0000``, several
    beats in one second, old Mac line ends): made here in that layout from the real R-R of
    wearablehrv-rhythm_RR.csv, since the HRV Logger files found in public repositories carry no licence."""
    src = [line.split(",") for line in (DATA / "wearablehrv-rhythm_RR.csv").read_text().splitlines()[2:]]
    t0 = dt.datetime(2016, 9, 22, 20, 42, 20, tzinfo=dt.timezone.utc)
    lines = ["date, rr, since_start, window, lap"]
    for ts, rr, _ in src:
        when = t0 + dt.timedelta(milliseconds=int(ts) - int(src[0][0]))
        lines.append(f"{when:%Y-%m-%d %H:%M:%S +0000}, {int(rr)}.000000, {int(ts) - int(src[0][0])}.000000, 1, 0")
    (tmp_path / "rr.csv").write_text("\r".join(lines) + "\r")
    (folder,) = _import(tmp_path, tmp_path / "rr.csv")
    rows = read_session(folder).heart_rate
    assert len(rows) == len(src) and [r.rr_ms for r in rows] == [(float(rr),) for _, rr, _ in src]
    assert rows[-1].t_s == (int(src[-1][0]) - int(src[0][0])) // 1000    # whole seconds, as the dates say
    info = json.loads((folder / "session.json").read_text())["import"]
    assert (info["start_time"], info["start_time_zone"]) == ("2016-09-22T20:42:20.000Z", "UTC")


def _refused(capsys, tmp_path: Path, *argv: str) -> str:
    out = tmp_path / "lab"
    code = main(["import", "hr", *argv, "--out", str(out), "--participant", "P01", *BODY])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert not out.exists() or not any(out.iterdir())
    return err[0]


def test_laps_only_refused(capsys, tmp_path):
    line = _refused(capsys, tmp_path, str(DATA / "laps-only-fr60.fit"))
    assert "laps-only-fr60.fit" in line and "laps only (1 lap summary" in line


def test_not_a_heart_rate_file(capsys, tmp_path):
    line = _refused(capsys, tmp_path, str(DATA / "LICENSE-MIT-python-fitparse.txt"))
    assert "expected a heart-rate column" in line and "MIT License" in line
    (tmp_path / "x.bin").write_bytes(bytes(range(256)))
    assert "binary data that is not FIT" in _refused(capsys, tmp_path, str(tmp_path / "x.bin"))
    assert "no such file" in _refused(capsys, tmp_path, str(tmp_path / "none.fit"))


def test_empty_series(capsys, tmp_path):
    (tmp_path / "e.csv").write_text("time,HR\n")
    assert "found none" in _refused(capsys, tmp_path, str(tmp_path / "e.csv"))
    gpx = (DATA / "garmin-oregon450.gpx").read_text(encoding="utf-8")
    (tmp_path / "nohr.gpx").write_text(re.sub(r"<gpxtpx:hr>\d+</gpxtpx:hr>", "", gpx), encoding="utf-8")
    assert "expected heart-rate samples, found none" in _refused(capsys, tmp_path, str(tmp_path / "nohr.gpx"))


def test_time_going_backwards(capsys, tmp_path):
    rows = (DATA / "polar-h10-sensor-logger_HR.txt").read_text().splitlines()
    rows[5], rows[6] = rows[6], rows[5]
    (tmp_path / "back.txt").write_text("\n".join(rows) + "\n")
    line = _refused(capsys, tmp_path, str(tmp_path / "back.txt"))
    assert "back.txt" in line and "never go backwards, found sample 5" in line


def test_bpm_in_wrong_unit(capsys, tmp_path):
    """A heart-rate column in Hz (beats per second) is not taken as bpm."""
    lines = (DATA / "polar-h10-sensor-logger_HR.txt").read_text().splitlines()
    hz = [lines[0]] + [";".join([c[0], f"{int(c[1]) / 60:.3f}", *c[2:]]) for c in (x.split(";") for x in lines[1:])]
    (tmp_path / "hz.txt").write_text("\n".join(hz) + "\n")
    line = _refused(capsys, tmp_path, str(tmp_path / "hz.txt"))
    assert "hz.txt" in line and "not a bpm series" in line


def test_time_in_another_unit(capsys, tmp_path):
    """Milliseconds from the start in a column read as seconds would make a 23-day session: refused."""
    rr = [int(line.split(",")[1]) for line in (DATA / "wearablehrv-rhythm_RR.csv").read_text().splitlines()[2:]]
    elapsed = [sum(rr[:k + 1]) for k in range(len(rr))]
    (tmp_path / "ms.csv").write_text("time,RR\n" + "".join(f"{t},{r}\n" for t, r in zip(elapsed, rr)))
    line = _refused(capsys, tmp_path, str(tmp_path / "ms.csv"))
    assert "ms.csv" in line and "expected a recording of at most 1e+06 s, found 2.55" in line


def test_one_bad_file_writes_nothing(capsys, tmp_path):
    line = _refused(capsys, tmp_path, str(DATA / "polar-s610.hrm"), str(DATA / "laps-only-fr60.fit"))
    assert "laps only" in line


def test_columns_chosen_by_option(tmp_path):
    """An ambiguous table: two rate columns; --hr-col picks one, --time-col the time."""
    (tmp_path / "two.csv").write_text("secs,hr_watch,heart rate\n0,80,90\n1,82,91\n2,84,92\n")
    out = tmp_path / "lab"
    assert main(["import", "hr", str(tmp_path / "two.csv"), "--out", str(out), "--participant", "P01", *BODY,
                 "--hr-col", "heart rate", "--time-col", "secs"]) == 0
    (folder,) = [p for p in out.iterdir() if p.is_dir()]
    assert [s.hr_bpm for s in read_session(folder).heart_rate] == [90, 91, 92]


def test_invalid_rows_marked(tmp_path):
    """A 0 bpm (no contact) and a 300 bpm sample are kept as not-valid rows, never as rates."""
    (tmp_path / "gaps.csv").write_text("time,HR\n0,80\n1,0\n2,300\n3,82\n")
    (folder,) = _import(tmp_path, tmp_path / "gaps.csv")
    rows = read_session(folder).heart_rate
    assert [(r.hr_bpm, r.valid) for r in rows] == [(80, True), (None, False), (None, False), (82, True)]


def test_files_match_their_sha256sums():
    import hashlib

    lines = (DATA / "SHA256SUMS").read_text().splitlines()
    assert {line.split()[1] for line in lines} >= set(SAMPLES) | {"laps-only-fr60.fit"}
    for line in lines:
        digest, name = line.split()
        assert hashlib.sha256((DATA / name).read_bytes()).hexdigest() == digest, name
