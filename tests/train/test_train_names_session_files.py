"""``train`` on sessions names the user's file, not a line of its internal table, and a key on frame 10^20
is one line, not an OverflowError (issue 37)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from effortface.cli import main

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSIONS = ("P01_20260112-093000_cardio", "P02_20260119-121100_cardio")


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    out = tmp_path / "lab"
    for name in SESSIONS:
        shutil.copytree(SAMPLES / name, out / name, ignore=shutil.ignore_patterns("*.avi", "serial"))
    return out


def _refused(capsys: pytest.CaptureFixture[str], lab: Path, tmp_path: Path) -> str:
    assert main(["train", str(lab), "--out", str(tmp_path / "model"), "--max-rows", "100"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and not (tmp_path / "model").exists(), err
    return err


def test_a_work_value_out_of_range_names_the_sessions_work_csv_and_time(lab: Path, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    session = lab / SESSIONS[1]
    assert main(["work", str(session)]) == 0
    capsys.readouterr()
    work = session / "work.csv"
    lines = work.read_text().splitlines()
    cells = lines[300].split(",")
    cells[1] = "150"
    lines[300] = ",".join(cells)
    work.write_text("\n".join(lines) + "\n")
    err = _refused(capsys, lab, tmp_path)
    assert f"{SESSIONS[1]}/work.csv: column w_per_kg: expected values from 0 to 100 (or empty), found 150 at " \
           f"t_s {cells[0]} s" in err
    assert "line" not in err


def test_a_key_on_frame_1e20_is_one_line(lab: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = lab / SESSIONS[0] / "annotations" / "R2.json"
    doc = json.loads(path.read_text())
    doc["tracks"]["eye_squint"][1]["frame"] = 10 ** 20
    path.write_text(json.dumps(doc))
    err = _refused(capsys, lab, tmp_path)
    assert "annotations/R2.json: tracks.eye_squint[1]: key-frame frame: expected an integer from 0 to 1e+09, " \
           "found 100000000000000000000" in err
