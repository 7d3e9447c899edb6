"""Issue 37, "nothing dropped or shifted without a word" in ``effortface export bids``: an underivable
session's work is stated (stderr and the dataset's README) or refused with ``--skip-invalid`` as the
way on; an XDF work stream with a drop-out keeps its times; a changed participant record keeps the
earlier sessions' values (``sub-<label>_sessions.tsv``); two sessions of one participant starting in
the same second get distinct labels. Each export passes the BIDS validator with 0 errors."""

from __future__ import annotations

import csv
import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.core.session.folder import read_session
from effortface.interop.bids import regular_grid
from effortface.synth.work import derive_work, read_work_csv

from .test_bids import _validate
from .test_xdf_import import LSL_T0, SESSION, session_streams
from .xdf_writer import write_xdf

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sessions"
CARDIO, STRENGTH = "P01_20260112-093000_cardio", "P01_20260119-140000_strength"


def _effortface(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "effortface", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


def _lab(tmp_path: Path, *names: str) -> Path:
    """A lab of copies of sample sessions (no video, no serial log) with the sample participants.tsv."""
    lab = tmp_path / "lab"
    for name in names:
        shutil.copytree(SAMPLE / name, lab / name, ignore=shutil.ignore_patterns("video.avi", "serial"))
    shutil.copy(SAMPLE / "participants.tsv", lab / "participants.tsv")
    return lab


def _tsv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh, delimiter="\t"))


def _notes(stderr: str) -> list[str]:
    lines = stderr.strip().splitlines()
    assert all(line.startswith("effortface export: note: ") for line in lines), stderr
    return [line.removeprefix("effortface export: note: ") for line in lines]


def _errors(dataset: Path) -> list[dict]:
    return [i for i in _validate(dataset) if i["severity"] == "error"]


def _physio(path: Path) -> np.ndarray:
    return np.array([[np.nan if v == "n/a" else float(v) for v in line.split("\t")]
                     for line in gzip.decompress(path.read_bytes()).decode().splitlines()])


def _hr_file(tmp_path: Path) -> Path:
    """A strap export (time, bpm) made from a sample session's valid heart rate."""
    rows = [s for s in read_session(SAMPLE / CARDIO).heart_rate if s.valid and s.hr_bpm is not None]
    path = tmp_path / "strap.csv"
    path.write_text("time_s,hr\n" + "".join(f"{s.t_s:.3f},{s.hr_bpm:g}\n" for s in rows))
    return path


def test_a_session_with_nothing_to_derive_work_from_is_a_stated_omission(tmp_path):
    """Before: the work file was left out with exit 0 and no word. The session is a real import of a
    strap file (heart rate only: no exercise log, no motion); the Must show's validator check."""
    lab = _lab(tmp_path, CARDIO)
    done = _effortface("import", "hr", _hr_file(tmp_path), "--out", lab, "--participant", "P01",
                       "--time-col", "time_s", "--hr-col", "hr")
    assert done.returncode == 0, done.stderr
    imported = Path(done.stdout.strip())
    out = tmp_path / "ds"
    done = _effortface("export", "bids", lab, "--out", out)
    assert done.returncode == 0, done.stderr
    (note,) = _notes(done.stderr)
    ses = read_session(imported).info.session_id.split("_")[1].replace("-", "")
    assert note == (f"sub-P01/ses-{ses} ({imported.name}): mechanical work left out: {imported}: expected a "
                    f"motion/ folder (motion.json) or exercise phases (phase_start rows in events.csv) to derive "
                    f"work, found neither")
    readme = (out / "README").read_text()                       # the lab's files named from the lab folder
    assert readme.endswith(f"\nLeft out of this export (effortface export bids):\n\n"
                           f"- {note.replace(f'{lab}/', '')}\n") and str(tmp_path) not in readme
    assert not list((out / "sub-P01" / f"ses-{ses}").rglob("*recording-work*"))
    assert len(list(out.rglob("*recording-work_physio.tsv.gz"))) == 1            # the cardio session's
    assert _errors(out) == []


