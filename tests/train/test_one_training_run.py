"""One function per job between the command line and the GUI: the training run
(:func:`effortface.train.pipeline.train_models`), its export and report
(:func:`~effortface.train.pipeline.export_outcome`), the evaluation
(:func:`effortface.train.evaluation.evaluate_bundle`) and the curve writer
(:func:`effortface.synth.curves_io.write_curve_chunks`, which ``write_curves`` calls) each exist
once, and both paths call them.

Each function is replaced, wherever a loaded ``effortface`` module holds it, by a spy that counts
the call and runs the real function; the CLI commands and the GUI models (``TrainSession``,
``SynthSession``) then run for real. ``effortface demo`` is checked the same way in
tests/commands/test_demo.py (:func:`spy_on_jobs`).
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from effortface.cli import main
from effortface.train.dataset import synthetic_table, write_table

CLIP = "motion/cmu_13_29_jumping_jacks_120fps.bvh"






@pytest.fixture(scope="module")
def table_csv(tmp_path_factory) -> Path:
    table = synthetic_table(n_participants=3, seconds=200, seed=5)
    return write_table(table, tmp_path_factory.mktemp("lab") / "lab.csv")


def test_cli_and_train_stage_run_the_same_training_and_export(table_csv: Path, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch, spy_on_jobs) -> None:
    from effortface.train.train_session import TrainSession

    calls = spy_on_jobs(monkeypatch)
    cli_model = tmp_path / "cli"
    assert main(["train", "--table", str(table_csv), "--out", str(cli_model), "--max-rows", "40"]) == 0
    assert calls == {"train_models": 1, "export_outcome": 1, "evaluate_bundle": 0, "write_curve_chunks": 0}

    session = TrainSession(tmp_path / "no-sessions")
    session.load_table(table_csv)
    session.set_settings(max_rows_per_participant=40)
    session.start_training()
    session.wait(300)
    assert session.outcome is not None
    gui_model = tmp_path / "gui"
    session.export(gui_model)
    session.wait(300)
    assert calls == {"train_models": 2, "export_outcome": 2, "evaluate_bundle": 0, "write_curve_chunks": 0}

    # same data and settings -> the same model, whichever path trained it
    assert (cli_model / "svr.npz").read_bytes() == (gui_model / "svr.npz").read_bytes()
    cli_doc, gui_doc = (json.loads((m / "model.json").read_text()) for m in (cli_model, gui_model))
    assert cli_doc["metrics"] == gui_doc["metrics"]
    assert cli_doc["provenance"]["sources"] == gui_doc["provenance"]["sources"] == [str(table_csv)]

    assert main(["evaluate", str(gui_model), "--table", str(table_csv)]) == 0
    assert calls["evaluate_bundle"] == 1


def test_synth_cli_and_synthesize_stage_write_with_the_same_writer(shared_data: Path, tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch, spy_on_jobs) -> None:
    from effortface.synth.synth_session import SynthSession

    calls = spy_on_jobs(monkeypatch)
    for fmt in ("csv", "livelink"):
        assert main(["synth", "default", str(shared_data / CLIP), "--format", fmt,
                     "--out", str(tmp_path / f"cli-{fmt}.csv")]) == 0
    assert calls["write_curve_chunks"] == 2
    session = SynthSession()
    session.load_motion(shared_data / CLIP)
    for fmt in ("csv", "livelink"):
        session.export(tmp_path / f"gui-{fmt}.csv", fmt)
    assert calls["write_curve_chunks"] == 4  # the stage writes whole curves through the same writer
    # the default character and model on the same clip: the same files
    cli = pd.read_csv(tmp_path / "cli-csv.csv")
    gui = pd.read_csv(tmp_path / "gui-csv.csv")
    assert list(cli.columns) == list(gui.columns)
    np.testing.assert_allclose(cli.to_numpy(), gui.to_numpy(), rtol=1e-9, atol=1e-12)
    assert (tmp_path / "cli-livelink.csv").read_text() == (tmp_path / "gui-livelink.csv").read_text()


def test_the_fold_count_rule_is_the_face_fits() -> None:
    """FaceFitConfig.n_folds (the progress bars' count) is the number of splits cv_folds makes."""
    from effortface.train.face_fit import FaceFitConfig, cv_folds

    for n_people, cv in ((3, "lopo"), (8, "lopo"), (11, "lopo"), (4, "kfold")):
        config = FaceFitConfig(cv=cv)
        data = SimpleNamespace(groups=np.repeat([f"P{i}" for i in range(n_people)], 10))  # all cv_folds reads
        folds = cv_folds(data, config.cv, config.n_splits, config.seed, config.max_folds)  # type: ignore[arg-type]
        assert len(folds) == config.n_folds(n_people)
