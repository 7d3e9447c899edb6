"""``effortface export bids`` of the sample lab passes the BIDS rules that apply: file names and
entities, required sidecar keys (SamplingFrequency, StartTime, Columns), TSV headers, participants."""

from __future__ import annotations

import csv
import gzip
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.capture_tool.session import list_sessions, read_session
from effortface.train.interop.bids import bids_label, export_bids

ROOT = Path(__file__).resolve().parents[3]
SAMPLE = ROOT / "sample_sessions"
#: BIDS file names of this export: entities in the specification's order, alphanumeric labels
NAME_RE = re.compile(r"^sub-(?P<sub>[A-Za-z0-9]+)_ses-(?P<ses>[A-Za-z0-9]+)_task-[A-Za-z0-9]+"
                     r"(_recording-[A-Za-z0-9]+_physio\.(tsv\.gz|json)|_events\.(tsv|json))$")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bids") / "ds"
    done = subprocess.run([sys.executable, "-m", "effortface", "export", "bids", SAMPLE, "--out", out],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()) == out
    return out


def _tsv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh, delimiter="\t"))


def test_top_level_files(dataset):
    desc = json.loads((dataset / "dataset_description.json").read_text())
    assert desc["Name"] and re.match(r"^\d+\.\d+\.\d+$", desc["BIDSVersion"]) and desc["DatasetType"] == "raw"
    rows = _tsv(dataset / "participants.tsv")
    assert list(rows[0])[0] == "participant_id"
    subs = sorted(p.name for p in dataset.glob("sub-*"))
    assert [r["participant_id"] for r in rows] == subs == [f"sub-P0{i}" for i in range(1, 7)]
    assert all(json.loads((dataset / "participants.json").read_text())[c] for c in list(rows[0])[1:])


def test_every_file_follows_the_naming_rules(dataset):
    files = [p for p in dataset.rglob("*") if p.is_file() and p.parent != dataset]
    assert len(files) == 12 * 6
    for f in files:
        m = NAME_RE.match(f.name)
        assert m, f.name
        rel = f.relative_to(dataset).parts
        assert rel[:3] == (f"sub-{m['sub']}", f"ses-{m['ses']}", "beh")   # folder entities = file entities


def test_physio_files_and_sidecars(dataset):
    sessions = {p.name: p for p in list_sessions(SAMPLE)}
    physio = sorted(dataset.rglob("*_physio.tsv.gz"))
    assert len(physio) == 24
    for data in physio:
        sidecar = json.loads(data.with_name(data.name.replace(".tsv.gz", ".json")).read_text())
        assert {"SamplingFrequency", "StartTime", "Columns"} <= set(sidecar)
        assert sidecar["SamplingFrequency"] > 0 and isinstance(sidecar["StartTime"], float)
        lines = gzip.decompress(data.read_bytes()).decode().splitlines()
        assert lines and not re.search(r"[A-Za-z]", lines[0].replace("n/a", ""))     # no header row
        values = np.array([[np.nan if v == "n/a" else float(v) for v in ln.split("\t")] for ln in lines])
        assert values.shape[1] == len(sidecar["Columns"])
        assert all(sidecar[c]["Units"] for c in sidecar["Columns"])
        if "heartrate" in data.name:
            assert 40 < np.nanmedian(values) < 200
    one = next(dataset.rglob("sub-P06_ses-20260121125500_task-cardio_recording-heartrate_physio.tsv.gz"))
    hr = [s for s in read_session(sessions["P06_20260121-125500_cardio"]).heart_rate if s.valid]
    got = np.array([float(v) for v in gzip.decompress(one.read_bytes()).decode().split() if v != "n/a"])
    assert got.min() >= min(s.hr_bpm for s in hr) - 1e-6 and got.max() <= max(s.hr_bpm for s in hr) + 1e-6


def test_events_tsv(dataset):
    for events in dataset.rglob("*_events.tsv"):
        rows = _tsv(events)
        assert list(rows[0])[:2] == ["onset", "duration"]
        for r in rows:
            float(r["onset"])
            assert r["duration"] == "n/a" or float(r["duration"]) >= 0
        assert any(r["trial_type"].startswith("phase_start") for r in rows)


def test_labels_are_sanitised_and_collisions_refused(tmp_path):
    assert bids_label("LAB2-07") == "LAB207"
    with pytest.raises(Exception, match="expected letters or digits"):
        bids_label("--")
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "x").write_text("keep")
    with pytest.raises(Exception, match=r"--out .*ds: expected a new or empty folder"):
        export_bids(SAMPLE, tmp_path / "ds")
    assert (tmp_path / "ds" / "x").read_text() == "keep"


def test_colliding_participant_labels_are_refused(tmp_path):
    import shutil

    src = SAMPLE / "P01_20260112-093000_cardio"
    for code in ("LAB2-07", "LAB20-7"):
        dst = tmp_path / "lab" / f"{code}_20260112-093000_cardio"
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns("video.avi", "serial"))
        doc = json.loads((dst / "session.json").read_text())
        doc["participant"]["code"], doc["session_id"] = code, dst.name
        (dst / "session.json").write_text(json.dumps(doc))
    with pytest.raises(Exception, match=r"participant 'LAB20-7' becomes BIDS label 'LAB207', as does 'LAB2-07'"):
        export_bids(tmp_path / "lab", tmp_path / "ds")
    assert not (tmp_path / "ds").exists()