def test_an_underivable_session_is_refused_unless_skip_invalid(tmp_path):
    """Before: a session whose work could not be derived (here: its exercise log names an exercise
    the catalog does not know) was exported without its work, exit 0, no word."""
    lab = _lab(tmp_path, CARDIO, STRENGTH)
    events = lab / STRENGTH / "events.csv"
    text = events.read_text()
    exercise = next(r["label"] for r in csv.DictReader(text.splitlines()) if r["kind"] == "phase_start")
    for kind in ("phase_start", "phase_end"):
        text = text.replace(f",{kind},{exercise},", f",{kind},underwater_basket_weaving,", 1)
    events.write_text(text)
    out = tmp_path / "ds"
    done = _effortface("export", "bids", lab, "--out", out)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"effortface export: error: {events}: line 3: ") and "underwater_basket_weaving" in line
    assert line.endswith("(its mechanical work cannot be exported: fix it, or --skip-invalid to export without "
                         "it, stated in the dataset's README)")
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["lab"]
    done = _effortface("export", "bids", lab, "--out", out, "--skip-invalid")
    assert done.returncode == 0, done.stderr
    (note,) = _notes(done.stderr)
    assert note.startswith(f"sub-P01/ses-20260119140000 ({STRENGTH}): mechanical work left out: {events}: line ")
    assert f"- {note.replace(f'{lab}/', '')}\n" in (out / "README").read_text()
    assert [p.name for p in out.rglob("*recording-work_physio.tsv.gz")] == [
        "sub-P01_ses-20260112093000_task-cardio_recording-work_physio.tsv.gz"]
    assert len(list(out.rglob("*recording-heartrate_physio.tsv.gz"))) == 2     # the rest of the session stays
    assert _errors(out) == []


def test_an_unreadable_motion_clip_is_refused_unless_skip_invalid(tmp_path):
    lab = _lab(tmp_path, "P02_20260112-113700_strength")
    (clip,) = (lab / "P02_20260112-113700_strength" / "motion").glob("*.bvh")
    clip.write_bytes(clip.read_bytes()[:2000])                                  # a truncated copy
    (lab / "P02_20260112-113700_strength" / "work.csv").write_text("t_s,w_per_kg,p_per_kg\n0,1,1\n1,1,1\n")
    done = _effortface("export", "bids", lab, "--out", tmp_path / "ds")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert str(clip) in done.stderr and "--skip-invalid" in done.stderr
    done = _effortface("export", "bids", lab, "--out", tmp_path / "ds", "--skip-invalid")
    assert done.returncode == 0, done.stderr
    (note,) = _notes(done.stderr)
    assert note.startswith(f"sub-P02/ses-20260112113700 (P02_20260112-113700_strength): motion clip {clip.name} "
                           f"left out: {clip}")
    assert not (tmp_path / "ds" / "sub-P02" / "ses-20260112113700" / "motion").exists()
    assert _errors(tmp_path / "ds") == []


