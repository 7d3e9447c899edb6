"""The exercise log panel: the exercise picker with its parameters, phase/rep/marker/sync hotkeys, the plan.

Hotkeys (application-wide while recording: the main window adds :attr:`QtPhasePanel.hotkeys`):
F1 rest, F2 start the exercise picked (with its parameters), F3 recovery, F4 end the phase, F9 one
repetition (not F5: Annotate rescans with it), F6 marker, F7 log the parameters (a speed or load
change), F8 sync test. Every phase is
an exercise id of the catalog (``effortface.core.exercises``), the ids ``effortface work`` reads.

The panel only asks: it emits :attr:`QtPhasePanel.phase_requested` and friends, and the capture
stage writes them through its :class:`~effortface.capture_tool.capture_session.CaptureSession`.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6 import QtCore, QtGui, QtWidgets

from effortface.core.exercises import read_catalog_rows

#: (exercise id logged, button text, hotkey) of the fixed phase keys; F2 starts the exercise picked
REST, RECOVERY = "rest", "recovery"
PHASE_KEYS = {REST: "F1", RECOVERY: "F3"}
EXERCISE_KEY, END_KEY, REP_KEY, MARKER_KEY, LOAD_KEY, SYNC_KEY = "F2", "F4", "F9", "F6", "F7", "F8"
PHASE_TITLES = {REST: "Rest", RECOVERY: "Recovery"}
#: plan column -> (label, unit, lowest, highest, step, decimals); its lowest value minus one step reads '-'
PARAMETERS = {
    "speed_m_s": ("Speed", "m/s", 0.0, 10.0, 0.1, 2), "grade_pct": ("Grade", "%", -30.0, 30.0, 0.5, 1),
    "power_w": ("Power", "W", 0.0, 2000.0, 5.0, 0), "cadence_per_min": ("Cadence", "/min", 0.0, 300.0, 1.0, 0),
    "rom_m": ("Range of motion", "m", 0.0, 3.0, 0.05, 2), "back_kg": ("Load on back", "kg", 0.0, 300.0, 0.5, 1),
    "left_kg": ("Load left hand", "kg", 0.0, 150.0, 0.5, 1), "right_kg": ("Load right hand", "kg", 0.0, 150.0, 0.5, 1),
    "machine_kg": ("Machine stack", "kg", 0.0, 500.0, 0.5, 1),
}
#: catalog model -> the parameters its work estimate reads (the others are not shown)
MODEL_PARAMETERS = {
    "constant": (),
    "treadmill": ("speed_m_s", "grade_pct", "back_kg", "left_kg", "right_kg"),
    "gait": ("speed_m_s", "grade_pct", "back_kg", "left_kg", "right_kg"),
    "reps": ("cadence_per_min", "back_kg", "left_kg", "right_kg"),
    "ergometer": ("power_w", "cadence_per_min"),
    "lift": ("machine_kg", "left_kg", "right_kg", "back_kg", "rom_m", "cadence_per_min"),
}
Parameters = tuple[tuple[str, float], ...]
#: the speed units the operator may type in -> (m/s per unit, highest, step, decimals); logged in m/s
SPEED_UNITS = {"m/s": (1.0, 10.0, 0.1, 2), "km/h": (1 / 3.6, 36.0, 0.5, 1)}


def speed_m_s(value: float, unit: str) -> float:
    """A speed typed in ``unit`` (:data:`SPEED_UNITS`) in m/s, to the millimetre per second."""
    return round(value * SPEED_UNITS[unit][0], 3)


def catalog_models() -> dict[str, str]:
    """Exercise id -> its catalog model (``gait``, ``reps``...), in catalog order."""
    return {row["id"].strip(): (row.get("model") or "").strip() for row in read_catalog_rows() if row.get("id")}


class QtPhasePanel(QtWidgets.QGroupBox):
    """Exercise picker and parameters, hotkeys for phases, reps, markers, sync; the protocol plan.

    Parameters
    ----------
    parent : QWidget, optional
        Parent widget.
    """

    phase_requested = QtCore.Signal(str, object)   # exercise id, Parameters
    end_requested = QtCore.Signal()
    rep_requested = QtCore.Signal()
    parameters_changed = QtCore.Signal(object)     # Parameters
    marker_requested = QtCore.Signal(str)          # marker text
    sync_requested = QtCore.Signal()
    plan_requested = QtCore.Signal(str)            # plan path ('' clears)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Exercise log", parent)
        self.models = catalog_models()
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        self.hotkeys: list[QtGui.QAction] = []
        self.spins: dict[str, QtWidgets.QDoubleSpinBox] = {}
        self._labels: dict[str, QtWidgets.QLabel] = {}
        self.shown: tuple[str, ...] = ()  # the parameters of the exercise picked, in order
        self._build()
        self._show_parameters()
        self.set_current(None)
        self.set_recording(False)

    # ------------------------------------------------------------------------------ layout
    def _build(self) -> None:
        grid = QtWidgets.QGridLayout(self)
        grid.setVerticalSpacing(4)
        self.exercise = QtWidgets.QComboBox()
        self.exercise.addItems(list(self.models))
        self.exercise.setToolTip("Exercise id of the catalog (effortface/core/data/exercise_catalog.csv): "
                                 "what `effortface work` estimates the work from")
        self.exercise.currentTextChanged.connect(lambda _: self._show_parameters())
        self.speed_unit = QtWidgets.QComboBox()
        self.speed_unit.addItems(list(SPEED_UNITS))
        self.speed_unit.setToolTip("The unit the speed is typed in (the log is always in m/s)")
        self.speed_unit.currentTextChanged.connect(self.set_speed_unit)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Exercise"))
        row.addWidget(self.exercise, 1)
        row.addWidget(QtWidgets.QLabel("speed in"))
        row.addWidget(self.speed_unit)
        grid.addLayout(row, 0, 0, 1, 4)
        self._params = QtWidgets.QGridLayout()
        self._params.setHorizontalSpacing(6)
        for column, (text, unit, lo, hi, step, decimals) in PARAMETERS.items():
            spin = QtWidgets.QDoubleSpinBox(minimum=lo - step, maximum=hi, singleStep=step, decimals=decimals,
                                            suffix=f" {unit}")
            spin.setSpecialValueText("-")
            spin.setValue(spin.minimum())
            spin.setToolTip(f"{text} ({unit}); '-' = not logged")
            self.spins[column], self._labels[column] = spin, QtWidgets.QLabel(text)
        self._speed_factor = 1.0  # m/s per unit of the speed box
        grid.addLayout(self._params, 1, 0, 1, 4)
        buttons = (
            (f"Rest  [{PHASE_KEYS[REST]}]", PHASE_KEYS[REST], lambda: self.request_phase(REST)),
            (f"Start exercise  [{EXERCISE_KEY}]", EXERCISE_KEY, self.request_exercise),
            (f"Recovery  [{PHASE_KEYS[RECOVERY]}]", PHASE_KEYS[RECOVERY], lambda: self.request_phase(RECOVERY)),
            (f"End phase  [{END_KEY}]", END_KEY, self.request_end),
            (f"+1 rep  [{REP_KEY}]", REP_KEY, self.request_rep),
            (f"Log speed/load  [{LOAD_KEY}]", LOAD_KEY, self.request_parameters),
            (f"Sync test (flash)  [{SYNC_KEY}]", SYNC_KEY, self.request_sync),
            (f"Marker  [{MARKER_KEY}]", MARKER_KEY, self.request_marker),
        )
        for i, (text, key, slot) in enumerate(buttons):
            button = QtWidgets.QPushButton(text)
            button.setMinimumHeight(30)
            button.clicked.connect(slot)
            self._hotkey(key, slot)
            self.buttons[key] = button
            if key != MARKER_KEY:
                grid.addWidget(button, 2 + i // 4, i % 4)
        for key in (PHASE_KEYS[REST], EXERCISE_KEY, PHASE_KEYS[RECOVERY]):
            self.buttons[key].setCheckable(True)
            self.buttons[key].setStyleSheet(
                "QPushButton:checked { background: #1b7f3b; color: white; font-weight: bold; }")
        self.marker_text = QtWidgets.QLineEdit(placeholderText="marker note (F6 logs it; logged at Stop if not sent)")
        grid.addWidget(self.marker_text, 4, 0, 1, 3)
        grid.addWidget(self.buttons[MARKER_KEY], 4, 3)
        self.plan_button = QtWidgets.QPushButton("Load plan...")
        self.plan_button.setToolTip("PLAN.csv (start_s,end_s,exercise[,parameters]): timed phases logged by "
                                    "themselves from Record, with a countdown (as `effortface capture --plan`)")
        self.plan_button.clicked.connect(self._browse_plan)
        self.plan_clear = QtWidgets.QPushButton("Clear plan")
        self.plan_clear.clicked.connect(lambda: self.plan_requested.emit(""))
        self.plan_label = QtWidgets.QLabel("no plan: phases by hotkey")
        self.plan_label.setWordWrap(True)
        grid.addWidget(self.plan_button, 5, 0)
        grid.addWidget(self.plan_clear, 5, 1)
        grid.addWidget(self.plan_label, 5, 2, 1, 2)

    def _hotkey(self, key: str, slot: Callable[[], None]) -> None:
        """A QAction with ``key``: the stage and the main window add it (one action, no ambiguity)."""
        action = QtGui.QAction(key, self)
        action.setShortcut(QtGui.QKeySequence(key))
        action.setShortcutContext(QtCore.Qt.ShortcutContext.WindowShortcut)
        action.triggered.connect(slot)
        self.hotkeys.append(action)

    def _show_parameters(self) -> None:
        """Show only the parameters the picked exercise's work estimate reads."""
        shown = MODEL_PARAMETERS.get(self.models.get(self.exercise.currentText(), ""), tuple(PARAMETERS))
        self.shown = shown
        for column, spin in self.spins.items():
            self._params.removeWidget(spin)
            self._params.removeWidget(self._labels[column])
            spin.setVisible(column in shown)
            self._labels[column].setVisible(column in shown)
        for i, column in enumerate(shown):  # packed three to a row, in the catalog model's order
            self._params.addWidget(self._labels[column], i // 3, 2 * (i % 3))
            self._params.addWidget(self.spins[column], i // 3, 2 * (i % 3) + 1)

    # ---------------------------------------------------------------------------- values
    def parameters(self) -> Parameters:
        """The parameters shown and set (not '-') as ``(column, value)`` pairs; the speed in m/s
        whatever unit it was typed in."""
        out = []
        for column in self.shown:
            spin = self.spins[column]
            if spin.value() > spin.minimum():
                value = (speed_m_s(spin.value(), self.speed_unit.currentText()) if column == "speed_m_s"
                         else round(spin.value(), spin.decimals()))
                out.append((column, value))
        return tuple(out)

    def set_speed_unit(self, unit: str) -> None:
        """Type the speed in ``unit`` (``m/s`` or ``km/h``); a speed already set is converted."""
        if self.speed_unit.currentText() != unit:
            self.speed_unit.setCurrentText(unit)  # comes back here through the signal
            return
        spin = self.spins["speed_m_s"]
        was = None if spin.value() <= spin.minimum() else spin.value() * self._speed_factor
        factor, hi, step, decimals = SPEED_UNITS[unit]
        self._speed_factor = factor
        spin.setDecimals(decimals)
        spin.setSingleStep(step)
        spin.setRange(-step, hi)
        spin.setSuffix(f" {unit}")
        spin.setToolTip(f"Speed ({unit}, logged in m/s); '-' = not logged")
        spin.setValue(spin.minimum() if was is None else was / factor)

    def pick(self, exercise: str, **values: float) -> None:
        """Pick ``exercise`` and set some parameters (tests, scripts): ``pick('squats', back_kg=10)``;
        ``speed_m_s`` is given in m/s whatever unit the speed is shown in."""
        self.exercise.setCurrentText(exercise)
        for column, value in values.items():
            self.spins[column].setValue(value / self._speed_factor if column == "speed_m_s" else value)

    # --------------------------------------------------------------------------- requests
    def request_phase(self, exercise: str) -> None:
        """Ask for a phase with no parameters (rest, recovery)."""
        if self._recording:
            self.phase_requested.emit(exercise, ())

    def request_exercise(self) -> None:
        """Ask for the exercise picked, with its parameters."""
        if self._recording:
            self.phase_requested.emit(self.exercise.currentText(), self.parameters())

    def request_end(self) -> None:
        """Ask for the running phase to end."""
        if self._recording:
            self.end_requested.emit()

    def request_rep(self) -> None:
        """Ask for one repetition to be counted."""
        if self._recording:
            self.rep_requested.emit()

    def request_parameters(self) -> None:
        """Ask for the parameters shown to be logged (a load or speed change)."""
        if self._recording:
            self.parameters_changed.emit(self.parameters())

    def request_marker(self) -> None:
        """Ask for a free marker with the note's text (then clear the note)."""
        if self._recording:
            self.marker_requested.emit(self.take_marker_text() or "marker")

    def take_marker_text(self) -> str:
        """The marker note typed (stripped), cleared."""
        text = self.marker_text.text().strip()
        self.marker_text.clear()
        return text

    def request_sync(self) -> None:
        """Ask for the sync self-test (flash)."""
        if self._recording:
            self.sync_requested.emit()

    def _browse_plan(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Protocol plan", "", "Plans (*.csv);;All files (*)")
        if path:
            self.plan_requested.emit(path)

    # ------------------------------------------------------------------------------ state
    def set_recording(self, recording: bool) -> None:
        """Enable the hotkeys and log buttons while recording (the plan can change only before)."""
        self._recording = recording
        for key, button in self.buttons.items():
            button.setEnabled(recording)
        for action in self.hotkeys:
            action.setEnabled(recording)
        self.plan_button.setEnabled(not recording)
        self.plan_clear.setEnabled(not recording)

    def set_current(self, exercise: str | None, since: str = "") -> None:
        """Show which phase runs (None: none) and since when."""
        picked = exercise not in (None, REST, RECOVERY)
        self.buttons[PHASE_KEYS[REST]].setChecked(exercise == REST)
        self.buttons[PHASE_KEYS[RECOVERY]].setChecked(exercise == RECOVERY)
        self.buttons[EXERCISE_KEY].setChecked(picked)
        title = "Exercise log"
        if exercise is not None:
            title += f"  -  now: {PHASE_TITLES.get(exercise, exercise)}" + (f" since {since}" if since else "")
        self.setTitle(title)

    def set_plan_text(self, text: str) -> None:
        """Show the plan loaded or its countdown line."""
        self.plan_label.setText(text or "no plan: phases by hotkey")
