"""Phase and marker buttons with hotkeys (F1-F4 phases, F6 marker, F7 load/speed, F8 sync test).

The panel only asks: it emits :attr:`QtPhasePanel.phase_requested` and friends, and the capture
stage writes them through the recorder on the session clock.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

#: (phase label in events.csv, button text, hotkey)
PHASES = (("rest", "Rest", "F1"), ("warmup", "Warm-up", "F2"), ("exercise", "Exercise", "F3"),
          ("recovery", "Recovery", "F4"))
PHASE_TITLES = {phase: text for phase, text, _ in PHASES}
MARKER_KEY, LOAD_KEY, SYNC_KEY = "F6", "F7", "F8"


def exercise_value(load_kg: float, speed_kmh: float) -> str:
    """The ``value`` column of an exercise event: ``load_kg=5;speed_kmh=8.5``."""
    return f"load_kg={load_kg:g};speed_kmh={speed_kmh:g}"


class QtPhasePanel(QtWidgets.QGroupBox):
    """Buttons and hotkeys for phases, exercise load/speed, free markers and the sync test.

    Parameters
    ----------
    parent : QWidget, optional
        Parent widget.
    """

    phase_requested = QtCore.Signal(str, str)   # phase label, value
    load_changed = QtCore.Signal(str)            # exercise value
    marker_requested = QtCore.Signal(str)        # marker text
    sync_requested = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Phases and markers", parent)
        self.buttons: dict[str, QtWidgets.QPushButton] = {}
        self._build()
        self.set_current(None)
        self.setEnabled(False)

    def _build(self) -> None:
        grid = QtWidgets.QGridLayout(self)
        for col, (phase, text, key) in enumerate(PHASES):
            button = QtWidgets.QPushButton(f"{text}  [{key}]")
            button.setCheckable(True)
            button.setMinimumHeight(36)
            button.setStyleSheet("QPushButton:checked { background: #1b7f3b; color: white; font-weight: bold; }")
            button.clicked.connect(lambda _=False, p=phase: self.request_phase(p))
            self._shortcut(key, lambda p=phase: self.request_phase(p))
            grid.addWidget(button, 0, col)
            self.buttons[phase] = button
        self.load_kg = QtWidgets.QDoubleSpinBox(maximum=500.0, singleStep=0.5, suffix=" kg")
        self.speed_kmh = QtWidgets.QDoubleSpinBox(maximum=40.0, singleStep=0.5, suffix=" km/h")
        self.apply_load = QtWidgets.QPushButton(f"Set load/speed  [{LOAD_KEY}]")
        self.apply_load.clicked.connect(self.request_load)
        self._shortcut(LOAD_KEY, self.request_load)
        self.marker_text = QtWidgets.QLineEdit(placeholderText="marker note (optional)")
        self.marker_button = QtWidgets.QPushButton(f"Marker  [{MARKER_KEY}]")
        self.marker_button.clicked.connect(self.request_marker)
        self._shortcut(MARKER_KEY, self.request_marker)
        self.sync_button = QtWidgets.QPushButton(f"Sync test (flash)  [{SYNC_KEY}]")
        self.sync_button.clicked.connect(self.request_sync)
        self._shortcut(SYNC_KEY, self.request_sync)
        grid.addWidget(QtWidgets.QLabel("Exercise load"), 1, 0)
        grid.addWidget(self.load_kg, 1, 1)
        grid.addWidget(QtWidgets.QLabel("Speed"), 1, 2)
        grid.addWidget(self.speed_kmh, 1, 3)
        grid.addWidget(self.apply_load, 2, 0, 1, 2)
        grid.addWidget(self.sync_button, 2, 2, 1, 2)
        grid.addWidget(self.marker_text, 3, 0, 1, 3)
        grid.addWidget(self.marker_button, 3, 3)

    def _shortcut(self, key: str, slot: object) -> None:
        shortcut = QtGui.QShortcut(QtGui.QKeySequence(key), self)
        shortcut.setContext(QtCore.Qt.ShortcutContext.WindowShortcut)
        shortcut.activated.connect(slot)

    def exercise_value(self) -> str:
        """The current load and speed as an events.csv value."""
        return exercise_value(self.load_kg.value(), self.speed_kmh.value())

    def request_phase(self, phase: str) -> None:
        """Ask for ``phase`` to start (exercise carries the load and speed fields)."""
        if not self.isEnabled():
            return
        self.phase_requested.emit(phase, self.exercise_value() if phase == "exercise" else "")

    def request_load(self) -> None:
        """Ask for a load/speed change event."""
        if self.isEnabled():
            self.load_changed.emit(self.exercise_value())

    def request_marker(self) -> None:
        """Ask for a free marker with the note's text (then clear the note)."""
        if self.isEnabled():
            self.marker_requested.emit(self.marker_text.text().strip() or "marker")
            self.marker_text.clear()

    def set_current(self, phase: str | None, since: str = "") -> None:
        """Show which phase is running (None: none yet) and since when."""
        for name, button in self.buttons.items():
            button.setChecked(name == phase)
        title = "Phases and markers"
        if phase is not None:
            title += f"  -  now: {PHASE_TITLES[phase]}" + (f" since {since}" if since else "")
        self.setTitle(title)

    def request_sync(self) -> None:
        """Ask for the sync self-test (flash)."""
        if self.isEnabled():
            self.sync_requested.emit()
