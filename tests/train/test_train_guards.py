"""Train guards the trainer (issue 25 item 5): sessions without annotations or too short are greyed
with the reason and never ticked; run-log lines carry the time they happened; a choice at the grid's
edge is warned about (with a wider grid one click away); no raw 'nan' in the tables."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PySide6 import QtCore

from effortface.train.gui.train_stage import QtTrainStage, _fmt
from effortface.train.run_log import grid_edge_warnings
from effortface.train.train_session import MIN_TRAIN_S, TrainSession

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sessions"
OK, BARE, SHORT = "P01_20260112-093000_cardio", "P02_20260119-121100_cardio", "P03_20260113-094400_cardio"


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    """Three real sample sessions: one fine, one without annotations, one cut to 42 s of video
    (and its participant's training level not recorded)."""
    lab = tmp_path / "lab"
    skip = shutil.ignore_patterns("video.avi", "serial")
    shutil.copytree(SAMPLE / OK, lab / OK, ignore=skip)
    shutil.copytree(SAMPLE / BARE, lab / BARE, ignore=shutil.ignore_patterns("video.avi", "serial", "annotations"))
    shutil.copytree(SAMPLE / SHORT, lab / SHORT, ignore=skip)
    frames = (lab / SHORT / "video_frames.csv").read_text().splitlines()
    kept = [frames[0]] + [r for r in frames[1:] if float(r.split(",")[1]) <= 42.0]
    (lab / SHORT / "video_frames.csv").write_text("\n".join(kept) + "\n")
    info = json.loads((lab / SHORT / "session.json").read_text())
    del info["participant"]["training_level"]
    (lab / SHORT / "session.json").write_text(json.dumps(info))
    return lab


def test_unusable_sessions_say_why_and_are_never_selected(lab: Path) -> None:
    session = TrainSession(lab)
    why = {e.session_id: e.unusable for e in session.entries}
    assert why[OK] == ""
    assert why[BARE] == "no annotations: key it in Annotate first"
    assert why[SHORT] == f"too short: 42 s of video (at least {MIN_TRAIN_S:.0f} s to train on)"
    said: list[str] = []
    session.status_changed.connect(lambda text, error: said.append(text))
    session.set_selected([OK, BARE, SHORT])
    assert session.selected == {OK}
    assert said == [f"not ticked: {BARE} and 1 more: no annotations: key it in Annotate first"]


def test_the_picker_greys_them_with_the_reason_and_use_shown_skips_them(qtbot, lab: Path) -> None:
    view = QtTrainStage(TrainSession(lab))
    qtbot.addWidget(view)
    table = view.picker.table
    rows = {table.item(r, 0).data(QtCore.Qt.ItemDataRole.UserRole): r for r in range(table.rowCount())}
    for sid, text in ((BARE, "no annotations"), (SHORT, "too short")):
        use = table.item(rows[sid], 0)
        assert use.text() == text and "not trained on" in use.toolTip()
        assert not use.flags() & QtCore.Qt.ItemFlag.ItemIsEnabled
        assert not use.flags() & QtCore.Qt.ItemFlag.ItemIsUserCheckable
    assert table.item(rows[OK], 0).flags() & QtCore.Qt.ItemFlag.ItemIsUserCheckable
    view.picker.select_shown_button.click()
    assert view.session.selected == {OK}
    tl_column = 3
    assert table.item(rows[SHORT], tl_column).text() == "n/a"   # training level not recorded: never 'nan'
    view.shutdown()


def test_run_log_lines_carry_the_time_they_happened() -> None:
    session = TrainSession(SAMPLE / "does-not-exist")
    t0 = session._started_s
    session._stamps.append(t0 + 1.5)
    session._stamps.append(t0 + 7.25)
    session._progress(0.1, "face CV fold 1 of 6")   # both delivered together, each with its own time
    session._progress(0.5, "face CV fold 3 of 6")
    assert session.run_log[-2].endswith("   1.50 s] face CV fold 1 of 6 (10%)")
    assert session.run_log[-1].endswith("   7.25 s] face CV fold 3 of 6 (50%)")
    assert session.run_log[-1][1:9].count(":") == 2   # and the wall-clock time, HH:MM:SS


def _grid(chosen: dict[str, tuple[float, float, float]]) -> pd.DataFrame:
    rows = []
    for name, best in chosen.items():
        for c in (1.0, 10.0):
            for g in (0.1, 0.5):
                for e in (0.05, 0.1):
                    rows.append({"blendshape": name, "C": c, "gamma": g, "epsilon": e, "CV MSE": 0.1,
                                 "chosen": "yes" if (c, g, e) == best else ""})
    return pd.DataFrame(rows)


def test_a_choice_on_the_grid_edge_is_named() -> None:
    lines = grid_edge_warnings(_grid({"mouth_open": (10.0, 0.1, 0.05), "brow_lower": (1.0, 0.5, 0.1)}))
    assert lines == ["mouth_open: C 10 is the grid's largest value, gamma 0.1 is the grid's smallest value, "
                     "epsilon 0.05 is the grid's smallest value",
                     "brow_lower: C 1 is the grid's smallest value, gamma 0.5 is the grid's largest value, "
                     "epsilon 0.1 is the grid's largest value"]
    inner = _grid({"a": (1.0, 0.1, 0.05)})
    inner = pd.concat([inner, pd.DataFrame([{"blendshape": "a", "C": 5.0, "gamma": 0.3, "epsilon": 0.07,
                                              "CV MSE": 0.05, "chosen": ""}])], ignore_index=True)
    inner["chosen"] = np.where((inner["C"] == 5.0), "yes", "")
    assert grid_edge_warnings(inner) == []
    assert grid_edge_warnings(pd.DataFrame()) == []


def test_the_wider_grid_is_one_click_away(qtbot) -> None:
    view = QtTrainStage(TrainSession(SAMPLE))
    qtbot.addWidget(view)
    view.session.grid_results = _grid({"mouth_open": (10.0, 0.1, 0.05)})
    view.session.grid_edges = grid_edge_warnings(view.session.grid_results)
    assert view.session.settings.grid == "small" and view.session.wider_grid() == "paper"
    assert view.use_wider_grid() == "paper"
    assert view.session.settings.grid == "paper" and view.settings_panel.grid.currentText() == "paper"
    assert view.session.wider_grid() == ""
    view.shutdown()


def test_tables_say_n_a_not_nan() -> None:
    assert _fmt(float("nan")) == "n/a" and _fmt(np.float64("nan")) == "n/a" and _fmt(0.28123) == "0.281"
