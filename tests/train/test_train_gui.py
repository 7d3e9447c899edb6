"""The Train stage offscreen: pick part of the sample lab, train, read results, export, compare.

Drives :class:`effortface.train.gui.train_stage.QtTrainStage` with real clicks and asserts on its model
(:class:`effortface.train.train_session.TrainSession`). Reads ``sample_sessions/``, writes only to tmp_path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore

from effortface.synth.bundle import read_bundle
from effortface.train.gui.train_stage import QtTrainStage
from effortface.synth.runtime import load_model
from effortface.train.train_session import TrainSession, filter_entries

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sessions"
SESSIONS = sorted(p.parent.name for p in SAMPLE.glob("*/session.json"))
CARDIO = [s for s in SESSIONS if s.endswith("_cardio")]  # one per participant
LEFT = QtCore.Qt.MouseButton.LeftButton
TIMEOUT_MS = 60_000


@pytest.fixture
def stage(qtbot) -> QtTrainStage:
    view = QtTrainStage(TrainSession(SAMPLE))
    qtbot.addWidget(view)
    yield view
    view.shutdown()
    view.session.wait(30)


def _pick_cardio_small(stage: QtTrainStage) -> None:
    """Filter to cardio sessions, use the shown ones, 60 face rows per participant."""
    stage.picker.exercise.setCurrentIndex(stage.picker.exercise.findData("cardio"))
    stage.picker.select_shown_button.click()
    stage.settings_panel.max_rows.setValue(60)


def _train(qtbot, stage: QtTrainStage) -> None:
    qtbot.mouseClick(stage.train_button, LEFT)
    qtbot.waitUntil(lambda: not stage.session.busy and stage.train_button.isEnabled(), timeout=TIMEOUT_MS)


def test_filters_pick_part_of_the_lab(stage: QtTrainStage) -> None:
    _pick_cardio_small(stage)
    assert stage.picker.table.rowCount() == len(CARDIO) == 6
    assert stage.session.selected == set(CARDIO)
    assert stage.session.settings.max_rows_per_participant == 60
    # unchecking one row removes that session from the model's selection
    stage.picker.table.item(1, 0).setCheckState(QtCore.Qt.CheckState.Unchecked)
    assert stage.session.selected == set(CARDIO) - {CARDIO[1]}
    assert "5 sessions" in stage.picker.description.text()


def test_train_export_and_refuse_overwrite(qtbot, stage: QtTrainStage, tmp_path: Path) -> None:
    _pick_cardio_small(stage)
    _train(qtbot, stage)
    outcome = stage.session.outcome
    assert outcome is not None and outcome.sessions == CARDIO
    assert set(outcome.hr_table()["model"]) == {"per_participant", "per_participant_in_sample", "pooled_threshold",
                                                "tl_regression"}
    x, y = stage.hr_results.curves["tl"].getData()          # Fig. 2 is drawn from the results
    np.testing.assert_allclose(y, outcome.fig2(CARDIO[0])["tl"])
    assert stage.face_results.table.rowCount() == len(outcome.face.blendshapes) + 1  # + mean row
    assert stage.export_button.isEnabled()

    out = tmp_path / "model"
    assert stage.export(out)
    qtbot.waitUntil(lambda: not stage.session.busy and (out / "MODEL_CARD.md").exists(), timeout=TIMEOUT_MS)
    stage.session.poll()
    for name in ("model.json", "svr.npz", "face.onnx", "MODEL_CARD.md", "report/report.md"):
        assert (out / name).is_file(), name
    assert read_bundle(out).provenance["participants"] == [f"P0{i}" for i in range(1, 7)]
    # the card in the app: the Card tab renders the exported MODEL_CARD.md
    card = stage.card.toPlainText()
    assert stage.tabs.tabText(stage.tabs.indexOf(stage.card)) == "Card"
    assert card.startswith("Model card: effortface face-of-effort model") and "raters: humans" in card
    assert stage.card.toolTip() == str(out / "MODEL_CARD.md")
    assert load_model(out).blendshapes.names == outcome.face.blendshapes

    stamp = (out / "model.json").stat().st_mtime_ns
    stage.confirm_overwrite = lambda path: False             # the user says no: nothing changes
    assert not stage.export(out)
    assert (out / "model.json").stat().st_mtime_ns == stamp
    assert "kept" in stage.status.text()
    stage.confirm_overwrite = lambda path: True              # the user says yes: replaced
    assert stage.export(out)
    qtbot.waitUntil(lambda: not stage.session.busy, timeout=TIMEOUT_MS)
    stage.session.poll()
    assert (out / "model.json").stat().st_mtime_ns != stamp


def test_cancel_keeps_previous_state(qtbot, stage: QtTrainStage) -> None:
    stage.picker.select_shown_button.click()
    qtbot.mouseClick(stage.train_button, LEFT)
    assert stage.cancel_button.isEnabled()
    qtbot.mouseClick(stage.cancel_button, LEFT)
    qtbot.waitUntil(lambda: stage.train_button.isEnabled(), timeout=TIMEOUT_MS)
    assert stage.session.outcome is None
    assert "cancelled" in stage.status.text()
    assert not stage.export_button.isEnabled()


def test_training_without_data_shows_the_error(qtbot, stage: QtTrainStage) -> None:
    stage.picker.clear_button.click()
    assert not stage.train_button.isEnabled()                # nothing to train on: no Train
    stage.train()                                            # a script or shortcut still says why
    assert "expected at least one selected session" in stage.status.text()
    assert "b00020" in stage.status.styleSheet()             # shown as an error, in the stage
    assert stage.session.outcome is None


def test_unannotated_session_is_reported(qtbot, tmp_path: Path) -> None:
    """A session without annotations cannot be ticked (issue 25): greyed with the reason, Use shown
    leaves it out, so Train stays off instead of failing at 0 %."""
    import shutil

    src = SAMPLE / CARDIO[0]
    dst = tmp_path / CARDIO[0]
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("annotations", "video.avi", "serial"))
    session = TrainSession(tmp_path)
    view = QtTrainStage(session)
    qtbot.addWidget(view)
    view.picker.annotation.setCurrentText("not annotated")
    assert [e.session_id for e in view.picker.shown()] == [CARDIO[0]]
    view.picker.select_shown_button.click()
    assert session.selected == set() and not view.train_button.isEnabled()
    assert view.picker.table.item(0, 0).text() == "no annotations"
    assert "no annotations" in view.status.text()
    view.shutdown()


def test_train_on_a_loaded_table(qtbot, stage: QtTrainStage, tmp_path: Path) -> None:
    from effortface.train.dataset import sessions_table, write_table

    table = write_table(sessions_table([SAMPLE / s for s in CARDIO]), tmp_path / "lab.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("participant,t_s\nP01,0\n")
    assert not stage.picker.load_table(bad)
    assert "bad.csv" in stage.status.text() and "expected columns" in stage.status.text()
    assert stage.session.table_path is None                  # the previous choice stays
    assert stage.picker.load_table(table)
    assert f"table {table}" in stage.picker.description.text()
    stage.settings_panel.max_rows.setValue(60)
    _train(qtbot, stage)
    assert stage.session.outcome is not None
    assert stage.session.outcome.sources == [str(table)]
    assert stage.session.outcome.sessions == CARDIO


@pytest.fixture(scope="module")
def two_bundles(tmp_path_factory) -> tuple[Path, Path]:
    """Bundle A: cardio sessions only; bundle B: all six sessions (small settings)."""
    root = tmp_path_factory.mktemp("bundles")
    out = []
    for name, exercise in (("a", "cardio"), ("b", "any")):
        s = TrainSession(SAMPLE)
        s.set_selected([e.session_id for e in filter_entries(s.entries, exercise=exercise)])
        s.set_settings(max_rows_per_participant=60)
        s.start_training()
        s.wait(120)
        s.export(root / name)
        s.wait(120)
        assert (root / name / "model.json").is_file()
        out.append(root / name)
    return out[0], out[1]


def test_compare_two_models(qtbot, stage: QtTrainStage, two_bundles: tuple[Path, Path]) -> None:
    stage.picker.select_shown_button.click()
    for edit, path in zip(stage.comparison.paths, two_bundles):
        edit.setText(str(path))
    qtbot.mouseClick(stage.comparison.compare_button, LEFT)
    qtbot.waitUntil(lambda: stage.session.comparison is not None, timeout=TIMEOUT_MS)
    c = stage.session.comparison
    a, b = c["a"].curves, c["b"].curves
    assert c["session"] in c["sessions"] and len(c["sessions"]) == len(SESSIONS) == 12
    assert not np.allclose(a["nhr"], b["nhr"])               # different TL regressions
    table = stage.comparison.table
    headers = [table.horizontalHeaderItem(i).text() for i in range(table.columnCount())]
    assert headers[:3] == ["metric", "model A", "model B"]
    assert table.rowCount() >= 6
    assert set(stage.comparison.axes) == {"nhr", *stage.session.blendshapes.names}


def test_compare_needs_two_folders(qtbot, stage: QtTrainStage) -> None:
    stage.comparison.paths[0].setText("")
    qtbot.mouseClick(stage.comparison.compare_button, LEFT)
    assert "expected two model folders" in stage.status.text()
    assert stage.session.comparison is None


# --------------------------------------------------------------------------- fixes of the GUI audit


def test_stage_fits_a_1280_window_after_training(qtbot, stage: QtTrainStage) -> None:
    """Captions wrap and tables shrink: the stage fits beside the main window's stage list."""
    _pick_cardio_small(stage)
    _train(qtbot, stage)
    for tab in range(stage.tabs.count()):
        stage.tabs.setCurrentIndex(tab)
        assert stage.minimumSizeHint().width() <= 1100, stage.tabs.tabText(tab)


