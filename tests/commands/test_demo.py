"""``effortface demo``: the whole pipeline on the sample lab (real pty replay, capture, decode, train,
evaluate, synthesize), and its refusal to overwrite."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from effortface.cli import main

SAMPLE_LAB = Path(__file__).resolve().parents[2] / "sample_sessions"


@pytest.fixture(scope="module")
def lab() -> Path:
    if not any(SAMPLE_LAB.glob("*/session.json")):
        pytest.skip("sample_sessions/ has no sessions yet (run sample_sessions/generate.py)")
    return SAMPLE_LAB


@pytest.mark.slow
def test_demo_runs_the_whole_pipeline(lab, tmp_path, capsys, monkeypatch, spy_on_jobs):
    calls = spy_on_jobs(monkeypatch)  # the demo trains, exports, evaluates and writes as the CLI and GUI do
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--capture-seconds", "4", "--max-rows", "60"]) == 0
    assert calls == {"train_models": 1, "export_outcome": 1, "evaluate_bundle": 1, "write_curve_chunks": 1}
    printed = capsys.readouterr().out.strip().splitlines()
    assert printed[-1] == f"report: {out / 'model' / 'report' / 'report.md'}"
    assert (out / "model" / "report" / "report.md").is_file()
    assert (out / ".effortface-demo").is_file()  # marks it as replaceable by --force
    # capture through the pseudo-terminal recorded real decoded samples, and decode agrees
    captured = next(p for p in (out / "captured").iterdir() if p.is_dir())  # beside it: participants.tsv
    live = pd.read_csv(captured / "heart_rate.csv")
    decoded = pd.read_csv(out / "decoded_heart_rate.csv")
    assert len(live) > 20 and abs(len(decoded) - len(live)) <= 1
    assert json.loads((captured / "session.json").read_text())["complete"] is True
    # the model folder, its evaluation and a synthesized clip
    assert {"model.json", "svr.npz", "face.onnx", "MODEL_CARD.md"} <= {p.name for p in (out / "model").iterdir()}
    synth = pd.read_csv(out / "synth.csv")
    assert {"mouth_stretch", "mouth_open", "eye_squint", "brow_lower", "nhr"} <= set(synth.columns)
    assert synth[["mouth_stretch", "eye_squint"]].max().max() > 0
    assert "| mouth_open |" in (out / "evaluation.md").read_text()
    # like a real lab, the sample lab records no work: effortface work derived it in the demo's copy
    assert not list(lab.glob("*/work.csv"))
    copies = sorted((out / "lab").glob("*/session.json"))
    assert len(copies) == len(list(lab.glob("*/session.json")))
    sources = {src.split(":")[0] for c in copies
               for src in pd.read_csv(c.parent / "work.csv", keep_default_na=False)["source"]}
    assert sources == {"log", "motion"}
    assert any(line.startswith("[work] effortface work: 12 sessions' work.csv derived") for line in printed)
    rater = next(line for line in printed if line.startswith("[rater] "))  # the machine rater on one session
    first = copies[0].parent
    assert rater.startswith(f"[rater] {first.name}: a face on ") and "raw machine r vs the human mean" in rater
    assert (first / "machine" / "face_landmarker.csv").is_file()
    rs = [float(part.rsplit(" ", 1)[1]) for part in rater.split("key-frames: ")[1].split(", ")]
    assert len(rs) == 4 and min(rs) >= 0.5, rater


def test_demo_rater_step_says_why_it_was_skipped(tmp_path, monkeypatch):
    import importlib.util

    from effortface.demo import rater_step

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ai_edge_litert" else real(name, *a))
    line = rater_step(tmp_path)
    assert line == "skipped: the package ai-edge-litert is not installed (no wheel for this platform)"
    assert not (tmp_path / "machine").exists()


def test_demo_refuses_an_existing_out(lab, tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["demo", "--out", str(empty)]) == 2
    err = capsys.readouterr().err
    assert f"--out {empty}: expected a new folder, found an existing one (pass --force)" in err


def test_demo_hints_force_only_where_force_would_replace(lab, tmp_path, capsys):
    """A folder --force may not replace is not answered with "pass --force" (that led to a second refusal)."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    assert main(["demo", "--out", str(mine)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "--force" not in line
    assert line.endswith(f"--out {mine}: expected a new folder or one made by effortface demo, found other files "
                         "(no .effortface-demo) (not replaced: choose another --out)")


def test_demo_needs_sessions(tmp_path, capsys):
    assert main(["demo", "--lab", str(tmp_path), "--out", str(tmp_path / "d")]) == 2
    assert "expected session folders, found none" in capsys.readouterr().err


