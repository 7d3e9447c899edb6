"""The participant form: codes and body data only, never a personal name.

The form starts empty: every body field reads '-' (not confirmed) until the operator sets it, or
until a participant of the lab's registry (``participants.tsv``) is picked by code, and a field
never set is never written (None in ``session.json``). Sex, age, height, mass and training level
must be confirmed before Record (:data:`REQUIRED`); the form says which are.

One truth per participant: a code the lab knows (its registry, or its sessions) shows the lab's
record beside the code. Typed values that differ from it are kept and shown in red, field by field,
and Record is refused until the operator picks "Use the record" (the form takes the record) or
"Change the record" (after a confirmation: the record changes on purpose, the old one kept, dated,
in ``participants_history.tsv``).

The form keeps only widget state; :meth:`QtParticipantForm.participant` builds the session module's
validated ``Participant`` and shows any problem inside the form (the rule: expected errors are shown inside the window and the previous state is kept).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

from PySide6 import QtCore, QtWidgets

from effortface.core.errors import UserError
from effortface.core.participant import LIMITS, Limit
from effortface.capture_tool.participants import HISTORY_TSV, REQUIRED, conflict_message, differences
from effortface.core.session.folder import CODE_RULE, SEXES, Participant, make_session_id

#: what the sex box shows before a choice
CHOOSE = "- choose -"
#: the registry box's first entry
NEW_PARTICIPANT = "(new participant)"
#: what a refused Record tells the operator to do
CONFLICT_HINT = "choose 'Use the record' or 'Change the record'"
#: field -> row title
TITLES = {"sex": "Sex", "age": "Age", "height_m": "Height", "mass_kg": "Mass", "training_level": "Training level",
          "hr_rest_bpm": "Resting HR", "hr_max_bpm": "Max HR"}


def preview_session_name(code: str, label: str = "", when: dt.datetime | None = None) -> str:
    """The folder name the session will get, or a template while the code or label is invalid."""
    when = when or dt.datetime.now()
    try:
        return make_session_id(code, when, label or None)
    except UserError:
        return f"{code or '<code>'}_{when.strftime('%Y%m%d-%H%M%S')}" + (f"_{label}" if label else "")


class QtParticipantForm(QtWidgets.QGroupBox):
    """Participant code (or a registered participant), sex, age, height, mass, training level, measured HR.

    Parameters
    ----------
    parent : QWidget, optional
        Parent widget.
    """

    changed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Participant", parent)
        self.known: dict[str, Participant] = {}
        self.sources: dict[str, str] = {}
        #: the operator confirmed changing the lab's record of the code (reset for each recording)
        self.update_record = False
        self._from_registry = False
        self._build()
        self._preview_timer = QtCore.QTimer(self, interval=1000)
        self._preview_timer.timeout.connect(self._update_preview)
        self._preview_timer.start()
        self._update_preview()
        self._show_confirmed()

    def _build(self) -> None:
        form = QtWidgets.QFormLayout(self)
        self.registry = QtWidgets.QComboBox()
        self.registry.addItem(NEW_PARTICIPANT)
        self.registry.setToolTip("Participants of participants.tsv in the lab folder: pick one by code "
                                 "(demographics are entered once)")
        self.code = QtWidgets.QLineEdit(placeholderText="P01", maxLength=16)
        self.code.setToolTip(f"Participant code: {CODE_RULE}")
        self.record = QtWidgets.QLabel(wordWrap=True, textFormat=QtCore.Qt.TextFormat.RichText)
        self.record.setToolTip("The lab's record of this code (participants.tsv, or its latest session)")
        self.use_record = QtWidgets.QPushButton("Use the record")
        self.use_record.setToolTip("Fill the form with the lab's record of this code")
        self.change_record = QtWidgets.QPushButton("Change the record...")
        self.change_record.setToolTip(f"Record with the values typed and make them the lab's record (after a "
                                      f"confirmation; the old record is kept, dated, in {HISTORY_TSV})")
        self.record_buttons = QtWidgets.QWidget()
        buttons = QtWidgets.QHBoxLayout(self.record_buttons)
        buttons.setContentsMargins(0, 0, 0, 0)
        buttons.addWidget(self.use_record)
        buttons.addWidget(self.change_record)
        self.sex = QtWidgets.QComboBox()
        self.sex.addItems([CHOOSE, *SEXES])
        self.age = _optional_spin("age")
        # not ``self.height``: that would hide QWidget.height() (mypy found it)
        self.height_m = _optional_dspin("height_m", 0.01, 2)
        self.mass = _optional_dspin("mass_kg", 0.5, 1)
        self.training_level = _optional_dspin("training_level", 0.5, 1)
        self.hr_rest = _optional_spin("hr_rest_bpm")
        self.hr_max = _optional_spin("hr_max_bpm")
        self.fields: dict[str, QtWidgets.QWidget] = {
            "sex": self.sex, "age": self.age, "height_m": self.height_m, "mass_kg": self.mass,
            "training_level": self.training_level, "hr_rest_bpm": self.hr_rest, "hr_max_bpm": self.hr_max}
        self.label = QtWidgets.QLineEdit(placeholderText="optional, e.g. treadmill", maxLength=32)
        self.session_preview = QtWidgets.QLabel(textFormat=QtCore.Qt.TextFormat.PlainText)
        self.session_preview.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.confirmed = QtWidgets.QLabel(wordWrap=True)
        self.message = QtWidgets.QLabel(wordWrap=True)
        self.message.setStyleSheet("color: #b00020;")
        self._row_labels: dict[str, QtWidgets.QLabel] = {}
        form.addRow("Registered", self.registry)
        form.addRow("Code", self.code)
        form.addRow("Lab record", self.record)
        form.addRow("", self.record_buttons)
        #: beside each field, the lab's record of it when the two differ (side by side, said once)
        self.record_hints: dict[str, QtWidgets.QLabel] = {}
        for field, widget in self.fields.items():
            self._row_labels[field] = QtWidgets.QLabel(TITLES[field])
            hint = QtWidgets.QLabel()
            hint.setStyleSheet("color: #b00020;")
            hint.hide()
            self.record_hints[field] = hint
            row = QtWidgets.QHBoxLayout()
            row.setContentsMargins(0, 0, 0, 0)
            row.addWidget(widget, 1)
            row.addWidget(hint)
            form.addRow(self._row_labels[field], row)
        form.addRow("Session label", self.label)
        form.addRow("Session", self.session_preview)
        form.addRow(self.confirmed)
        form.addRow(self.message)
        self.registry.currentTextChanged.connect(self._on_registry_pick)
        self.code.textChanged.connect(self._on_code_changed)
        self.use_record.clicked.connect(self.take_record)
        self.change_record.clicked.connect(self.ask_change_record)
        self.label.textChanged.connect(self._on_changed)
        self.sex.currentIndexChanged.connect(self._on_changed)
        for spin in (self.age, self.height_m, self.mass, self.training_level, self.hr_rest, self.hr_max):
            spin.valueChanged.connect(self._on_changed)

    # ---------------------------------------------------------------------------- registry
    def set_known(self, known: dict[str, Participant], sources: dict[str, str] | None = None) -> None:
        """Offer the lab's participants (code -> Participant) in the 'Registered' box; ``sources``:
        code -> the file its record comes from (named when a Record is refused)."""
        self.known = dict(known)
        self.sources = dict(sources or {})
        current = self.registry.currentText()
        self.registry.blockSignals(True)
        self.registry.clear()
        self.registry.addItems([NEW_PARTICIPANT, *sorted(self.known)])
        self.registry.setCurrentText(current if current in self.known else NEW_PARTICIPANT)
        self.registry.blockSignals(False)
        self._on_code_changed()

    def _on_registry_pick(self, code: str) -> None:
        if code in self.known:
            self.code.setText(code)
        elif self._from_registry:
            self.code.clear()

    def _on_code_changed(self, *_: object) -> None:
        """A registered code fills (and locks) the body fields from the registry, unless values typed
        before differ from its record (then both are shown); leaving it clears them."""
        person = self.known.get(self.code.text().strip())
        self.update_record = False
        if person is not None:
            if self._from_registry or not self.conflicts(person):
                self.fill(person)
        elif self._from_registry:
            self.clear_fields()
        self.registry.blockSignals(True)
        self.registry.setCurrentText(person.code if person is not None else NEW_PARTICIPANT)
        self.registry.blockSignals(False)
        self._on_changed()

    def fill(self, person: Participant) -> None:
        """Show a registered participant's fields (locked: the registry is edited, not the form)."""
        self._from_registry = True
        for field, widget in self.fields.items():
            _set_field(widget, getattr(person, field))
            widget.setEnabled(getattr(person, field) is None)  # a field the registry lacks can be entered

    def conflicts(self, person: Participant | None = None) -> list[tuple[str, object, object]]:
        """The fields whose value differs from the lab's record of the code: (field, record, form).

        Empty for an unknown code and once the operator chose to change the record.
        """
        person = person or self.known.get(self.code.text().strip())
        if person is None or (self.update_record and person.code == self.code.text().strip()):
            return []
        return differences(person, self.values())

    def take_record(self) -> None:
        """'Use the record': the form takes the lab's record of the code."""
        person = self.known.get(self.code.text().strip())
        if person is not None:
            self.update_record = False
            self.fill(person)
            self._on_changed()

    def ask_change_record(self) -> bool:
        """'Change the record': after a confirmation, the values typed become the lab's record at Record.

        Returns
        -------
        bool
            True if the operator confirmed.
        """
        code = self.code.text().strip()
        person = self.known.get(code)
        if person is None:
            return False
        diff = differences(person, self.values())
        change = ("from " + ", ".join(f"{TITLES[f].lower()} {_text(r)} to {_text(g)}" for f, r, g in diff)) if diff else \
            "(edit the fields, which are unlocked)"
        answer = QtWidgets.QMessageBox.question(
            self, "Change the lab's record",
            f"Change the lab's record of {code} {change}? Sessions recorded before keep their values; "
            f"the old record is kept, dated, in {HISTORY_TSV}.",
            QtWidgets.QMessageBox.StandardButton.Yes | QtWidgets.QMessageBox.StandardButton.No,
            QtWidgets.QMessageBox.StandardButton.No)
        if answer != QtWidgets.QMessageBox.StandardButton.Yes:
            return False
        self.update_record = True
        self._from_registry = False
        for widget in self.fields.values():
            widget.setEnabled(True)
        self._on_changed()
        return True

    def _show_record(self) -> None:
        """The lab's record beside the code, each differing field's record beside its box, the two choices."""
        person = self.known.get(self.code.text().strip())
        self.record.setVisible(person is not None)
        self.record_buttons.setVisible(person is not None)
        if person is None:
            self.record.clear()
            for hint in self.record_hints.values():
                hint.hide()
            return
        shown = ", ".join(f"{TITLES[f].lower()} {_text(getattr(person, f))}" for f in TITLES
                          if getattr(person, f) is not None)
        diff = self.conflicts(person)
        text = shown
        if self.update_record:
            text += "<br><span style='color:#806000;'>The record changes to the values below at Record.</span>"
        self.record.setText(text)
        differing = {f: r for f, r, _ in diff}
        for field, label in self._row_labels.items():
            hint = self.record_hints[field]
            hint.setVisible(field in differing)
            if field in differing:  # typed value in its box, the lab's record beside it
                hint.setText(f"lab record: {_text(differing[field])}")
                label.setText(TITLES[field])
                label.setStyleSheet("color: #b00020; font-weight: bold;")
        self.use_record.setEnabled(bool(diff) or self.update_record)
        self.change_record.setEnabled(not self.update_record)

    def clear_after_recording(self) -> None:
        """After Stop: an empty form for the next participant (code, label, fields, record choice)."""
        self.update_record = False
        self.registry.setCurrentIndex(0)
        self.code.clear()
        self.label.clear()
        self.clear_fields()
        self._on_changed()

    def clear_fields(self) -> None:
        """Every body field back to '-' (not confirmed), editable."""
        self._from_registry = False
        for widget in self.fields.values():
            _set_field(widget, None)
            widget.setEnabled(True)

    # ------------------------------------------------------------------------------ changes
    def _on_changed(self, *_: object) -> None:
        self.message.clear()
        _mark(self.code, False)
        _mark(self.label, False)
        self._update_preview()
        self._show_confirmed()
        self.changed.emit()

    def _show_confirmed(self) -> None:
        """Tick each confirmed field's row and say what Record still needs."""
        values = self.values()
        source = " (registry)" if self._from_registry else ""
        for field, label in self._row_labels.items():
            ok = values[field] is not None
            required = field in REQUIRED
            label.setText(("\u2714 " if ok else ("\u2716 " if required else "")) + TITLES[field])
            label.setStyleSheet("" if ok or not required else "color: #b00020;")
        missing = self.missing()
        self.confirmed.setText(f"All required fields confirmed{source}." if not missing else
                               "To confirm before Record: " + ", ".join(TITLES[f].lower() for f in missing))
        diff = self.conflicts()
        if diff:
            where = self.sources.get(self.code.text().strip(), "the lab")
            self.confirmed.setText(f"{', '.join(TITLES[f] for f, _, _ in diff)} differ{'s' * (len(diff) == 1)} "
                                   f"from the lab's record (beside each; from {where}): Use the record, or "
                                   "Change the record.")
            self.confirmed.setStyleSheet("color: #b00020;")
        else:
            self.confirmed.setStyleSheet("")
        self._show_record()

    def missing(self) -> list[str]:
        """The required fields not confirmed yet."""
        values = self.values()
        return [field for field in REQUIRED if values[field] is None]

    def _update_preview(self) -> None:
        if not self.isEnabled():
            return  # recording: the preview shows the session's real name (see show_session_name)
        self.session_preview.setText(preview_session_name(self.code.text().strip(), self.session_label()))

    def show_session_name(self, name: str) -> None:
        """Show the name of the session being recorded (the form is disabled meanwhile)."""
        self.session_preview.setText(name)

    def values(self) -> dict[str, Any]:
        """The fields as ``Participant`` keyword arguments (None for a field not confirmed)."""
        sex = self.sex.currentText()
        height, mass = _optional_value(self.height_m), _optional_value(self.mass)
        return {
            "code": self.code.text().strip(),
            "sex": sex if sex in SEXES else None,
            "age": _optional_value(self.age),
            "height_m": None if height is None else round(height, 2),
            "mass_kg": None if mass is None else round(mass, 1),
            "training_level": _optional_value(self.training_level),
            "hr_rest_bpm": _optional_value(self.hr_rest),
            "hr_max_bpm": _optional_value(self.hr_max),
        }

    def session_label(self) -> str:
        """The optional label appended to the session name."""
        return self.label.text().strip()

    def validate(self) -> str:
        """Check the form; return the problem as one line ('' when valid) and show it in the form."""
        problem = self._problem()
        self.message.setText("" if self.conflicts() else problem)  # a conflict is said once, above
        _mark(self.code, "code" in problem.split(":")[0])
        _mark(self.label, "label" in problem.split(":")[0])
        return problem

    def _problem(self) -> str:
        try:
            make_session_id(self.code.text().strip(), dt.datetime.now(), self.session_label() or None)
            self.participant()
        except UserError as exc:
            return str(exc)
        diff = self.conflicts()
        if diff:
            code = self.code.text().strip()
            return conflict_message(code, self.sources.get(code, "the lab"), diff, CONFLICT_HINT)
        missing = self.missing()
        if missing:
            return (f"participant {', '.join(TITLES[f].lower() for f in missing)}: expected a confirmed value "
                    "before Record (or pick a registered participant), found none")
        return ""

    def participant(self) -> Participant:
        """The validated :class:`~effortface.core.session.folder.Participant` built from the form
        (fields not confirmed are None).

        Raises
        ------
        UserError
            If a field is invalid (the message names it).
        """
        return Participant(**self.values())


