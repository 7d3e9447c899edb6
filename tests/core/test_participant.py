"""One participant record, one limits table: the four places that take a person's body data (the
Capture form, session.json, the training table check and the runtime's Character) accept and refuse
the same bounds."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from effortface.capture_tool.gui.participant_form import QtParticipantForm
from effortface.core.session.folder import SessionInfo, read_session_info
from effortface.core.errors import SessionFormatError, UserError
from effortface.core.participant import LIMITS, Participant
from effortface.train.dataset import DatasetError, read_table, synthetic_table, write_table
from effortface.synth.runtime import Character

#: The documented limits (README "Capturing...", effortface/core/participant.py) and,
#: per field, a step just outside them that the form's spin boxes can show (their resolution).
DOCUMENTED = {
    "age": (10, 100, 1),
    "height_m": (0.5, 2.6, 0.01),
    "mass_kg": (15, 300, 0.1),
    "training_level": (0, 10, 0.1),
    "hr_rest_bpm": (25, 120, 1),
    "hr_max_bpm": (100, 240, 1),
}
#: The form's widget for each field.
FORM_WIDGETS = {"age": "age", "height_m": "height_m", "mass_kg": "mass", "training_level": "training_level",
                "hr_rest_bpm": "hr_rest", "hr_max_bpm": "hr_max"}

CASES = [pytest.param(field, value, ok, id=f"{field}={value:g}")
         for field, (lo, hi, step) in DOCUMENTED.items()
         for value, ok in ((lo, True), (hi, True), (round(lo - step, 6), False), (round(hi + step, 6), False))]


def test_the_table_is_the_documented_one() -> None:
    assert {name: limit.bounds for name, limit in LIMITS.items()} == \
        {name: (lo, hi) for name, (lo, hi, _) in DOCUMENTED.items()}


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return synthetic_table(n_participants=1, seconds=30, seed=3)


def _accepts_session_json(tmp_path: Path, field: str, value: float) -> bool:
    data = SessionInfo("P01_20260304-050607", Participant("P01")).to_dict()
    data["participant"][field] = value
    (tmp_path / "session.json").write_text(json.dumps(data), encoding="utf-8")
    try:
        return read_session_info(tmp_path).participant.to_dict()[field] == value
    except SessionFormatError as exc:
        assert f"participant {field}: expected a number from" in str(exc)
        return False


def _accepts_table(table: pd.DataFrame, tmp_path: Path, field: str, value: float) -> bool:
    path = write_table(table.assign(**{field: value}), tmp_path / "table.csv")
    try:
        return bool((read_table(path)[field] == value).all())
    except DatasetError as exc:
        assert f"column {field}: expected a number from" in str(exc)
        return False


def _accepts_character(field: str, value: float) -> bool:
    try:
        return getattr(Character(**{field: value}), field) == value
    except UserError as exc:
        assert f"{field}: expected a number from" in str(exc)
        return False


def _accepts_form(qtbot, field: str, value: float) -> bool:
    """The form accepts a value if its spin box can hold it and the participant it builds has it."""
    form = QtParticipantForm()
    qtbot.addWidget(form)
    form.code.setText("P01")
    form.sex.setCurrentText("female")  # the required fields confirmed (the form starts empty)
    for name, valid in (("age", 30), ("height_m", 1.7), ("mass", 70.0), ("training_level", 3.0)):
        getattr(form, name).setValue(valid)
    getattr(form, FORM_WIDGETS[field]).setValue(value)
    shown = form.values()[field]
    # whatever it shows is valid; a value it cannot hold shows '-' (not confirmed: Record waits for it)
    assert form.validate() == "" or (shown is None and "expected a confirmed value" in form.validate())
    return form.participant().to_dict().get(field) == pytest.approx(value)


@pytest.mark.parametrize(("field", "value", "ok"), CASES)
def test_four_places_accept_and_refuse_the_same_bounds(qtbot, table, tmp_path, field, value, ok) -> None:
    assert {"form": _accepts_form(qtbot, field, value),
            "session.json": _accepts_session_json(tmp_path, field, value),
            "table": _accepts_table(table, tmp_path, field, value),
            "Character": _accepts_character(field, value)} == dict.fromkeys(
        ("form", "session.json", "table", "Character"), ok)


def test_form_height_is_the_widget_height(qtbot) -> None:
    """The body-height spin box no longer hides QWidget.height() (mypy found it)."""
    form = QtParticipantForm()
    qtbot.addWidget(form)
    assert isinstance(form.height(), int)
    form.height_m.setValue(1.81)
    form.code.setText("P01")
    assert form.participant().height_m == 1.81


def test_the_bounds_table_and_the_participant_limits_agree_on_body_mass():
    """One ceiling for a body mass: the segment model's check cannot accept what a participant cannot."""
    from effortface.core.bounds import BOUNDS
    from effortface.core.participant import LIMITS

    assert BOUNDS["mass_kg"].high == LIMITS["mass_kg"].bounds[1]
