"""read_curves: the per-frame CSV and the Live Link Face CSV of effortface synth, read back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.core.errors import UserError
from effortface.synth.curves_io import read_curves
from tests.conftest import ROOT

CLIP = ROOT / "tests" / "data" / "motion" / "cmu_13_29_jumping_jacks_120fps.bvh"


def test_read_curves_gives_back_what_synth_wrote(tmp_path: Path) -> None:
    csv, live = tmp_path / "f.csv", tmp_path / "f_live.csv"
    assert main(["synth", "default", str(CLIP), "--out", str(csv)]) == 0
    assert main(["synth", "default", str(CLIP), "--out", str(live), "--format", "livelink"]) == 0
    per_frame, livelink = read_curves(csv), read_curves(live)
    assert len(per_frame["t_s"]) == 439 and per_frame["t_s"][1] == pytest.approx(1 / 120)
    assert {"mouth_open", "hr_bpm", "epoc"} <= set(per_frame)
    assert np.allclose(np.diff(livelink["t_s"]), 1 / 60) and livelink["t_s"][0] == 0
    assert {"jawOpen", "mouthStretchLeft", "browDownRight", "tongueOut"} <= set(livelink)
    resampled = np.interp(livelink["t_s"], per_frame["t_s"], per_frame["eye_squint"])
    assert np.allclose(livelink["eyeSquintLeft"], resampled, atol=1e-5)


@pytest.mark.parametrize("text, expected", [
    ("time,x\n0,1\n", "expected a header starting with t_s"),
    ("t_s,mouth_open\n", "expected at least one row of values, found none"),
    ("t_s,mouth_open\n0,0.1\n0.1\n", "line 3: expected 2 values, found 1"),
    ("t_s,mouth_open\n0,abc\n", "line 2, column mouth_open: expected a number, found 'abc'"),
    ("Timecode,BlendShapeCount,JawOpen\n1:2,61,0.5\n", "line 2: expected a timecode HH:MM:SS:FF.fff, found '1:2'"),
])
def test_bad_curve_files_are_one_line_naming_the_file(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(UserError) as err:
        read_curves(path)
    assert str(err.value).startswith(str(path)) and expected in str(err.value) and "\n" not in str(err.value)


def test_a_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="expected a curves CSV"):
        read_curves(tmp_path)
