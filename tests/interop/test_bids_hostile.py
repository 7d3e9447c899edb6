"""Issue 29: ``export bids`` never writes inside its inputs, cleans text cells, and a failed export
leaves nothing that looks like a dataset."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest

from effortface.core.session.folder import EventWriter, Event
from effortface.cli import main
from effortface.interop.bids import bids_text

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sessions"
SESSIONS = ("P01_20260112-093000_cardio", "P02_20260112-113700_strength")


def _lab(tmp_path: Path) -> Path:
    lab = tmp_path / "lab"
    for name in SESSIONS:
        shutil.copytree(SAMPLE / name, lab / name, ignore=shutil.ignore_patterns("video.avi", "serial", "motion"))
    return lab


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("where", ["lab", "session"])
def test_out_inside_an_input_is_refused_and_nothing_written(tmp_path, capsys, where) -> None:
    lab = _lab(tmp_path)
    before = _snapshot(lab)
    out = lab / "ds" if where == "lab" else lab / SESSIONS[0] / "ds"
    assert main(["export", "bids", str(lab), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: expected a dataset folder apart from the inputs" in err and len(err.splitlines()) == 1
    assert _snapshot(lab) == before and not out.exists()


def test_marker_text_with_tabs_newlines_and_nul_gives_a_valid_events_tsv(tmp_path, capsys) -> None:
    lab = _lab(tmp_path)
    events = lab / SESSIONS[0] / "events.csv"
    events.unlink()
    writer = EventWriter(events)
    writer.write(Event(1.0, "marker", "go\tnow\nplease", "a\0b\r\nc"))
    writer.write(Event(2.0, "marker", "\t\n", ""))
    writer.close()
    assert main(["export", "bids", str(lab), "--out", str(tmp_path / "ds")]) == 0, capsys.readouterr().err
    (tsv,) = (tmp_path / "ds").rglob("sub-P01*_events.tsv")
    text = tsv.read_text()
    assert "\0" not in text and '"' not in text
    lines = text.splitlines()
    assert all(len(line.split("\t")) == 4 for line in lines), lines
    assert lines[1].split("\t")[2:] == ["marker:go now please", "a b c"]
    assert lines[2].split("\t")[2] == "marker"
    assert bids_text("\x00\x07") == "n/a"


def test_a_failed_export_leaves_nothing_that_looks_like_a_dataset(tmp_path, capsys) -> None:
    lab = _lab(tmp_path)
    hr = lab / SESSIONS[1] / "heart_rate.csv"
    hr.write_text(hr.read_text() + "12.5,not-a-rate,,1,hxm,1\n")
    out = tmp_path / "ds"
    assert main(["export", "bids", str(lab), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "heart_rate.csv" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lab"]  # no dataset, no hidden staging folder


@pytest.mark.parametrize("bad_row", ["abc,marker,go,", "1e300,marker,go,"])
def test_a_damaged_events_csv_is_one_line_naming_file_and_line(tmp_path, capsys, bad_row) -> None:
    """events.csv is read by the session's checked reader: a time that is not a number or is outside
    the bounds names the file and line (the export read it with float() and gave a traceback)."""
    lab = _lab(tmp_path)
    events = lab / SESSIONS[0] / "events.csv"
    lines = events.read_text(encoding="utf-8").splitlines()
    events.write_text("\n".join([*lines[:2], bad_row, *lines[2:]]) + "\n", encoding="utf-8")
    assert main(["export", "bids", str(lab), "--out", str(tmp_path / "ds")]) == 2
    (err,) = capsys.readouterr().err.strip().splitlines()
    assert f"{events}: line 3: expected t_s,kind,label,value" in err, err
    assert not (tmp_path / "ds").exists()
