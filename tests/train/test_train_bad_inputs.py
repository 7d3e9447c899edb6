"""Bad inputs to ``effortface train`` / ``evaluate`` found by the CLI audit: each gives exit 2 and
one line naming the file or option, the expectation and the finding, with nothing overwritten."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from effortface.cli import main
from effortface.train.dataset import synthetic_table, write_table


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return synthetic_table(n_participants=3, seconds=120, seed=5)


def _one_line(capsys: pytest.CaptureFixture, command: str, pattern: str) -> str:
    """The single stderr line of a refused command, checked against ``pattern``."""
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"effortface {command}: error: "), err
    assert re.search(pattern, err), err
    return err


def _train(args: list[str]) -> int:
    return main(["train", *args, "--max-rows", "20"])


# --------------------------------------------------------------------------- item 1: --out --force


def test_force_refuses_the_input_sessions_folder(table, tmp_path, capsys, make_session):
    lab = tmp_path / "lab"
    for _, rows in table.groupby("session"):
        make_session(lab, rows.reset_index(drop=True))
    before = sorted(p.name for p in lab.iterdir())
    assert _train([str(lab), "--out", str(lab), "--force"]) == 2
    _one_line(capsys, "train", r"--out \S+lab: expected a model folder apart from the inputs, found input")
    assert sorted(p.name for p in lab.iterdir()) == before


def test_force_refuses_the_input_table(table, tmp_path, capsys):
    csv = write_table(table, tmp_path / "t.csv")
    before = csv.read_bytes()
    assert _train(["--table", str(csv), "--out", str(csv), "--force"]) == 2
    _one_line(capsys, "train", r"--out \S+t.csv: expected a model folder apart from the inputs")
    assert csv.read_bytes() == before


def test_force_refuses_a_folder_holding_the_input(table, tmp_path, capsys):
    csv = write_table(table, tmp_path / "t.csv")
    assert _train(["--table", str(csv), "--out", str(tmp_path), "--force"]) == 2
    _one_line(capsys, "train", r"found input \S+t.csv inside it")
    assert csv.is_file()


def test_force_refuses_the_current_directory(table, tmp_path, capsys, monkeypatch):
    csv = write_table(table, tmp_path / "t.csv")
    work = tmp_path / "work"
    work.mkdir()
    (work / "keep.txt").write_text("x")
    monkeypatch.chdir(work)
    assert _train(["--table", str(csv), "--out", ".", "--force"]) == 2
    _one_line(capsys, "train", r"--out \.: expected a model folder to write, found the current directory")
    assert (work / "keep.txt").read_text() == "x"


def test_force_refuses_other_files_and_folders(table, tmp_path, capsys, make_session):
    csv = write_table(table, tmp_path / "t.csv")
    other = tmp_path / "other.txt"
    other.write_text("keep")
    assert _train(["--table", str(csv), "--out", str(other), "--force"]) == 2
    _one_line(capsys, "train", r"--out \S+other.txt: expected a model folder \(with model.json\) to "
                               r"replace, found a file")
    sessions = tmp_path / "sessions"
    for _, rows in table.groupby("session"):
        make_session(sessions, rows.reset_index(drop=True))
    assert _train(["--table", str(csv), "--out", str(sessions), "--force"]) == 2
    _one_line(capsys, "train", r"found a folder with 6 session folders")
    assert other.read_text() == "keep" and len(list(sessions.iterdir())) == 6


def test_force_replaces_a_model_folder_or_an_empty_one(tmp_path):
    from effortface.train.export import check_model_target

    model, empty = tmp_path / "model", tmp_path / "empty"
    model.mkdir()
    (model / "model.json").write_text("{}")
    empty.mkdir()
    assert check_model_target(model, force=True) == model
    assert check_model_target(empty, force=True) == empty
    assert check_model_target(tmp_path / "new") == tmp_path / "new"


# --------------------------------------------------------------------------- items 2, 3, 4, 6: tables


def _spoil(column: str, value: object, rows: slice | str = slice(0, 1)):
    """A spoiler setting ``column`` to ``value`` on some rows (a slice, or a participant code)."""
    def spoil(t: pd.DataFrame) -> pd.DataFrame:
        t[column] = t[column].astype(object) if isinstance(value, str) else t[column]
        if isinstance(rows, str):
            t.loc[t["participant"] == rows, column] = value
        else:
            t.loc[t.index[rows], column] = value
        return t
    return spoil


def _same_tl(t: pd.DataFrame) -> pd.DataFrame:
    t.loc[t["participant"] == "P02", "training_level"] = t.loc[t["participant"] == "P01", "training_level"].iloc[0]
    return t


BAD_TABLES = {
    # item 2: too few participants / training levels
    "one participant": (lambda t: t[t["participant"] == "P01"],
                        r"expected sessions of at least 3 participants with 2 or more distinct training "
                        r"levels .*found 1 participant$"),
    "two participants": (lambda t: t[t["participant"] != "P03"], r"found 2 participants$"),
    "one level without P03": (_same_tl, r"found only training level \S+ without P03$"),
    # item 3: crashes inside the fits
    "header only": (lambda t: t.iloc[:0], r"expected rows of participant-seconds, found only the header"),
    "no session id": (_spoil("session", np.nan, slice(3, 5)),
                      r"column session: expected an id on every row, found 2 empty \(first on line 5\)"),
    "no participant id": (_spoil("participant", np.nan, slice(0, 4)),
                          r"column participant: expected an id on every row, found 4 empty"),
    "t_s empty": (_spoil("t_s", np.nan, slice(1, 2)), r"column t_s: expected a finite time on every row, "
                                                      r"found nan on line 3"),
    "t_s constant": (_spoil("t_s", 0.0, slice(0, 2)), r"session P01_\S+: expected one row per t_s, found t_s 0 again"),
    "work infinite": (_spoil("w_per_kg", np.inf), r"column w_per_kg: expected values from 0 to 100 .*found inf on line 2"),
    "no work for P01": (_spoil("w_per_kg", np.nan, "P01"),
                        r"participant P01: heart-rate fit: expected >= 10 samples .*found 0$"),
    "blendshape never annotated": (_spoil("mouth_open", np.nan, slice(None)),
                                   r"blendshape mouth_open: expected key-framed weights on at least 2 seconds "
                                   r"with work and heart rate, found none \(the column is empty\)"),
    "sex x": (_spoil("sex", "x", "P01"), r"participant P01: column sex: expected one of female, male, found 'x'"),
    # item 4: silently accepted values
    "negative mass": (_spoil("mass_kg", -70.0, "P01"), r"participant P01: column mass_kg: expected a number "
                                                       r"from 15 to 300 kg, found -70"),
    "training level 99": (_spoil("training_level", 99.0, "P02"), r"P02: column training_level: .* 0 to 10, found 99"),
    "age 0": (_spoil("age", 0.0, "P01"), r"P01: column age: expected a number from 10 to 100 years, found 0"),
    "height in cm": (_spoil("height_m", 178.0, "P01"), r"column height_m: expected a number from 0.5 to 2.6 m, found 178"),
    "negative heart rate": (_spoil("hr_bpm", -5.0), r"column hr_bpm: expected values from 25 to 250 \(or empty\), "
                                                    r"found -5 on line 2"),
    "weight 5": (_spoil("mouth_open", 5.0), r"column mouth_open: expected values from 0 to 1 \(or empty\), found 5"),
    # item 6: errors found while preparing, before any progress bar
    "no heart rate in a session": (_spoil("hr_bpm", np.nan, "P02"), r"session P02_\S+: expected heart-rate values"),
    "measured HR_max below rest": (lambda t: t.assign(hr_rest_bpm=70.0, hr_max_bpm=180.0).pipe(
        _spoil("hr_max_bpm", 110.0, "P03")).pipe(_spoil("hr_rest_bpm", 115.0, "P03")),
        r"participant P03: expected hr_max_bpm > hr_rest_bpm, found 110 <= 115"),
}


@pytest.mark.parametrize("case", list(BAD_TABLES))
def test_bad_table_exit_2_with_one_line_before_any_progress(case, table, tmp_path, capsys):
    spoil, pattern = BAD_TABLES[case]
    csv = tmp_path / "bad.csv"
    spoil(table.copy()).to_csv(csv, index=False)
    assert _train(["--table", str(csv), "--out", str(tmp_path / "model")]) == 2
    _one_line(capsys, "train", r"bad.csv: .*" + pattern)
    assert not (tmp_path / "model").exists()


def test_session_without_mass_names_the_session(table, tmp_path, capsys, make_session):
    for i, (_, rows) in enumerate(table.groupby("session")):
        part = None
        if i == 1:
            first = rows.iloc[0]
            part = {k: first[k] for k in ("sex", "age", "height_m", "training_level")}
        make_session(tmp_path / "lab", rows.reset_index(drop=True), participant=part)
    assert _train([str(tmp_path / "lab"), "--out", str(tmp_path / "model")]) == 2
    _one_line(capsys, "train", r"session P01_\S+_strength: expected a mass_kg for participant P01, found none")


def test_physiology_refuses_unknown_sex_and_missing_body_values():
    from effortface.core.errors import UserError
    from effortface.synth.physiology import hr_rest_bpm, vo2max_ml_per_kg_min

    with pytest.raises(UserError, match=r"sex: expected one of female, male .*found 'x'"):
        hr_rest_bpm(30, "x", 2.0)
    with pytest.raises(UserError, match=r"mass_kg: expected a positive number for VO2max, found None"):
        vo2max_ml_per_kg_min(30, "male", 1.8, None, 2.0)  # type: ignore[arg-type]


def test_hr_check_and_face_check_raise_user_errors(table):
    from effortface.core.errors import UserError
    from effortface.train.dataset import hr_series, prepare
    from effortface.train.face_fit import check_face_table
    from effortface.train.hr_fit import check_hr_series

    prepared = prepare(table[table["participant"] != "P03"])
    with pytest.raises(UserError, match=r"^lab: expected sessions of at least 3 participants.*found 2"):
        check_hr_series(hr_series(prepared), "lab")
    with pytest.raises(UserError, match=r"^lab: blendshape eye_squint: .*found none \(the column is empty\)"):
        check_face_table(prepared.assign(eye_squint=np.nan), ["mouth_open", "eye_squint"], "lab")


def test_train_stage_refuses_too_few_participants_before_any_progress(table):
    """The Train stage's worker runs the same checks as the command line, before its first step."""
    from effortface.core.blendshapes import DEFAULT_SET
    from effortface.core.errors import UserError
    from effortface.train.train_session import TrainSettings, train_models

    steps: list[str] = []
    with pytest.raises(UserError, match=r"^lab: expected sessions of at least 3 participants.*found 2"):
        train_models(table[table["participant"] != "P03"], DEFAULT_SET, TrainSettings(), ["lab"],
                     lambda fraction, text: steps.append(text))
    assert steps == []


