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
def test_demo_runs_the_whole_pipeline(lab, tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--capture-seconds", "4", "--max-rows", "60"]) == 0
    printed = capsys.readouterr().out.strip().splitlines()
    assert printed[-1] == f"report: {out / 'model' / 'report' / 'report.md'}"
    assert (out / "model" / "report" / "report.md").is_file()
    # capture through the pseudo-terminal recorded real decoded samples, and decode agrees
    captured = next((out / "captured").iterdir())
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


def test_demo_refuses_an_existing_out(lab, tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"--out {tmp_path}: expected a new folder, found an existing one (pass --force)" in err


def test_demo_needs_sessions(tmp_path, capsys):
    assert main(["demo", "--lab", str(tmp_path), "--out", str(tmp_path / "d")]) == 2
    assert "expected session folders, found none" in capsys.readouterr().err


def test_default_out_is_a_fresh_timestamped_folder(tmp_path, monkeypatch):
    import argparse

    from effortface.commands.demo import _out_dir

    monkeypatch.chdir(tmp_path)
    out = _out_dir(argparse.Namespace(out=None, force=False))
    assert out.name.startswith("effortface-demo-") and not out.exists()
    forced = tmp_path / "old"
    (forced / "x").mkdir(parents=True)
    assert _out_dir(argparse.Namespace(out=str(forced), force=True)) == forced and not forced.exists()