def test_export_cannot_be_cancelled_so_cancel_is_disabled(qtbot, stage: QtTrainStage,
                                                         tmp_path: Path) -> None:
    _pick_cardio_small(stage)
    _train(qtbot, stage)
    assert stage.export(tmp_path / "model")
    assert stage.session.busy and not stage.train_button.isEnabled()
    assert not stage.cancel_button.isEnabled()               # an export always finishes
    stage.session.cancel()                                   # (e.g. closing the window) says so
    assert "cannot be cancelled" in stage.status.text()
    qtbot.waitUntil(lambda: not stage.session.busy and stage.train_button.isEnabled(), timeout=TIMEOUT_MS)
    assert "exported model to" in stage.status.text()
    assert not stage.cancel_button.isEnabled()


def test_cancel_stops_a_comparison(qtbot, stage: QtTrainStage, two_bundles: tuple[Path, Path],
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Cancel is enabled while comparing, and the comparison stops at its next step."""
    import threading

    import effortface.train.train_session as ts

    release, real = threading.Event(), ts.compare_bundle

    def held_compare_bundle(*args):
        assert release.wait(TIMEOUT_MS / 1000)               # until the test has clicked Cancel
        return real(*args)

    monkeypatch.setattr(ts, "compare_bundle", held_compare_bundle)
    _pick_cardio_small(stage)
    for edit, path in zip(stage.comparison.paths, two_bundles):
        edit.setText(str(path))
    qtbot.mouseClick(stage.comparison.compare_button, LEFT)
    assert stage.cancel_button.isEnabled()
    qtbot.mouseClick(stage.cancel_button, LEFT)
    release.set()                                            # model A loads, then the job stops
    qtbot.waitUntil(lambda: not stage.session.busy and stage.train_button.isEnabled(), timeout=TIMEOUT_MS)
    assert "compare cancelled" in stage.status.text()
    assert stage.session.comparison is None


def test_rater_field_can_be_cleared_and_retyped(qtbot, stage: QtTrainStage) -> None:
    """Typing is free; the name is checked when the user is done (Enter, leaving, picking)."""
    Key = QtCore.Qt.Key
    _pick_cardio_small(stage)
    combo = stage.settings_panel.rater
    edit = combo.lineEdit()
    edit.selectAll()
    qtbot.keyClick(edit, Key.Key_Backspace)
    assert edit.text() == ""                                 # not snapped back to "mean"
    assert "b00020" not in stage.status.styleSheet()
    qtbot.keyClicks(edit, "X1")
    assert edit.text() == "X1"
    assert stage.session.settings.rater_policy == "mean"     # not written on every keystroke
    qtbot.keyClick(edit, Key.Key_Return)
    assert "X1" in stage.status.text() and "R1, R2, R3" in stage.status.text()
    assert "b00020" in stage.status.styleSheet()
    assert edit.text() == "X1" and stage.session.settings.rater_policy == "mean"
    qtbot.mouseClick(stage.train_button, LEFT)               # refused before training starts
    assert not stage.session.busy and "X1" in stage.status.text()

    edit.selectAll()
    qtbot.keyClicks(edit, "R2")
    qtbot.keyClick(edit, Key.Key_Return)
    assert stage.session.settings.rater_policy == "R2"
    assert "b00020" not in stage.status.styleSheet() and "R2" in stage.status.text()
    index = combo.findText("mean")
    combo.setCurrentIndex(index)
    combo.activated.emit(index)                              # what a user's pick emits
    assert stage.session.settings.rater_policy == "mean"
    assert [combo.itemText(i) for i in range(combo.count())] == ["mean", "R1", "R2", "R3"]


def test_compare_without_ticks_uses_the_models_sessions(qtbot, stage: QtTrainStage,
                                                        two_bundles: tuple[Path, Path]) -> None:
    """Nothing ticked: the sessions the models were trained on (said, and offered before comparing)."""
    a, b = two_bundles
    cmp = stage.comparison
    assert not stage.session.selected
    cmp.paths[0].setText(str(a))
    cmp.paths[1].setText(str(b))
    assert [cmp.choice.itemText(i) for i in range(cmp.choice.count())] == SESSIONS   # A cardio, B all
    assert "nothing ticked" in cmp.data_label.text() and "12 sessions" in cmp.data_label.text()
    cmp.paths[1].setText(str(a))                             # model A against itself: its sessions
    assert [cmp.choice.itemText(i) for i in range(cmp.choice.count())] == CARDIO
    assert "6 sessions" in cmp.data_label.text()
    cmp.choice.setCurrentText(CARDIO[2])
    qtbot.mouseClick(cmp.compare_button, LEFT)
    qtbot.waitUntil(lambda: stage.session.comparison is not None, timeout=TIMEOUT_MS)
    c = stage.session.comparison
    assert c["session"] == CARDIO[2] and c["sessions"] == CARDIO
    assert "nothing ticked" in stage.status.text() and "b00020" not in stage.status.styleSheet()
    assert "Compared on the 6 sessions the models were trained on" in cmp.data_label.text()
    assert stage.minimumSizeHint().width() <= 1100
    stage.picker.table.item(1, 0).setCheckState(QtCore.Qt.CheckState.Checked)   # ticked ones win
    assert "1 ticked session (P01)" in cmp.data_label.text()
    assert [cmp.choice.itemText(i) for i in range(cmp.choice.count())] == [SESSIONS[1]]


# --------------------------------------------------------------------------- issue 16 items 10-11


def test_train_is_enabled_only_with_something_selected(stage: QtTrainStage, tmp_path: Path) -> None:
    from effortface.train.dataset import sessions_table, write_table

    assert not stage.session.selected and not stage.train_button.isEnabled()
    assert "Tick sessions" in stage.train_button.toolTip()
    stage.picker.table.item(0, 0).setCheckState(QtCore.Qt.CheckState.Checked)
    assert stage.train_button.isEnabled()
    stage.picker.clear_button.click()
    assert not stage.train_button.isEnabled()
    assert stage.picker.load_table(write_table(sessions_table([SAMPLE / CARDIO[0]]), tmp_path / "t.csv"))
    assert stage.train_button.isEnabled()


def test_a_run_shows_no_stale_error_a_legend_a_log_and_labelled_axes(qtbot, stage: QtTrainStage) -> None:
    """Before training no legend; a new run clears an old error; after it the run log holds the
    per-fold scores, the grid search, the timings and the held-out plots; Fig. 3 has y labels."""
    assert not stage.hr_results.legend.isVisible()           # no legend for curves not drawn yet
    stage.show_status("train failed: an old error", True)
    _pick_cardio_small(stage)
    progress_texts: list[str] = []
    stage.session.progress_changed.connect(lambda f, t: progress_texts.append(t))
    qtbot.mouseClick(stage.train_button, LEFT)
    assert "b00020" not in stage.status.styleSheet() and "old error" not in stage.status.text()
    assert stage.status.text().startswith("training on 6 sessions")
    qtbot.waitUntil(lambda: not stage.session.busy and stage.train_button.isEnabled(), timeout=TIMEOUT_MS)
    assert stage.session.outcome is not None
    assert stage.hr_results.legend.isVisible() and len(stage.hr_results.legend.items) == 3
    assert any("s elapsed, about" in t and "s left" in t for t in progress_texts)   # an ETA shown
    log = stage.run_log.text.toPlainText()
    assert "face CV fold 6 of 6" in log and "train: done in" in log
    assert log.count("held out P0") == 6 and "chose C" in log
    names = stage.session.blendshapes.names
    assert stage.run_log.folds.rowCount() == 6 * len(names)   # per held-out participant and blendshape
    assert stage.run_log.folds.columnCount() == 5
    grid = stage.session.grid_results
    assert len(grid) == len(names) * 4 and (grid["chosen"] == "yes").sum() == len(names)
    assert stage.run_log.grid.rowCount() == len(grid)
    scatter = [i for i in stage.run_log.scatter.getPlotItem().listDataItems() if i.opts["symbol"]]
    assert len(scatter) == len(names) and len(scatter[0].getData()[0]) > 100
    assert all(ax.getAxis("left").labelText == "weight" for ax in stage.face_results.axes)
    assert "gamma 0.1, 0.5" in stage.settings_panel.grid.toolTip()


@pytest.fixture(scope="module")
def kfold_bundle(tmp_path_factory) -> Path:
    """A bundle of the cardio sessions scored by random-frame K-fold (small settings)."""
    out = tmp_path_factory.mktemp("kfold") / "kfold"
    s = TrainSession(SAMPLE)
    s.set_selected([e.session_id for e in filter_entries(s.entries, exercise="cardio")])
    s.set_settings(max_rows_per_participant=60, cv="kfold")
    s.start_training()
    s.wait(120)
    s.export(out)
    s.wait(120)
    assert (out / "model.json").is_file()
    return out


def test_compare_shows_cv_schemes(qtbot, stage: QtTrainStage, two_bundles: tuple[Path, Path],
                                  kfold_bundle: Path) -> None:
    """A leave-one-participant-out model beside a K-fold one: each scheme named, settings and
    chosen hyper-parameters shown, a difference column, and a new session recomputes."""
    stage.picker.exercise.setCurrentIndex(stage.picker.exercise.findData("cardio"))
    stage.picker.select_shown_button.click()
    for edit, path in zip(stage.comparison.paths, (two_bundles[0], kfold_bundle)):
        edit.setText(str(path))
    qtbot.mouseClick(stage.comparison.compare_button, LEFT)
    qtbot.waitUntil(lambda: stage.session.comparison is not None, timeout=TIMEOUT_MS)
    table = stage.comparison.table
    headers = [table.horizontalHeaderItem(i).text() for i in range(table.columnCount())]
    assert headers == ["metric", "model A", "model B", "B - A"]
    rows = {table.item(r, 0).text(): [table.item(r, c).text() for c in (1, 2, 3)]
            for r in range(table.rowCount())}
    assert rows["CV scheme"] == ["leave one participant out", "random-frame K-fold (inflated)", "differs"]
    assert rows["rater policy"] == ["mean", "mean", "same"] and rows["grid"] == ["small", "small", "same"]
    assert rows["rater source"] == ["humans", "humans", "same"]  # who labelled the face, a row of its own
    for name in stage.session.blendshapes.names:
        assert len(rows[f"{name} C / gamma / epsilon"][0].split(" / ")) == 3
    r_a, r_b, diff = rows["HR tl_regression r"]
    assert float(diff) == pytest.approx(float(r_b) - float(r_a), abs=2e-3)
    caption_text = stage.comparison.scores_caption.text()
    assert "model A by leave one participant out" in caption_text
    assert "model B by random-frame K-fold" in caption_text and "held-out participants" not in caption_text

    first = stage.session.comparison["session"]
    other = next(i for i in range(stage.comparison.choice.count())
                 if stage.comparison.choice.itemText(i) != first)
    stage.comparison.choice.setCurrentIndex(other)
    stage.comparison.choice.activated.emit(other)            # what a pick in the list sends
    qtbot.waitUntil(lambda: stage.session.comparison["session"] != first and not stage.session.busy,
                    timeout=TIMEOUT_MS)
    assert stage.session.comparison["session"] == stage.comparison.choice.itemText(other)


@pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")
@pytest.mark.parametrize("size", [(1280, 800), (1400, 900)])
def test_no_session_column_is_clipped(qtbot, stage: QtTrainStage, size: tuple[int, int]) -> None:
    stage.resize(*size)
    stage.show()
    qtbot.waitExposed(stage)
    table = stage.picker.table
    assert table.horizontalScrollBar().maximum() == 0       # every column in view
    assert table.viewport().width() >= table.horizontalHeader().length()


def test_columns_that_repeat_others_are_hidden(tmp_path: Path) -> None:
    from effortface.train.gui.train_stage import _redundant_columns
    from effortface.train.train_session import SessionEntry

    def entry(session_id: str = "P01_20260112-093000_cardio", **changes) -> SessionEntry:
        values = dict(path=tmp_path, session_id=session_id, participant="P01", exercise="cardio",
                      training_level=2.5, raters=("R1",), complete=True, tracks="R1 4/4")
        return SessionEntry(**{**values, **changes})

    all_hidden = {"participant", "exercise", "complete", "raters"}
    assert _redundant_columns([entry(), entry(raters=(), tracks="")]) == all_hidden
    assert _redundant_columns([entry(), entry("P01_20260112-093000")]) == all_hidden - {"exercise"}
    assert _redundant_columns([entry(participant="P07")]) == all_hidden - {"participant"}
    assert _redundant_columns([entry(complete=False)]) == all_hidden - {"complete"}
    assert _redundant_columns([entry(tracks="unreadable")]) == all_hidden - {"raters"}


@pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")
def test_the_stage_fits_the_main_window_at_1280x800(qtbot, tmp_path: Path, monkeypatch) -> None:
    """Beside the stage list: every session column and the Fig. 2 / Fig. 3 / comparison tables in view."""
    import shutil

    from effortface.app import MainWindow

    lab = tmp_path / "lab"
    for name in CARDIO:
        shutil.copytree(SAMPLE / name, lab / name, ignore=shutil.ignore_patterns("serial"))
    monkeypatch.setenv("EFFORTFACE_SETTINGS", str(tmp_path / "settings.ini"))
    window = MainWindow(lab, QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat))
    qtbot.addWidget(window)
    window.resize(1280, 800)
    window.show()
    qtbot.waitExposed(window)
    try:
        stage = window.show_stage("train")
        _pick_cardio_small(stage)
        _train(qtbot, stage)
        table = stage.picker.table
        shown = [table.horizontalHeaderItem(c).text() for c in range(table.columnCount())
                 if not table.isColumnHidden(c)]
        assert shown == ["use", "session", "TL", "complete tracks"]
        for tab, results in enumerate((stage.hr_results.table, stage.face_results.table, table)):
            stage.tabs.setCurrentIndex(min(tab, 1))
            qtbot.waitUntil(lambda t=results: t.isVisible())
            assert results.horizontalScrollBar().maximum() == 0
            assert results.horizontalHeader().length() <= results.viewport().width()
        assert "HR RMSE\nbpm" in [stage.hr_results.table.horizontalHeaderItem(c).text()
                                 for c in range(stage.hr_results.table.columnCount())]
        stage.tabs.setCurrentWidget(stage.run_log)
        for plot in (stage.run_log.scatter, stage.run_log.residuals):  # no plot wider than its widget
            qtbot.waitUntil(plot.isVisible)
            assert plot.getPlotItem().geometry().width() <= plot.viewport().width()
    finally:
        window.shutdown()
        stage.session.wait(30)


def test_a_refused_engine_file_is_shown_and_the_model_kept(qtbot, stage: QtTrainStage, tmp_path: Path,
                                                            monkeypatch) -> None:
    """issue 26: the stage says what was saved and what was not, as the CLI's exit status 3 does."""
    from effortface.train import export

    monkeypatch.setattr(export, "ONNX_TOL_FLOAT32", 1e-12)
    _pick_cardio_small(stage)
    _train(qtbot, stage)
    out = tmp_path / "model"
    assert stage.export(out)
    qtbot.waitUntil(lambda: not stage.session.busy and "not written" in stage.status.text(), timeout=TIMEOUT_MS)
    assert stage.status.text().startswith(f"model written to {out}") and "face.onnx (float32 engine file refused" \
        in stage.status.text()
    assert "b00020" in stage.status.styleSheet()
    assert not (out / "face.onnx").exists() and load_model(out).blendshapes.names == stage.session.outcome.face.blendshapes


def test_c_and_gamma_values_replace_the_grid(qtbot, stage: QtTrainStage) -> None:
    """issue 26: the Train stage's C and gamma fields, as effortface train --C / --gamma."""
    panel = stage.settings_panel
    assert panel.values["C"].placeholderText() == "grid's: 1 10"
    panel.values["C"].setText("0.3 3")
    assert panel.commit_values("C")
    assert stage.session.settings.c_values == (0.3, 3.0)
    assert stage.session.settings.config().grid["C"] == [0.3, 3.0]
    panel.values["gamma"].setText("0.2 zero")
    assert not panel.commit_values("gamma")
    assert stage.status.text() == "gamma values: expected positive numbers separated by spaces, found '0.2 zero'"
    panel.values["gamma"].setText("-1")
    assert not panel.commit_values("gamma")
    assert stage.status.text() == "gamma values: expected one or more positive numbers, found -1"
    assert stage.session.settings.gamma_values is None
    panel.values["C"].setText("")
    assert panel.commit_values("C") and stage.session.settings.c_values is None


def test_export_starts_in_the_labs_models_folder(tmp_path: Path, qtbot) -> None:
    lab = tmp_path / "lab"
    lab.mkdir()
    view = QtTrainStage(TrainSession(lab))
    qtbot.addWidget(view)
    try:
        start = view.export_start()
        assert start == lab.resolve() / "models" / "new_model" and start.is_absolute()
        (lab / "models" / "new_model").mkdir(parents=True)
        assert view.export_start().name == "new_model_2"  # never an existing model
    finally:
        view.shutdown()


def test_humans_plus_machine_that_adds_nothing_says_so(qtbot, stage: QtTrainStage) -> None:
    """The sample lab has no machine track: humans + machine cannot add a second, and the stage says it."""
    _pick_cardio_small(stage)
    box = stage.settings_panel.sources
    box.setCurrentIndex(box.findData("humans+machine"))
    _train(qtbot, stage)
    assert stage.session.outcome is not None, stage.status.text()
    text = stage.status.text()
    assert "; note: humans + machine added nothing: the machine labelled no second" in text
    assert "the model learnt the humans' labels alone" in text and "bold" in stage.status.styleSheet()