# --------------------------------------------------------------------------- evaluate (items 3, 5)


@pytest.fixture(scope="module")
def model(table, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("m") / "model"
    csv = write_table(table, tmp_path_factory.mktemp("t") / "lab.csv")
    assert _train(["--table", str(csv), "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("case", ["no participant id", "sex x", "header only", "no session id"])
def test_evaluate_bad_table_exit_2_with_one_line(case, model, table, tmp_path, capsys):
    spoil, pattern = BAD_TABLES[case]
    csv = tmp_path / "bad.csv"
    spoil(table.copy()).to_csv(csv, index=False)
    capsys.readouterr()
    assert main(["evaluate", str(model), "--table", str(csv)]) == 2
    _one_line(capsys, "evaluate", r"bad.csv: .*" + pattern)


def test_evaluate_refuses_default_with_a_consistent_message(table, tmp_path, capsys):
    csv = write_table(table, tmp_path / "t.csv")
    assert main(["evaluate", "default", "--table", str(csv)]) == 2
    err = _one_line(capsys, "evaluate", r"default: expected a model folder written by 'effortface train' "
                                        r"\(model.json, svr.npz\), found 'default'")
    assert "or 'default'" not in err
    assert main(["evaluate", str(csv), "--table", str(csv)]) == 2
    _one_line(capsys, "evaluate", r"t.csv: expected a model folder .*found a file$")