def test_an_xdf_work_stream_with_a_drop_out_keeps_its_times(tmp_path):
    """Before: the 1 Hz work stream with 30 s missing was written back to back at 1 Hz, so every
    sample after the drop-out was 30 s early (and the recording 30 s short)."""
    original = SAMPLE / SESSION
    streams = [s for s in session_streams(original) if s.type in ("HeartRate", "Markers", "EffortWork")]
    work = next(s for s in streams if s.type == "EffortWork")
    keep = [i for i, t in enumerate(work.stamps) if not 200 <= t - LSL_T0 < 230]
    assert len(work.stamps) - len(keep) == 30
    work.stamps, work.samples = [work.stamps[i] for i in keep], [work.samples[i] for i in keep]
    lab = tmp_path / "lab"
    p = read_session(original).participant
    done = _effortface("import", "xdf", write_xdf(tmp_path / "rec.xdf", streams), "--out", lab, "--participant",
                       "P06", "--sex", p.sex, "--mass", p.mass_kg, "--label", "cardio")
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.strip())
    saved = read_work_csv(folder / "work.csv")                                   # the import keeps the times
    assert np.diff(saved.t_s).max() == pytest.approx(31.0, abs=1e-3)
    out = tmp_path / "ds"
    done = _effortface("export", "bids", lab, "--out", out)
    assert done.returncode == 0, done.stderr
    (note,) = _notes(done.stderr)
    assert "mechanical work resampled from" in note and "drop-outs at 199-230 s" in note
    (tsv,) = out.rglob("*recording-work_physio.tsv.gz")
    sidecar = json.loads(tsv.with_name(tsv.name.replace(".tsv.gz", ".json")).read_text())
    got = _physio(tsv)
    t = sidecar["StartTime"] + np.arange(len(got)) / sidecar["SamplingFrequency"]
    assert sidecar["SamplingFrequency"] == pytest.approx(1.0) and "drop-outs at 199-230 s" in sidecar["Description"]
    assert t[-1] == pytest.approx(saved.t_s[-1], abs=0.5)                        # not 30 s short
    gap = (t > 199.5) & (t < 229.5)
    assert gap.sum() == 30 and np.isnan(got[gap]).all() and np.isfinite(got[~gap]).all()
    truth = derive_work(original)                                               # each second at its own time
    at = np.rint(t[~gap] - t[0]).astype(int) + int(round(t[0]))
    np.testing.assert_allclose(got[~gap, 0], truth.w_per_kg[at], rtol=1e-5)
    assert _errors(out) == []


def test_regular_grid_keeps_regular_series_and_places_irregular_ones():
    t = np.arange(10.0)
    v = np.c_[t, -t]
    grid, values, how = regular_grid(t, v, 1.0)
    assert how == "" and grid is t and values is v
    jitter = t + np.array([0, 0.2, -0.3, 0, 0, 0.1, 0, 0, 0, 0])
    grid, values, how = regular_grid(jitter, v, 1.0)
    np.testing.assert_array_equal(grid, t) and np.testing.assert_array_equal(values, v)
    assert "0 of 10 rows" in how and "drop-outs" not in how
    grid, values, how = regular_grid(np.r_[t[:3], t[6:]], np.r_[v[:3], v[6:]], 1.0)
    assert np.isnan(values[3:6]).all() and values[6, 0] == 6 and "drop-outs at 2-6 s" in how


def test_a_changed_participant_record_keeps_the_earlier_sessions_values(tmp_path):
    """Before: participants.tsv had one row per participant, the last session's record: the earlier
    sessions' body values (here a mass of 58 kg and an age of 23) were in no file of the dataset."""
    lab = _lab(tmp_path, CARDIO, STRENGTH)
    done = _effortface("import", "hr", _hr_file(tmp_path), "--out", lab, "--participant", "P01", "--mass", "61.5",
                       "--age", "24", "--time-col", "time_s", "--hr-col", "hr", "--update-participant")
    assert done.returncode == 0, done.stderr
    imported = Path(done.stdout.strip())
    out = tmp_path / "ds"
    done = _effortface("export", "bids", lab, "--out", out)
    assert done.returncode == 0, done.stderr
    (row,) = _tsv(out / "participants.tsv")
    assert (row["participant_id"], float(row["weight"]), float(row["age"])) == ("sub-P01", 61.5, 24.0)
    sessions = _tsv(out / "sub-P01" / "sub-P01_sessions.tsv")
    start = read_session(imported).info.session_id.split("_")[1]
    assert [(r["session_id"], r["acq_time"], float(r["weight"]), float(r["age"])) for r in sessions] == [
        ("ses-20260112093000", "2026-01-12T09:30:00", 58.0, 23.0),
        ("ses-20260119140000", "2026-01-19T14:00:00", 58.0, 23.0),
        (f"ses-{start.replace('-', '')}", f"{start[:4]}-{start[4:6]}-{start[6:8]}T{start[9:11]}:{start[11:13]}:"
                                          f"{start[13:15]}", 61.5, 24.0)]
    described = json.loads((out / "sub-P01" / "sub-P01_sessions.json").read_text())
    assert set(sessions[0]) - {"session_id"} <= set(described)
    assert _errors(out) == []


