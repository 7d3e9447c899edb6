"""The participant form: codes and body data only, never a personal name.

The form keeps only widget state; :meth:`QtParticipantForm.participant` builds the session module's
validated ``Participant`` and shows any problem inside the form (STYLE.md E4).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

from PySide6 import QtCore, QtWidgets

from effortface.core.errors import UserError
from effortface.core.participant import LIMITS, Limit
from effortface.capture_tool.session import CODE_RULE, SEXES, Participant, make_session_id


def preview_session_name(code: str, label: str = "", when: dt.datetime | None = None) -> str:
    """The folder name the session will get, or a template while the code or label is invalid."""
    when = when or dt.datetime.now()
    try:
        return make_session_id(code, when, label or None)
    except UserError:
        return f"{code or '<code>'}_{when.strftime('%Y%m%d-%H%M%S')}" + (f"_{label}" if label else "")


class QtParticipantForm(QtWidgets.QGroupBox):
    """Participant code, sex, age, height, mass, training level, optional measured HR rest/max.

    Parameters
    ----------
    parent : QWidget, optional
        Parent widget.
    """

    changed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Participant", parent)
        self._build()
        self._preview_timer = QtCore.QTimer(self, interval=1000)
        self._preview_timer.timeout.connect(self._update_preview)
        self._preview_timer.start()
        self._update_preview()

    def _build(self) -> None:
        form = QtWidgets.QFormLayout(self)
        self.code = QtWidgets.QLineEdit(placeholderText="P01", maxLength=16)
        self.code.setToolTip(f"Participant code: {CODE_RULE}")
        self.sex = QtWidgets.QComboBox()
        self.sex.addItems(SEXES)
        self.age = _spin("age", 30)
        # not ``self.height``: that would hide QWidget.height() (mypy found it)
        self.height_m = _dspin("height_m", 1.75, 0.01, 2)
        self.mass = _dspin("mass_kg", 70.0, 0.5, 1)
        self.training_level = _dspin("training_level", 3.0, 0.5, 1)
        self.hr_rest = _optional_hr("hr_rest_bpm")
        self.hr_max = _optional_hr("hr_max_bpm")
        self.label = QtWidgets.QLineEdit(placeholderText="optional, e.g. treadmill", maxLength=32)
        self.session_preview = QtWidgets.QLabel(textFormat=QtCore.Qt.TextFormat.PlainText)
        self.session_preview.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.message = QtWidgets.QLabel(wordWrap=True)
        self.message.setStyleSheet("color: #b00020;")
        for text, widget in (("Code", self.code), ("Sex", self.sex), ("Age", self.age),
                             ("Height", self.height_m), ("Mass", self.mass),
                             ("Training level", self.training_level),
                             ("Resting HR", self.hr_rest), ("Max HR", self.hr_max),
                             ("Session label", self.label), ("Session", self.session_preview)):
            form.addRow(text, widget)
        form.addRow(self.message)
        for edit in (self.code, self.label):
            edit.textChanged.connect(self._on_changed)
        for spin in (self.age, self.height_m, self.mass, self.training_level, self.hr_rest, self.hr_max):
            spin.valueChanged.connect(self._on_changed)
        self.sex.currentIndexChanged.connect(self._on_changed)

    def _on_changed(self, *_: object) -> None:
        self.message.clear()
        _mark(self.code, False)
        _mark(self.label, False)
        self._update_preview()
        self.changed.emit()

    def _update_preview(self) -> None:
        if not self.isEnabled():
            return  # recording: the preview shows the session's real name (see show_session_name)
        self.session_preview.setText(preview_session_name(self.code.text().strip(), self.session_label()))

    def show_session_name(self, name: str) -> None:
        """Show the name of the session being recorded (the form is disabled meanwhile)."""
        self.session_preview.setText(name)

    def values(self) -> dict[str, Any]:
        """The fields as ``Participant`` keyword arguments (None for HR not measured)."""
        return {
            "code": self.code.text().strip(),
            "sex": self.sex.currentText(),
            "age": self.age.value(),
            "height_m": round(self.height_m.value(), 2),
            "mass_kg": round(self.mass.value(), 1),
            "training_level": self.training_level.value(),
            "hr_rest_bpm": _optional_value(self.hr_rest),
            "hr_max_bpm": _optional_value(self.hr_max),
        }

    def session_label(self) -> str:
        """The optional label appended to the session name."""
        return self.label.text().strip()

    def validate(self) -> str:
        """Check the form; return the problem as one line ('' when valid) and show it in the form."""
        problem = self._problem()
        self.message.setText(problem)
        _mark(self.code, "code" in problem.split(":")[0])
        _mark(self.label, "label" in problem.split(":")[0])
        return problem

    def _problem(self) -> str:
        try:
            make_session_id(self.code.text().strip(), dt.datetime.now(), self.session_label() or None)
            self.participant()
        except UserError as exc:
            return str(exc)
        return ""

    def participant(self) -> Participant:
        """The validated :class:`~effortface.capture_tool.session.Participant` built from the form.

        Raises
        ------
        UserError
            If a field is invalid (the message names it).
        """
        return Participant(**self.values())


def _spin(field: str, value: int) -> QtWidgets.QSpinBox:
    """An integer spin box over the whole-number part of :data:`LIMITS` ``[field]``."""
    limit = LIMITS[field]
    spin = QtWidgets.QSpinBox(minimum=math.ceil(limit.lo), maximum=math.floor(limit.hi), value=value,
                              suffix=_suffix(limit))
    spin.setToolTip(limit.meaning)
    spin.setKeyboardTracking(False)
    return spin


def _dspin(field: str, value: float, step: float, decimals: int) -> QtWidgets.QDoubleSpinBox:
    """A spin box over :data:`LIMITS` ``[field]``."""
    limit = LIMITS[field]
    spin = QtWidgets.QDoubleSpinBox(minimum=limit.lo, maximum=limit.hi, singleStep=step,
                                    suffix=_suffix(limit), decimals=decimals)
    spin.setToolTip(limit.meaning)
    spin.setValue(value)
    return spin


def _suffix(limit: Limit) -> str:
    return f" {limit.unit}" if limit.unit else ""


def _optional_hr(field: str) -> QtWidgets.QSpinBox:
    """A bpm spin box over :data:`LIMITS` ``[field]`` whose extra lowest value (one below the limit)
    reads 'not measured' (stored as None, see :func:`_optional_value`)."""
    spin = _spin(field, 0)
    spin.setMinimum(spin.minimum() - 1)
    spin.setSpecialValueText("not measured")
    spin.setValue(spin.minimum())
    return spin


def _optional_value(spin: QtWidgets.QSpinBox) -> int | None:
    """The value of an :func:`_optional_hr` spin box, None when it reads 'not measured'."""
    return None if spin.value() == spin.minimum() else spin.value()


def _mark(widget: QtWidgets.QWidget, bad: bool) -> None:
    widget.setStyleSheet("border: 2px solid #b00020;" if bad else "")