def test_default_out_is_a_fresh_timestamped_folder(tmp_path, monkeypatch):
    from effortface.demo import MARKER, demo_out_dir, replace_out

    monkeypatch.chdir(tmp_path)
    out = demo_out_dir(None)
    assert out.name.startswith("effortface-demo-") and not out.exists()
    forced = tmp_path / "old"
    (forced / "x").mkdir(parents=True)
    (forced / MARKER).write_text("")  # a previous demo output
    assert demo_out_dir(str(forced), force=True) == forced
    assert (forced / "x").is_dir()  # nothing removed until every option is checked
    replace_out(forced)
    assert [p.name for p in forced.iterdir()] == [MARKER]


def _precious(folder: Path) -> dict[str, bytes]:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "model.json").write_bytes(b"{}")
    (folder / "sub").mkdir(exist_ok=True)
    (folder / "sub" / "data.csv").write_bytes(b"a,b\n1,2\n")
    return _snapshot(folder)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize(("options", "message"), [
    (["--capture-seconds", "0"], "--capture-seconds: expected seconds above 0, found 0"),
    (["--capture-seconds", "-1"], "--capture-seconds: expected seconds above 0, found -1"),
    (["--capture-seconds", "nan"], "--capture-seconds: expected seconds above 0, found nan"),
    (["--max-rows", "-1"], "--max-rows: expected at least 20 (as effortface train), found -1"),
    (["--max-rows", "19"], "--max-rows: expected at least 20 (as effortface train), found 19"),
])
def test_bad_options_are_refused_before_out_is_touched(lab, tmp_path, capsys, options, message):
    """A bad option is named up front: --force removes nothing and no half-made --out is left."""
    kept = tmp_path / "labcopy2"
    before = _precious(kept)
    assert main(["demo", "--out", str(kept), "--force", *options]) == 2
    assert message in _one_line(capsys.readouterr().err)
    assert _snapshot(kept) == before
    fresh = tmp_path / "fresh"
    assert main(["demo", "--out", str(fresh), *options]) == 2
    assert message in _one_line(capsys.readouterr().err)
    assert not fresh.exists()


def test_force_refuses_a_folder_not_made_by_demo(lab, tmp_path, capsys):
    kept = tmp_path / "labcopy2"
    before = _precious(kept)
    assert main(["demo", "--out", str(kept), "--force"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert f"--out {kept}: expected a new folder or one made by effortface demo, found other files " \
           "(no .effortface-demo) (not replaced: choose another --out)" in line
    assert _snapshot(kept) == before


def test_force_refuses_a_file(lab, tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_bytes(b"keep")
    assert main(["demo", "--out", str(afile), "--force"]) == 2
    assert f"--out {afile}: expected a new folder or one made by effortface demo, found a file (not replaced" \
        in _one_line(capsys.readouterr().err)
    assert afile.read_bytes() == b"keep"


def test_force_never_replaces_the_lab_or_the_current_directory(tmp_path, monkeypatch, capsys):
    from effortface.core.session.folder import Participant, SessionInfo, create_session
    from effortface.demo import MARKER

    fake_lab = tmp_path / "lab"
    create_session(fake_lab, SessionInfo("P01_20260101-100000_cardio", Participant("P01"), complete=True))
    (fake_lab / MARKER).write_text("")  # even with the marker
    before = _snapshot(fake_lab)
    for out in (fake_lab, tmp_path):
        assert main(["demo", "--lab", str(fake_lab), "--out", str(out), "--force"]) == 2
        assert "(not replaced: choose another --out)" in _one_line(capsys.readouterr().err)
    assert _snapshot(fake_lab) == before
    work = tmp_path / "work"
    work.mkdir()
    (work / MARKER).write_text("")
    (work / "mine.txt").write_text("mine")
    monkeypatch.chdir(work)
    assert main(["demo", "--lab", str(fake_lab), "--out", ".", "--force"]) == 2
    assert "found the current directory" in _one_line(capsys.readouterr().err)
    assert (work / "mine.txt").read_text() == "mine"


def test_held_out_summary_names_what_is_held_out() -> None:
    from effortface.commands.demo import held_out_summary

    metrics = {"hr": {"tl_regression": {"r": 0.95}, "per_participant": {"r": 0.91},
                      "per_participant_in_sample": {"r": 0.96}},
               "face_held_out": [{"model": "svr", "r": 0.6}, {"model": "svr", "r": 0.8},
                                 {"model": "svr_known_expressiveness", "r": 0.96}]}
    line = held_out_summary(metrics)
    assert line == ("held out (not fitted on the scored participant or session): heart rate TL model r 0.95; "
                    "own model on other sessions r 0.91; face r 0.70")
    metrics["face_held_out"] += [{"model": "svr_as_game", "r": 0.5}, {"model": "svr_as_game", "r": 0.6}]
    assert held_out_summary(metrics).endswith("face as a game uses it (NHR from work) r 0.55")