def test_two_sessions_starting_in_the_same_second_get_distinct_labels(tmp_path):
    """Before: ``ses-20260112093000`` twice: refused with a FileExistsError naming a staging folder that
    no longer existed once the command ended."""
    lab = _lab(tmp_path, CARDIO)
    twin = lab / "P01_20260112-093000_strength"
    shutil.copytree(lab / CARDIO, twin)
    doc = json.loads((twin / "session.json").read_text())
    doc["session_id"] = twin.name
    (twin / "session.json").write_text(json.dumps(doc))
    out = tmp_path / "ds"
    done = _effortface("export", "bids", lab, "--out", out)
    assert done.returncode == 0, done.stderr
    assert _notes(done.stderr) == [
        f"{CARDIO}: another session of P01 starts in the same second: exported as ses-20260112093000cardio",
        f"{twin.name}: another session of P01 starts in the same second: exported as ses-20260112093000strength"]
    assert sorted(p.name for p in (out / "sub-P01").glob("ses-*")) == ["ses-20260112093000cardio",
                                                                       "ses-20260112093000strength"]
    assert [r["session_id"] for r in _tsv(out / "sub-P01" / "sub-P01_sessions.tsv")] == [
        "ses-20260112093000cardio", "ses-20260112093000strength"]
    assert _errors(out) == []
    # labels equal once sanitised ("a-b" and "ab") cannot be told apart: one line naming both sessions
    for name in ("P01_20260112-093000_a-b", "P01_20260112-093000_ab"):
        shutil.copytree(lab / CARDIO, lab / name)
        doc["session_id"] = name
        (lab / name / "session.json").write_text(json.dumps(doc))
    done = _effortface("export", "bids", lab, "--out", tmp_path / "ds2")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert (f"{lab / 'P01_20260112-093000_ab'}: expected one BIDS session per session folder, found the same "
            f"sub-P01/ses-20260112093000ab as {lab / 'P01_20260112-093000_a-b'}") in done.stderr
    assert not (tmp_path / "ds2").exists() and not list(tmp_path.glob(".ds2*"))


def test_a_session_without_valid_heart_rate_is_a_stated_omission(tmp_path):
    """Before: an empty heart-rate physio file (no rows), exit 0, no word."""
    lab = _lab(tmp_path, CARDIO)
    path = lab / CARDIO / "heart_rate.csv"
    rows = list(csv.DictReader(path.read_text().splitlines()))
    with open(path, "w", newline="") as fh:                     # contact lost all along: valid=0, no bpm
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows({**r, "hr_bpm": "", "valid": "0"} for r in rows)
    out = tmp_path / "ds"
    done = _effortface("export", "bids", lab, "--out", out)
    assert done.returncode == 0, done.stderr
    assert _notes(done.stderr) == [f"sub-P01/ses-20260112093000 ({CARDIO}): heart rate left out: {path}: expected "
                                   f"at least 2 valid samples, found fewer"]
    assert f"heart rate left out: {CARDIO}/heart_rate.csv: expected" in (out / "README").read_text()
    assert not list(out.rglob("*recording-heartrate*")) and len(list(out.rglob("*recording-work*"))) == 2
    assert _errors(out) == []


def test_work_times_no_grid_can_hold_are_refused_not_a_huge_file(tmp_path):
    """Three samples a millisecond apart and one a day later: a 1 kHz grid would be 86 million rows."""
    lab = _lab(tmp_path, CARDIO)
    work = lab / CARDIO / "work.csv"
    work.write_text("t_s,w_per_kg,p_per_kg\n0,1,1\n0.001,1,1\n0.002,1,1\n86400,1,1\n")
    done = _effortface("export", "bids", lab, "--out", tmp_path / "ds")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert (f"{work}: t_s: expected times a grid at their median step (0.001 s) can hold in at most 10 times "
            f"their 4 rows, found 86400 s of them") in done.stderr and "--skip-invalid" in done.stderr
    done = _effortface("export", "bids", lab, "--out", tmp_path / "ds", "--skip-invalid")
    assert done.returncode == 0 and "mechanical work left out" in done.stderr
    assert not list((tmp_path / "ds").rglob("*recording-work*")) and _errors(tmp_path / "ds") == []