def _text(value: object) -> str:
    """A record value as shown: numbers without a useless '.0'."""
    return f"{value:g}" if isinstance(value, float) else str(value)


def _optional_spin(field: str) -> QtWidgets.QSpinBox:
    """An integer spin box over the whole-number part of :data:`LIMITS` ``[field]`` whose extra lowest
    value (one below the limit) reads '-': not confirmed (None, see :func:`_optional_value`)."""
    limit = LIMITS[field]
    spin = QtWidgets.QSpinBox(minimum=math.ceil(limit.lo) - 1, maximum=math.floor(limit.hi), suffix=_suffix(limit))
    spin.setSpecialValueText("-")
    spin.setValue(spin.minimum())
    spin.setToolTip(f"{limit.meaning} ({limit.lo:g}-{limit.hi:g}); '-' = not confirmed")
    spin.setKeyboardTracking(False)
    return spin


def _optional_dspin(field: str, step: float, decimals: int) -> QtWidgets.QDoubleSpinBox:
    """A spin box over :data:`LIMITS` ``[field]`` whose lowest value, one unit of its last decimal below
    the limit, reads '-' (not confirmed): every other value it can show is valid."""
    limit = LIMITS[field]
    spin = QtWidgets.QDoubleSpinBox(minimum=round(limit.lo - 10.0 ** -decimals, decimals), maximum=limit.hi,
                                    singleStep=step, suffix=_suffix(limit), decimals=decimals)
    spin.setSpecialValueText("-")
    spin.setValue(spin.minimum())
    spin.setToolTip(f"{limit.meaning} ({limit.lo:g}-{limit.hi:g}); '-' = not confirmed")
    return spin


def _suffix(limit: Limit) -> str:
    return f" {limit.unit}" if limit.unit else ""


def _optional_value(spin: QtWidgets.QSpinBox | QtWidgets.QDoubleSpinBox) -> Any:
    """The value of an optional spin box, None when it reads '-' (its lowest value)."""
    return None if spin.value() <= spin.minimum() else spin.value()


def _set_field(widget: QtWidgets.QWidget, value: object) -> None:
    """Show ``value`` in a field (None: '-' / choose)."""
    if isinstance(widget, QtWidgets.QComboBox):
        widget.setCurrentText(str(value) if value is not None else CHOOSE)
    elif isinstance(widget, QtWidgets.QSpinBox):
        widget.setValue(widget.minimum() if value is None else int(round(float(value))))  # type: ignore[arg-type]
    elif isinstance(widget, QtWidgets.QDoubleSpinBox):
        widget.setValue(widget.minimum() if value is None else float(value))  # type: ignore[arg-type]


def _mark(widget: QtWidgets.QWidget, bad: bool) -> None:
    widget.setStyleSheet("border: 2px solid #b00020;" if bad else "")
