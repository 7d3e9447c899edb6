"""Issue 34: ``effortface work`` reads each clip with its motion.json entry's ``unit_m`` / ``up``
(else ``--unit-m`` / ``--up``, else detected) and puts it through the plausibility gate."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from effortface.cli import main

SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"
STRENGTH = "P02_20260112-113700_strength"  # motion/squats_set2.bvh: a real CMU squats clip


def _session(tmp_path: Path, **entry: object) -> Path:
    folder = Path(shutil.copytree(SAMPLES / STRENGTH, tmp_path / STRENGTH,
                                  ignore=shutil.ignore_patterns("video.avi", "serial")))
    index = folder / "motion" / "motion.json"
    doc = json.loads(index.read_text())
    doc["files"][0].update(entry)
    index.write_text(json.dumps(doc))
    return folder


def _error(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_an_entrys_unit_is_honoured_and_gated(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """unit_m 0.02 (instead of the CMU unit 0.05644) makes a 0.5 m body: refused naming the clip."""
    folder = _session(tmp_path, unit_m=0.02)
    assert main(["work", str(folder)]) == 2
    clip = folder / "motion" / "squats_set2.bvh"
    assert _error(capsys).startswith(f"effortface work: error: {clip}: standing height 0.54 m: expected 1.2-2.2 m")
    assert not (folder / "work.csv").exists()
    assert main(["work", str(folder), "--trust-skeleton"]) == 0
    assert (folder / "work.csv").exists()


def test_an_entrys_up_axis_is_honoured(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = _session(tmp_path, up="z")
    assert main(["work", str(folder)]) == 2
    assert "squats_set2.bvh: standing height 0." in _error(capsys)


def test_the_command_options_apply_to_entries_without_their_own(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    folder = _session(tmp_path)
    assert main(["work", str(folder), "--unit-m", "0.02"]) == 2
    assert "squats_set2.bvh: standing height 0.54 m" in _error(capsys)
    folder = _session(tmp_path / "own", unit_m=0.05644)  # the entry's own unit wins over --unit-m
    assert main(["work", str(folder), "--unit-m", "0.02"]) == 0, capsys.readouterr().err


def test_a_bad_entry_up_is_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = _session(tmp_path, up="sideways")
    assert main(["work", str(folder)]) == 2
    assert _error(capsys) == (f"effortface work: error: {folder / 'motion' / 'motion.json'}: files[0].up: "
                              "expected one of x, y, z, -x, -y, -z, found 'sideways'")
