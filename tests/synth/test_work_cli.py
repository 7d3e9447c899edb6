"""``effortface work``: work.csv from motion/ and the exercise log; refusals write nothing."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from effortface.cli import main
from effortface.train.dataset import sessions_table

SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"
CARDIO = "P01_20260112-093000_cardio"
STRENGTH = "P02_20260112-113700_strength"  # has motion/ (a real CMU squats clip) for one set


def _copy(tmp_path: Path, name: str) -> Path:
    """A sample session without its video and serial log (the sample lab records no work.csv)."""
    return Path(shutil.copytree(SAMPLES / name, tmp_path / name, ignore=shutil.ignore_patterns("video.avi", "serial")))


def test_work_from_the_log_and_from_motion(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cardio, strength = _copy(tmp_path, CARDIO), _copy(tmp_path, STRENGTH)
    assert main(["work", str(cardio), str(strength)]) == 0
    out = capsys.readouterr().out.splitlines()
    # the regenerated lab (10-minute sessions): measured mean w of P01's treadmill session
    assert out[0] == f"{cardio / 'work.csv'}: 640 s: motion 0 s, log 640 s, none 0 s; mean w 7.46 W/kg"
    assert "motion 35 s" in out[1]
    work = pd.read_csv(cardio / "work.csv", keep_default_na=False)
    assert list(work.columns) == ["t_s", "w_per_kg", "p_per_kg", "source"]
    np.testing.assert_array_equal(work["t_s"], np.arange(640))
    truth = pd.read_csv(SAMPLES / "_ground_truth" / CARDIO / "physiology.csv")  # the simulator's own w
    true_w = np.interp(work["t_s"], truth["t_s"], truth["w_per_kg"])
    run = (work["source"] == "log:treadmill").to_numpy() & (true_w > 12)  # the runs (walks: below 5)
    assert run.sum() > 150
    assert work["w_per_kg"][run].mean() == pytest.approx(true_w[run].mean(), rel=0.10)
    motion = pd.read_csv(strength / "work.csv", keep_default_na=False)
    assert set(motion["source"]) == {"log:rest", "log:squats", "log:jumping_jacks", "motion:squats_set2.bvh"}


def test_a_session_without_work_csv_trains_with_no_extra_step(tmp_path: Path) -> None:
    """sessions_table (train, evaluate, the Train stage) derives the same work as ``effortface work``."""
    folder = _copy(tmp_path, CARDIO)
    derived = sessions_table([folder])
    assert main(["work", str(folder)]) == 0
    written = pd.read_csv(folder / "work.csv")
    np.testing.assert_allclose(derived["w_per_kg"], written["w_per_kg"], atol=1e-4)


def _one_error_line(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_a_hand_made_work_csv_is_kept_unless_force(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = _copy(tmp_path, CARDIO)
    (folder / "work.csv").write_text("t_s,w_per_kg,p_per_kg\n0,0.1,0.1\n1,4.2,4.0\n", encoding="utf-8")
    before = (folder / "work.csv").read_bytes()
    assert main(["work", str(folder)]) == 2
    assert _one_error_line(capsys) == (f"effortface work: error: {folder / 'work.csv'}: expected no work.csv "
                                       f"(it may be hand-made), found one; use --force to replace it")
    assert (folder / "work.csv").read_bytes() == before
    assert main(["work", str(folder), "--force"]) == 0
    assert (folder / "work.csv").read_text().startswith("t_s,w_per_kg,p_per_kg,source\n")


def _spoil(folder: Path, rows: str) -> None:
    (folder / "events.csv").write_text("t_s,kind,label,value\n" + rows, encoding="utf-8")


BAD = {
    "neither": ("0,sync,session_start,\n",
                r"{f}: expected a motion/ folder \(motion.json\) or exercise phases \(phase_start rows in "
                r"events.csv\) to derive work, found neither"),
    "unknown exercise": ("0,phase_start,zumba,\n",
                         r"{f}/events.csv: line 2: exercise 'zumba': expected an id of the catalog "
                         r"\S+exercise_catalog.csv \(rest, "),
    "negative speed": ("0,phase_start,treadmill,\n0,speed,treadmill,-2\n",
                       r"{f}/events.csv: line 3: speed treadmill: expected a number >= 0 m/s, found '-2'"),
    "negative load": ("0,phase_start,squats,\n0,load,back_kg,-10\n",
                      r"{f}/events.csv: line 3: load back_kg: expected a number >= 0 kg, found '-10'"),
    "no speed": ("0,phase_start,treadmill,\n",
                 r"{f}/events.csv: line 2: exercise 'treadmill' \(treadmill in \S+\): expected a speed row"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_sessions_exit_2_with_one_line_and_write_nothing(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                            case: str) -> None:
    good, bad = _copy(tmp_path, STRENGTH), _copy(tmp_path, CARDIO)
    rows, message = BAD[case]
    _spoil(bad, rows)
    assert main(["work", str(good), str(bad)]) == 2
    assert re.match("effortface work: error: " + message.format(f=bad),
                    _one_error_line(capsys))
    assert not (good / "work.csv").exists() and not (bad / "work.csv").exists()
