"""``effortface train`` and ``effortface evaluate``: a small real run, and bad inputs -> exit 2 with
one line naming the file or option and the problem."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest

from effortface.cli import main
from effortface.train.dataset import synthetic_table, write_table


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return synthetic_table(n_participants=3, seconds=200, seed=21)


@pytest.fixture(scope="module")
def table_csv(table, tmp_path_factory) -> Path:
    return write_table(table.drop(columns=["exercise"]), tmp_path_factory.mktemp("t") / "lab.csv")


@pytest.fixture(scope="module")
def trained(table_csv, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("m") / "model"
    assert main(["train", "--table", str(table_csv), "--out", str(out), "--max-rows", "40"]) == 0
    return out


def test_train_writes_bundle_and_report(trained, capsys):
    assert {p.name for p in trained.iterdir()} >= {"model.json", "svr.npz", "face.onnx", "MODEL_CARD.md", "report"}
    report = (trained / "report" / "report.md").read_text()
    assert "fig2_nhr.png" in report and "fig3_blendshapes.png" in report
    assert (trained / "report" / "fig2_nhr.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads((trained / "model.json").read_text())
    assert set(doc["metrics"]["hr"]) == {"per_participant", "per_participant_in_sample", "pooled_threshold",
                                         "tl_regression"}
    assert doc["provenance"]["cv"] == "lopo" and doc["provenance"]["n_participants"] == 3


def test_progress_is_plain_lines_when_stderr_is_redirected(table_csv, tmp_path):
    """issue 16, 14: tqdm wrote carriage returns and escape codes into redirected logs."""
    log = tmp_path / "train.log"
    with log.open("w") as stderr:
        done = subprocess.run([sys.executable, "-m", "effortface", "train", "--table", str(table_csv),
                               "--out", str(tmp_path / "model"), "--max-rows", "40"],
                              stdout=subprocess.PIPE, stderr=stderr, text=True, timeout=600)
    text = log.read_text()
    assert done.returncode == 0, text
    assert "\r" not in text and "\x1b" not in text
    lines = [line for line in text.splitlines() if line.startswith(("train: ", "export: "))]
    assert lines[0] == "train:   5% heart-rate models" and lines[-1] == "export: 100% done", text
    assert len(lines) == len(set(lines)) and len(lines) < 60  # one per step or tenth, not per report


def test_evaluate_rescoring(trained, table_csv, capsys):
    assert main(["evaluate", str(trained), "--table", str(table_csv)]) == 0
    out = capsys.readouterr().out
    assert "## heart rate" in out and "| mouth_open |" in out
    # by default no key-frame of the scored data scales the predictions, and stdout says what did
    assert "Scaling: predictions x the mean expressiveness of the model's 3 training participants" in out
    assert "no key-frame of the scored data" in out and "borrows from the labels" not in out
    assert "## face as a game uses it" in out and "## face with the measured NHR" in out


def test_evaluate_known_expressiveness_is_an_explicit_option(trained, table_csv, capsys):
    assert main(["evaluate", str(trained), "--table", str(table_csv)]) == 0
    default = capsys.readouterr().out
    assert main(["evaluate", str(trained), "--table", str(table_csv), "--known-expressiveness"]) == 0
    known = capsys.readouterr().out
    assert "own maximal key-framed weight (--known-expressiveness: borrows from the labels" in known
    assert default.split("## face as a game")[1] != known.split("## face as a game")[1]  # scaling changed


def test_report_and_card_lead_with_the_score_as_a_game_uses_it(trained):
    card = (trained / "MODEL_CARD.md").read_text()
    report = (trained / "report" / "report.md").read_text()
    assert "**Held-out face score as a game uses it (NHR predicted from work, no measured heart rate)" in card
    assert "With the measured NHR (svr, labelled" in card and "svr_nested_measured_nhr" in card
    assert "**Held-out face score as a game uses it" in report and "With the measured NHR" in report
    assert card.index("as a game uses it") < card.index("| blendshape | model |")


def test_train_from_sessions(table, tmp_path, capsys, make_session):
    for _, rows in table.groupby("session"):
        make_session(tmp_path / "lab", rows.reset_index(drop=True), raters={"R1": 0.0, "R2": 0.05})
    out = tmp_path / "model"
    assert main(["train", str(tmp_path / "lab"), "--out", str(out), "--max-rows", "40",
                 "--rater-policy", "R2"]) == 0
    assert "report:" in capsys.readouterr().out
    assert json.loads((out / "model.json").read_text())["provenance"]["rater_policy"] == "R2"


def _sessions(make_session: Callable[..., Path], table: pd.DataFrame, root: Path, spoil: str) -> list[str]:
    for i, (_, rows) in enumerate(table.groupby("session")):
        kw = {}
        if spoil == "no_hr" and i == 0:
            kw["hr"] = False
        if spoil == "contradictory" and i == 1:
            kw["participant"] = {"sex": "male", "age": 99.0, "height_m": 1.8, "mass_kg": 80.0,
                                 "training_level": 1.0}
        folder = make_session(root, rows.reset_index(drop=True), **kw)
        if spoil == "unannotated" and i == 0:
            for f in (folder / "annotations").glob("*.json"):
                f.unlink()
    return [str(root)]


def _existing(folder: Path) -> Path:
    folder.mkdir()
    return folder


def _csv(t: pd.DataFrame, path: Path) -> str:
    t.to_csv(path, index=False)
    return str(path)


BAD = {
    "table missing a column": (
        lambda t, d, make: ["--table", _csv(t.drop(columns=["p_per_kg"]), d / "bad.csv")],
        r"bad.csv: expected columns p_per_kg"),
    "session without heart rate": (
        lambda t, d, make: _sessions(make, t, d / "lab", "no_hr"), r"heart_rate.csv: expected valid heart-rate samples, found 0"),
    "unannotated session": (
        lambda t, d, make: _sessions(make, t, d / "lab", "unannotated"), r"P01_\S+: expected key-framed annotations"),
    "contradictory participant": (
        lambda t, d, make: _sessions(make, t, d / "lab", "contradictory"), r"participant P01: expected one sex"),
    "existing --out without --force": (
        lambda t, d, make: ["--table", str(write_table(t, d / "ok.csv")), "--out", str(_existing(d / "old"))],
        r"--out \S+: expected a new model folder, found an existing one \(pass --force"),
    "neither sessions nor table": (lambda t, d, make: [], r"expected session folders or --table CSV .*found neither"),
    "unknown rater": (
        lambda t, d, make: _sessions(make, t, d / "lab", "") + ["--rater-policy", "R7"], r"expected rater 'R7'"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_inputs_exit_2_with_one_line(case, table, tmp_path, capsys, make_session):
    build, message = BAD[case]
    args = build(table.copy(), tmp_path, make_session)
    if "--out" not in args:
        args += ["--out", str(tmp_path / "model")]
    assert main(["train", *args, "--max-rows", "40"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("effortface train: error: ")
    assert pytest.importorskip("re").search(message, err), err
    assert not (tmp_path / "model").exists()


def test_evaluate_bad_model_folder(tmp_path, table_csv, capsys):
    assert main(["evaluate", str(tmp_path / "nope"), "--table", str(table_csv)]) == 2
    assert "expected a model folder" in capsys.readouterr().err


def test_random_frame_cv_only_when_asked_and_with_a_warning(table_csv, tmp_path, capsys):
    out = tmp_path / "kfold"
    assert main(["train", "--table", str(table_csv), "--out", str(out), "--max-rows", "40", "--cv", "kfold"]) == 0
    assert "--cv kfold puts neighbouring, autocorrelated seconds" in capsys.readouterr().err
    assert json.loads((out / "model.json").read_text())["provenance"]["cv"] == "kfold"


def test_one_kind_of_exercise_gives_null_unseen_exercise_scores(table, tmp_path):
    one = table.copy()
    one["exercise"] = "circuit"
    out = tmp_path / "one"
    assert main(["train", "--table", str(write_table(one, tmp_path / "one.csv")), "--out", str(out),
                 "--max-rows", "40"]) == 0
    rows = json.loads((out / "model.json").read_text())["metrics"]["face_protocols"]
    assert all(r["r"] is None for r in rows if r["protocol"] == "unseen_exercise")
    assert all(r["r"] is not None for r in rows if r["protocol"] == "unseen_participant")


def test_refused_engine_file_keeps_the_model_and_exits_3(table_csv, tmp_path, capsys, monkeypatch):
    """issue 26: a float32 face.onnx over its bound used to end the run with exit 2 and no model."""
    from effortface.train import export
    from effortface.synth.runtime import load_model

    monkeypatch.setattr(export, "ONNX_TOL_FLOAT32", 1e-12)
    out = tmp_path / "model"
    capsys.readouterr()
    assert main(["train", "--table", str(table_csv), "--out", str(out), "--max-rows", "40"]) == 3
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("effortface train:")]
    assert len(err) == 1 and err[0].startswith(f"effortface train: model written to {out} (model.json, svr.npz, "
                                               "face_f64.onnx, MODEL_CARD.md, report); not written: face.onnx "
                                               "(float32 engine file refused: "), err
    assert "found" in err[0] and "face.onnx" not in {p.name for p in out.iterdir()}
    assert load_model(out).face.predict([[1.0, 1.5, 0.5, 0.2]]).shape == (1, 4)
    assert (out / "report" / "report.md").is_file()
    doc = json.loads((out / "model.json").read_text())
    assert doc["metrics"]["engine_export"]["status"] == "refused"


def test_failed_report_keeps_the_model_and_exits_3(table_csv, tmp_path, capsys, monkeypatch):
    from effortface.train import report

    def broken(*_args, **_kwargs):
        raise ValueError("figure broke")

    monkeypatch.setattr(report, "write_report", broken)
    out = tmp_path / "model"
    capsys.readouterr()
    assert main(["train", "--table", str(table_csv), "--out", str(out), "--max-rows", "40"]) == 3
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("effortface train:")]
    assert err == [f"effortface train: model written to {out} (model.json, svr.npz, face_f64.onnx, MODEL_CARD.md); "
                   f"not written: report ({out / 'report'}: ValueError: figure broke)"]
    assert {"model.json", "svr.npz", "face.onnx", "face_f64.onnx"} <= {p.name for p in out.iterdir()}


def test_c_and_gamma_options(table_csv, tmp_path, capsys):
    out = tmp_path / "model"
    assert main(["train", "--table", str(table_csv), "--out", str(out), "--max-rows", "40", "--C", "0.5",
                 "--gamma", "0.2", "0.4"]) == 0
    doc = json.loads((out / "model.json").read_text())
    assert all(b["best"]["C"] == 0.5 for b in doc["metrics"]["face_cv"].values())
    assert all(b["best"]["gamma"] in (0.2, 0.4) for b in doc["metrics"]["face_cv"].values())
    capsys.readouterr()
    assert main(["train", "--table", str(table_csv), "--out", str(tmp_path / "m2"), "--C", "0"]) == 2
    assert capsys.readouterr().err.strip() == "effortface train: error: --C: expected one or more positive numbers, found 0"
