"""One truth per participant in Capture (issue 25 item 1), the real main window offscreen (pytest-qt)
on a copy of sample_sessions/: P01-P06 are offered, P01 typed with other demographics is refused
until "Use the record" or "Change the record" (confirmed), and the code alone records the lab's P01
from a real pseudo-terminal strap."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets

from effortface.capture_tool.participants import REGISTRY_TSV, read_history, read_registry
from effortface.core.session.folder import Participant

from .test_capture_stage_daily import _choose, _end, _record, _stop, _strap
from .conftest import capture_stage_on
from .test_participant_truth import LAB_P01, copy_sample_lab
from effortface.capture_tool.replay import start_replay_thread

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    return copy_sample_lab(tmp_path / "lab")


@pytest.fixture
def stage(qtbot, tmp_path: Path, lab: Path):
    yield from capture_stage_on(qtbot, lab, tmp_path / "settings.ini")


def type_wrong_p01(stage) -> None:
    """The operator types a new participant's demographics, then the code the lab's P01 has."""
    form = stage.form
    form.sex.setCurrentText("male")
    form.age.setValue(45)
    form.height_m.setValue(1.66)
    form.mass.setValue(58.0)
    form.training_level.setValue(8)
    form.code.setText("P01")


def _new_p01_sessions(lab: Path) -> list[Path]:
    return [p for p in lab.glob("P01_*") if p.name not in ("P01_20260112-093000_cardio", "P01_20260119-140000_strength")]


def test_the_labs_participants_are_offered_from_its_sessions(stage) -> None:
    form = stage.form
    assert [form.registry.itemText(i) for i in range(1, form.registry.count())] == [
        "P01", "P02", "P03", "P04", "P05", "P06"]
    form.code.setText("P01")
    assert form.values() == {**LAB_P01.__dict__, "hr_rest_bpm": None, "hr_max_bpm": None}
    assert form.record.isVisible() and "sex female, age 23" in form.record.text()


def test_p01_with_other_demographics_is_refused_until_a_choice(qtbot, stage, lab: Path, monkeypatch) -> None:
    replay = _strap(30.0)
    _choose(qtbot, stage, replay.path)
    type_wrong_p01(stage)
    form = stage.form
    # the typed values are kept, the lab's record is shown beside them, what differs in red
    assert form.values()["sex"] == "male" and form.sex.isEnabled()
    # side by side, once: each differing field's box holds the typed value, the lab's record beside it
    hints = {f: h.text() for f, h in form.record_hints.items() if h.isVisible()}
    assert hints == {"sex": "lab record: female", "age": "lab record: 23", "training_level": "lab record: 2.5"}
    assert form.record.text() == "sex female, age 23, height 1.66, mass 58, training level 2.5"
    assert form.confirmed.text() == ("Sex, Age, Training level differ from the lab's record (beside each; from "
                                     "P01_20260119-140000_strength/session.json): Use the record, or Change "
                                     "the record.")
    assert "#b00020" in form._row_labels["sex"].styleSheet() and "#b00020" not in form._row_labels["mass_kg"].styleSheet()
    assert not form._row_labels["sex"].text().startswith("\u2714")  # no tick on a field that conflicts
    assert form.use_record.isEnabled() and form.change_record.isEnabled()
    qtbot.mouseClick(stage.record_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.wait(200)
    assert not stage.session.recording and stage.session.state == "idle"
    # the conflict is stated once, in the form (record beside each typed value): the banner points to it
    assert stage.banner_text() == "Record refused: see the participant form"
    assert form.message.text() == ""  # not a second time in the form
    assert _new_p01_sessions(lab) == [] and not (lab / REGISTRY_TSV).exists()
    # "Use the record": the form takes the lab's P01, the refusal goes, and Record records it
    qtbot.mouseClick(form.use_record, QtCore.Qt.MouseButton.LeftButton)
    assert form.conflicts() == [] and stage.banner_text() == ""
    path = _record(qtbot, stage)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 2, timeout=10_000)
    _stop(qtbot, stage)
    _end(replay, thread)
    stored = json.loads((path / "session.json").read_text())["participant"]
    assert stored == {"code": "P01", "sex": "female", "age": 23, "height_m": 1.66, "mass_kg": 58.0,
                      "training_level": 2.5}
    assert not (lab / REGISTRY_TSV).exists()  # the record was used, nothing rewritten


def test_change_the_record_asks_then_records_and_keeps_the_old_one(qtbot, stage, lab: Path, monkeypatch) -> None:
    replay = _strap(30.0)
    _choose(qtbot, stage, replay.path)
    type_wrong_p01(stage)
    asked: list[str] = []
    answers = iter([QtWidgets.QMessageBox.StandardButton.No, QtWidgets.QMessageBox.StandardButton.Yes])
    monkeypatch.setattr(QtWidgets.QMessageBox, "question",
                        lambda parent, title, text, *a: (asked.append(text), next(answers))[1])
    form = stage.form
    assert not form.ask_change_record() and not form.update_record  # "No": nothing changes
    qtbot.mouseClick(form.change_record, QtCore.Qt.MouseButton.LeftButton)
    assert form.update_record and form.conflicts() == []
    assert "Change the lab's record of P01 from sex female to male, age 23 to 45, training level 2.5 to 8" in asked[-1]
    path = _record(qtbot, stage)
    thread = start_replay_thread(replay)
    qtbot.waitUntil(lambda: stage.live.n_samples() >= 2, timeout=10_000)
    _stop(qtbot, stage)
    _end(replay, thread)
    new = Participant("P01", "male", 45, 1.66, 58.0, 8)
    assert json.loads((path / "session.json").read_text())["participant"]["sex"] == "male"
    assert read_registry(lab / REGISTRY_TSV)["P01"] == new
    assert [old for old, _ in read_history(lab)] == [LAB_P01]
    # earlier sessions keep the values they were recorded with
    assert json.loads((lab / "P01_20260112-093000_cardio" / "session.json").read_text())["participant"]["sex"] == "female"
    assert not form.update_record  # the choice was for that recording only
