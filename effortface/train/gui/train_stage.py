"""The Train stage: pick sessions (or a table), choose settings, train in the background, read the
results as the paper shows them, export the bundle, compare two bundles.

:class:`QtTrainStage` views a :class:`~effortface.train.train_session.TrainSession`: the controls call its
methods, its callbacks update the views, and a QTimer calls :meth:`TrainSession.poll` to bring the
worker thread's progress and results to the GUI thread (the rule: a view writes back only through model methods and keeps widget state only; worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.annotate.completeness import RULE_TEXT as COMPLETENESS_RULE
from effortface.core.gui.qt_compat import guard_none_refcount
from effortface.core.errors import UserError
from effortface.core.gui.widgets import caption
from effortface.train.dataset import RATER_SOURCES
from effortface.train.face_fit import CV_CHOICES, GRIDS, PROTOCOLS
from effortface.train.run_log import CV_LABELS, cv_caption, grid_tooltip, held_out_pairs
from effortface.train.train_session import ANY, TrainSession, filter_entries

__all__ = ["QtTrainStage", "TrainSession"]

POLL_MS = 50
_REAL, _OWN, _PRED, _B = "#1f77b4", "#ff7f0e", "#d62728", "#2ca02c"
_FACE_COLORS = ("#d62728", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf")
#: the Raters box's label sources (``effortface train --raters``)
_SOURCE_LABELS = {"humans": "humans", "humans+machine": "humans + machine where no human keyed"}
_SESSION_COLUMNS = ("use", "session", "participant", "TL", "exercise", "raters", "complete",
                    "complete tracks")
_ANNOTATION_CHOICES = {"any annotation status": None, "annotated": True, "not annotated": False}


def _fmt(value: Any) -> str:
    """A table cell: numbers to 3 significant digits, 'n/a' for a value that is not a number (never 'nan')."""
    if isinstance(value, (float, np.floating)):
        return f"{value:.3g}" if np.isfinite(value) else "n/a"
    return str(value)


#: a column narrowed to fit its table keeps at least this width (its text wraps)
_MIN_WRAPPED_PX = 80


def _two_lines(label: str) -> str:
    """``label`` broken at the space nearest its middle."""
    spaces = [i for i, ch in enumerate(label) if ch == " "]
    if not spaces:
        return label
    i = min(spaces, key=lambda k: abs(2 * k - len(label)))
    return f"{label[:i]}\n{label[i + 1:]}"


class QtFrameTable(QtWidgets.QTableWidget):
    """A read-only table showing a DataFrame (floats to 3 significant digits).

    A column label wider than the column's values goes on two lines, so that short numbers under
    long labels (``HR RMSE bpm``) take the width of the numbers; rows are as tall as their text. A
    table still wider than its view narrows its widest column, whose text then wraps.
    """

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.verticalHeader().setVisible(False)
        self.setAlternatingRowColors(True)

    def show_frame(self, frame: pd.DataFrame) -> None:
        """Replace the content with ``frame``."""
        self.clear()
        self.setColumnCount(len(frame.columns))
        self.setRowCount(len(frame))
        self.setHorizontalHeaderLabels([str(c) for c in frame.columns])
        for r, row in enumerate(frame.itertuples(index=False)):
            for c, value in enumerate(row):
                self.setItem(r, c, QtWidgets.QTableWidgetItem(_fmt(value)))
        self.resizeColumnsToContents()
        header = self.horizontalHeader()
        for c, label in enumerate(frame.columns):
            if header.sectionSizeHint(c) > self.sizeHintForColumn(c):
                self.setHorizontalHeaderItem(c, QtWidgets.QTableWidgetItem(_two_lines(str(label))))
        self._fit_width()

    def _fit_width(self) -> None:
        """Columns as wide as their content, the widest narrowed (its text wrapped) if they overflow."""
        self.resizeColumnsToContents()
        header = self.horizontalHeader()
        # room left by a vertical scroll bar, shown or not: wrapped rows may bring one
        room = self.maximumViewportSize().width() - self.verticalScrollBar().sizeHint().width()
        excess = header.length() - room
        if excess > 0 and self.columnCount():
            widest = max(range(self.columnCount()), key=header.sectionSize)
            header.resizeSection(widest, max(header.sectionSize(widest) - excess, _MIN_WRAPPED_PX))
        self.resizeRowsToContents()

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt override
        """Fit the columns to the new width."""
        super().resizeEvent(event)
        self._fit_width()


def _plot(title: str, y_label: str) -> pg.PlotWidget:
    w = pg.PlotWidget(background="w", title=title)
    w.showGrid(x=True, y=True, alpha=0.2)
    w.setLabel("bottom", "time (min)")
    w.setLabel("left", y_label)
    w.setMenuEnabled(False)
    return w


# --------------------------------------------------------------------------- data and settings


def _redundant_columns(entries: list[Any]) -> set[str]:
    """Session columns that say nothing the others do not (hidden, so the stage fits 1280x800).

    ``participant`` and ``exercise``: the session id (``<code>_<date>-<time>_<label>``) names them,
    unless a session's does not; ``complete``: the lab lists finished sessions only, so it shows
    only if one is not; ``raters``: the complete tracks name every rater, unless a session's tracks
    could not be read.
    """
    hidden = set()
    if all(e.session_id.startswith(f"{e.participant}_") for e in entries):
        hidden.add("participant")
    if all(e.session_id.endswith(f"_{e.exercise}") for e in entries):
        hidden.add("exercise")
    if all(e.complete for e in entries):
        hidden.add("complete")
    if all(e.tracks not in ("", "unreadable") or not e.raters for e in entries):
        hidden.add("raters")
    return hidden


class QtDataPicker(QtWidgets.QGroupBox):
    """Sessions filtered by participant, exercise and annotation status, with check boxes; or a table."""

    def __init__(self, session: TrainSession, on_error: Callable[[str, bool], None],
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Training data", parent)
        self.session = session
        self._on_error = on_error
        self.participant, self.exercise = QtWidgets.QComboBox(), QtWidgets.QComboBox()
        self.annotation = QtWidgets.QComboBox()
        self.annotation.addItems(list(_ANNOTATION_CHOICES))
        self.table = QtWidgets.QTableWidget(0, len(_SESSION_COLUMNS))
        self.table.setHorizontalHeaderLabels(list(_SESSION_COLUMNS))
        self.table.verticalHeader().setVisible(False)
        self.table.verticalHeader().setDefaultSectionSize(self.table.fontMetrics().height() + 8)  # 12 fit
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(   # the last column takes the room left
            len(_SESSION_COLUMNS) - 1, QtWidgets.QHeaderView.ResizeMode.Stretch)
        self.table.itemChanged.connect(self._on_item_changed)
        self.description = QtWidgets.QLabel(wordWrap=True)
        self._layout()
        for combo in (self.participant, self.exercise, self.annotation):
            combo.currentIndexChanged.connect(self.show_entries)
        session.sessions_changed.connect(self._on_sessions_changed)
        session.selection_changed.connect(self.show_entries)
        self._on_sessions_changed()

    def _layout(self) -> None:
        filters = QtWidgets.QHBoxLayout()
        for w in (self.participant, self.exercise, self.annotation):
            filters.addWidget(w)
        buttons = QtWidgets.QHBoxLayout()
        self.select_shown_button = QtWidgets.QPushButton("Use shown")
        self.select_shown_button.clicked.connect(lambda: self._select_shown(True))
        self.clear_button = QtWidgets.QPushButton("Use none")
        self.clear_button.clicked.connect(lambda: self._select_shown(False))
        self.refresh_button = QtWidgets.QPushButton("Rescan")
        self.refresh_button.clicked.connect(self.session.refresh)
        self.table_button = QtWidgets.QPushButton("Load table...")
        self.table_button.clicked.connect(self._ask_table)
        for button in (self.select_shown_button, self.clear_button, self.refresh_button, self.table_button):
            buttons.addWidget(button)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(filters)
        layout.addWidget(self.table, 1)
        layout.addLayout(buttons)
        layout.addWidget(self.description)

    def _on_sessions_changed(self) -> None:
        entries = self.session.entries
        for combo, values, what in ((self.participant, sorted({e.participant for e in entries}), "participant"),
                                    (self.exercise, sorted({e.exercise for e in entries}), "exercise")):
            combo.blockSignals(True)
            combo.clear()
            combo.addItem(f"any {what}", ANY)
            for v in values:
                combo.addItem(v, v)
            combo.blockSignals(False)
        self.show_entries()

    def shown(self) -> list[Any]:
        """The entries that pass the filters."""
        return filter_entries(self.session.entries, self.participant.currentData() or ANY,
                              self.exercise.currentData() or ANY,
                              _ANNOTATION_CHOICES[self.annotation.currentText()])

    def show_entries(self) -> None:
        """Fill the table with the filtered entries, checked when selected."""
        self.table.blockSignals(True)
        shown = self.shown()
        self.table.setRowCount(len(shown))
        for r, e in enumerate(shown):
            use = QtWidgets.QTableWidgetItem()
            use.setData(QtCore.Qt.ItemDataRole.UserRole, e.session_id)
            why = e.unusable_for(self.session.settings.raters)
            if why:  # greyed, never ticked, the reason on the row
                use.setText(why.split(":")[0])
                use.setFlags(use.flags() & ~QtCore.Qt.ItemFlag.ItemIsUserCheckable
                             & ~QtCore.Qt.ItemFlag.ItemIsEnabled)
                use.setToolTip(f"not trained on: {why}")
            else:
                use.setFlags(use.flags() | QtCore.Qt.ItemFlag.ItemIsUserCheckable)
                use.setCheckState(QtCore.Qt.CheckState.Checked if e.session_id in self.session.selected
                                  else QtCore.Qt.CheckState.Unchecked)
            self.table.setItem(r, 0, use)
            for c, v in enumerate((e.session_id, e.participant, _fmt(e.training_level), e.exercise,
                                   ", ".join(e.raters) or "none", "yes" if e.complete else "NO",
                                   e.tracks or "none"), 1):
                cell = QtWidgets.QTableWidgetItem(v)
                if c == len(_SESSION_COLUMNS) - 1:
                    cell.setToolTip("each rater's complete tracks / tracks: " + COMPLETENESS_RULE)
                if why:
                    cell.setFlags(cell.flags() & ~QtCore.Qt.ItemFlag.ItemIsEnabled)
                    cell.setToolTip(f"not trained on: {why}")
                self.table.setItem(r, c, cell)
        hidden = _redundant_columns(shown)
        for c, name in enumerate(_SESSION_COLUMNS):
            self.table.setColumnHidden(c, name in hidden)
        self.table.resizeColumnsToContents()
        self._fit_table_width()
        self.table.blockSignals(False)
        self.description.setText(f"Next training uses: {self.session.describe_data()}")

    def _fit_table_width(self) -> None:
        """As wide as its columns (no column clipped), up to 640 pixels (then it scrolls)."""
        header = self.table.horizontalHeader()
        columns = sum(max(self.table.sizeHintForColumn(c), header.sectionSizeHint(c))
                      for c in range(self.table.columnCount()) if not self.table.isColumnHidden(c))
        needed = columns + self.table.verticalScrollBar().sizeHint().width() + 2 * self.table.frameWidth() + 2
        self.table.setMinimumWidth(min(needed, 640))

    def _on_item_changed(self, item: QtWidgets.QTableWidgetItem) -> None:
        if item.column() == 0:
            checked = item.checkState() == QtCore.Qt.CheckState.Checked
            self.session.set_selected([item.data(QtCore.Qt.ItemDataRole.UserRole)], checked)

    def _select_shown(self, selected: bool) -> None:
        """Tick (or untick) the shown sessions that can be trained on; the model leaves the others out
        (greyed) and says why."""
        self.session.set_selected([e.session_id for e in self.shown()], selected)

    def _ask_table(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open training table", "", "CSV (*.csv)")
        if path:
            self.load_table(path)

    def load_table(self, path: str | Path) -> bool:
        """Train on a long table instead of sessions (a bad file is reported in the stage)."""
        try:
            self.session.load_table(path)
        except UserError as exc:
            self._on_error(str(exc), True)
            return False
        return True


class QtSettingsPanel(QtWidgets.QGroupBox):
    """Rater policy, hyper-parameter grid, cross-validation and rows per participant."""

    def __init__(self, session: TrainSession, on_error: Callable[[str, bool], None],
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__("Settings", parent)
        self.session = session
        self._on_error = on_error
        self.rater = QtWidgets.QComboBox(editable=True)
        self.rater.setInsertPolicy(QtWidgets.QComboBox.InsertPolicy.NoInsert)
        self.grid = QtWidgets.QComboBox()
        for i, name in enumerate(GRIDS):
            self.grid.addItem(name)
            self.grid.setItemData(i, grid_tooltip(name), QtCore.Qt.ItemDataRole.ToolTipRole)
        self.cv = QtWidgets.QComboBox()
        for key in CV_CHOICES:
            self.cv.addItem(CV_LABELS[key], key)
        self.cv.setToolTip("How the face SVR's grid search and scores hold data out:\n"
                           "leave one participant out: every score is on a person the model never saw "
                           "(the paper's honest protocol);\nrandom-frame K-fold: frames of the same "
                           "person on both sides, scores inflated (for comparison only).")
        self.max_rows = QtWidgets.QSpinBox(minimum=20, maximum=100000, singleStep=50)
        self.max_rows.setKeyboardTracking(False)
        self.max_rows.setToolTip("Face training rows per participant (1 Hz, evenly spaced): fewer "
                                 "train faster, more use more of the key-framed data.")
        self.rater.setToolTip("'mean' averages the raters of each session; a rater's name trains on "
                              "that rater's key-frames only.")
        self.sources = QtWidgets.QComboBox()
        for key in RATER_SOURCES:
            self.sources.addItem(_SOURCE_LABELS[key], key)
        self.sources.setToolTip("humans: the raters' key-frames only. humans + machine: also the machine "
                                "rater's weights (machine/face_landmarker.csv, Pre-annotate) where no human "
                                "keyed; the report then compares held-out scores on human labels of a fit on "
                                "human labels only and of this one.")
        raters_row = QtWidgets.QHBoxLayout()
        raters_row.setContentsMargins(0, 0, 0, 0)
        raters_row.addWidget(self.rater, 1)
        raters_row.addWidget(self.sources, 1)
        form = QtWidgets.QFormLayout(self)
        form.addRow("Raters", raters_row)
        form.addRow("SVR grid", self.grid)
        form.addRow("Cross-validation", self.cv)
        form.addRow("Face rows per participant", self.max_rows)
        self.values = {key: self._values_edit(key) for key in ("C", "gamma")}
        form.addRow("C values", self.values["C"])
        form.addRow("gamma values", self.values["gamma"])
        session.sessions_changed.connect(self._fill_raters)
        self._fill_raters()
        self.show_settings()
        # not on every keystroke (an editable combo box always has its line edit)
        self.rater.lineEdit().editingFinished.connect(self.commit_rater)  # type: ignore[union-attr]  # see above
        self.rater.activated.connect(self.commit_rater)                    # a pick from the list
        self.sources.currentIndexChanged.connect(lambda i: self._write(raters=self.sources.itemData(i)))
        self.grid.currentTextChanged.connect(lambda v: self._write(grid=v))
        self.grid.currentTextChanged.connect(lambda v: self.grid.setToolTip(grid_tooltip(v)))
        self.grid.currentTextChanged.connect(lambda _v: self.show_settings())  # the values' placeholders
        self.cv.currentIndexChanged.connect(lambda i: self._write(cv=self.cv.itemData(i)))
        self.max_rows.valueChanged.connect(lambda v: self._write(max_rows_per_participant=int(v)))

    def _values_edit(self, key: str) -> QtWidgets.QLineEdit:
        """A field of numbers replacing the grid's values of ``key`` (``--C`` / ``--gamma``)."""
        edit = QtWidgets.QLineEdit()
        edit.setToolTip(f"Values of {key} to search, separated by spaces, in place of the grid's "
                        f"(empty: the grid's). Same as effortface train --{key}.")
        edit.editingFinished.connect(lambda: self.commit_values(key))
        return edit

    def commit_values(self, key: str) -> bool:
        """Use the numbers typed in the ``key`` field (empty: the grid's); a bad entry is reported."""
        text = self.values[key].text().strip()
        field = {"C": "c_values", "gamma": "gamma_values"}[key]
        try:
            values = tuple(float(v) for v in text.replace(",", " ").split()) if text else None
        except ValueError:
            self._on_error(f"{key} values: expected positive numbers separated by spaces, found {text!r}", True)
            return False
        if values == getattr(self.session.settings, field):
            return True
        try:
            self.session.set_settings(**{field: values})
        except UserError as exc:
            self._on_error(str(exc).replace(f"--{key}:", f"{key} values:"), True)
            return False
        return True

    def _fill_raters(self) -> None:
        raters = sorted({r for e in self.session.entries for r in e.raters})
        self.rater.blockSignals(True)
        self.rater.clear()
        self.rater.addItems(["mean", *raters])
        self.rater.setCurrentText(self.session.settings.rater_policy)
        self.rater.blockSignals(False)

    def commit_rater(self, *_: Any) -> bool:
        """Validate and use the rater typed or picked (when it differs from the settings).

        A rejected name is reported in red and stays in the field for the user to correct; the
        settings keep the previous policy.
        """
        text = self.rater.currentText()
        if text.strip() == self.session.settings.rater_policy:
            return True
        try:
            self.session.set_rater_policy(text)       # says what it did through status_changed
        except UserError as exc:
            self._on_error(str(exc), True)
            return False
        return True

    def _write(self, **changes: Any) -> None:
        try:
            self.session.set_settings(**changes)
        except UserError as exc:
            self._on_error(str(exc), True)
            self.show_settings()

    def show_settings(self) -> None:
        """Show the session's settings (without writing back)."""
        s = self.session.settings
        for w in (self.rater, self.sources, self.grid, self.cv, self.max_rows):
            w.blockSignals(True)
        self.rater.setCurrentText(s.rater_policy)
        self.sources.setCurrentIndex(RATER_SOURCES.index(s.raters))
        self.grid.setCurrentText(s.grid)
        self.grid.setToolTip(grid_tooltip(s.grid))
        self.cv.setCurrentIndex(CV_CHOICES.index(s.cv))
        self.max_rows.setValue(s.max_rows_per_participant)
        for key, values in (("C", s.c_values), ("gamma", s.gamma_values)):
            self.values[key].setPlaceholderText("grid's: " + " ".join(f"{v:g}" for v in GRIDS[s.grid][key]))
            self.values[key].setText("" if values is None else " ".join(f"{v:g}" for v in values))
        for w in (self.rater, self.sources, self.grid, self.cv, self.max_rows):
            w.blockSignals(False)


# --------------------------------------------------------------------------- results


class QtHeartRateResults(QtWidgets.QWidget):
    """Fig. 2: measured and simulated NHR of one session, and the models' scores beside the paper's."""

    def __init__(self, session: TrainSession, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.choice = QtWidgets.QComboBox()
        self.choice.currentTextChanged.connect(self.show_session)
        self.plot = _plot("Train to see measured and simulated NHR", "NHR")
        self.legend = self.plot.addLegend(offset=(8, 8))
        self.legend.setVisible(False)      # no legend for curves that do not exist yet
        self.curves = {key: self.plot.plot([], [], pen=pg.mkPen(color, width=w, style=style), name=name)
                       for key, color, w, style, name in (
                           ("measured", _REAL, 2, QtCore.Qt.PenStyle.SolidLine, "measured"),
                           ("own", _OWN, 1.5, QtCore.Qt.PenStyle.SolidLine, "own model"),
                           ("tl", _PRED, 1.5, QtCore.Qt.PenStyle.DashLine, "TL model (held out)"))}
        self.plot.setYRange(0, 1, padding=0.03)
        self.table = QtFrameTable()
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Session"))
        row.addWidget(self.choice, 1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(row)
        layout.addWidget(self.plot, 3)
        layout.addWidget(caption("Heart-rate models (held out: own model on the participant's other "
                                 "sessions, pooled threshold and TL models without the participant; "
                                 "per_participant_in_sample is in-sample; the paper's figures last):"))
        layout.addWidget(self.table, 1)
        session.results_changed.connect(self.show_results)

    def show_results(self) -> None:
        """New training results: the session list and the table."""
        o = self.session.outcome
        assert o is not None
        self.choice.blockSignals(True)
        self.choice.clear()
        self.choice.addItems(o.sessions)
        self.choice.blockSignals(False)
        self.table.show_frame(o.hr_table())
        self.legend.setVisible(True)
        self.show_session(o.sessions[0])

    def show_session(self, session_id: str) -> None:
        """Draw Fig. 2 for one session."""
        o = self.session.outcome
        if o is None or not session_id:
            return
        fig = o.fig2(session_id)
        for key, curve in self.curves.items():
            curve.setData(fig["t_min"], fig[key], connect="finite")
        self.plot.setTitle(f"Fig. 2: {fig['title']}")


class QtFaceResults(QtWidgets.QWidget):
    """Fig. 3: key-framed and predicted weights of one session under one protocol, and the scores."""

    def __init__(self, session: TrainSession, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.choice, self.protocol = QtWidgets.QComboBox(), QtWidgets.QComboBox()
        self.protocol.addItems([p.replace("_", " ") for p in PROTOCOLS])
        self.choice.currentTextChanged.connect(self.show_session)
        self.protocol.currentTextChanged.connect(self.show_session)
        self.plots = pg.GraphicsLayoutWidget()
        self.plots.setBackground("w")
        self.axes: list[pg.PlotItem] = []
        self.curves: list[tuple[pg.PlotDataItem, pg.PlotDataItem]] = []
        self.table = QtFrameTable()
        row = QtWidgets.QHBoxLayout()
        for w in (QtWidgets.QLabel("Session"), self.choice, QtWidgets.QLabel("Protocol"), self.protocol):
            row.addWidget(w)
        row.addStretch(1)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(row)
        layout.addWidget(caption("<span style='color:#1f77b4'>key-framed</span> and "
                                 "<span style='color:#d62728'>predicted</span> weights (Fig. 3)"))
        layout.addWidget(self.plots, 3)
        layout.addWidget(caption("Face SVR on held-out participants beside the mean and "
                                 "linear baselines (r, RMSE in % of the observed range):"))
        layout.addWidget(self.table, 2)
        session.results_changed.connect(self.show_results)

    def _build_axes(self, names: tuple[str, ...]) -> None:
        self.plots.clear()
        self.axes, self.curves = [], []
        for i, name in enumerate(names):
            ax = self.plots.addPlot(row=i // 2, col=i % 2, title=name.replace("_", " "))
            ax.setYRange(0, 1, padding=0.03)
            ax.setLabel("bottom", "time (min)")
            ax.setLabel("left", "weight")
            ax.showGrid(x=True, y=True, alpha=0.2)
            self.axes.append(ax)
            self.curves.append((ax.plot([], [], pen=pg.mkPen(_REAL, width=2)),
                                ax.plot([], [], pen=pg.mkPen(_PRED, width=1.5))))

    def show_results(self) -> None:
        """New training results: sessions, axes and the score table."""
        o = self.session.outcome
        assert o is not None
        self._build_axes(o.face.blendshapes)
        self.choice.blockSignals(True)
        self.choice.clear()
        self.choice.addItems(o.face_sessions())
        self.choice.blockSignals(False)
        self.table.show_frame(o.face_table())
        self.show_session()

    def show_session(self, *_: Any) -> None:
        """Draw Fig. 3 for the chosen session and protocol."""
        o = self.session.outcome
        if o is None or not self.choice.currentText():
            return
        fig = o.fig3(self.choice.currentText(), PROTOCOLS[self.protocol.currentIndex()])
        for b, (keyed, pred) in enumerate(self.curves):
            keyed.setData(fig["t_min"], fig["keyed"][:, b], connect="finite")
            pred.setData(fig["t_min"], fig["predicted"][:, b], connect="finite")


class QtRunLog(QtWidgets.QWidget):
    """The run log: timed progress lines, per-fold scores, the grid search, held-out residuals.

    Left: the log (elapsed time on each line, the time left in the progress bar) above the
    per-fold and grid-search tables; right: held-out predicted vs key-framed weights and the
    residuals, one colour per blendshape.
    """

    def __init__(self, session: TrainSession, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.text = QtWidgets.QPlainTextEdit(readOnly=True)
        self.text.setPlaceholderText("Train to see the run's steps, folds and timings here.")
        self.folds, self.grid = QtFrameTable(), QtFrameTable()
        self.edge_note = QtWidgets.QLabel(wordWrap=True)
        self.edge_note.setStyleSheet("color: #664d03; background: #fff3cd; padding: 3px;")
        self.wider_button = QtWidgets.QPushButton("Use the wider grid")
        self.wider_button.setToolTip("Choose the next wider SVR grid for the next training (Train again to use it)")
        self.edge_bar = QtWidgets.QWidget()
        edge = QtWidgets.QHBoxLayout(self.edge_bar)
        edge.setContentsMargins(0, 0, 0, 0)
        edge.addWidget(self.edge_note, 1)
        edge.addWidget(self.wider_button)
        self.edge_bar.hide()
        self.scatter = self._plot("Held out: predicted vs key-framed", "key-framed weight", "predicted weight")
        self.residuals = self._plot("Residuals", "predicted weight", "predicted - key-framed")
        tables = QtWidgets.QTabWidget()
        tables.addTab(self.folds, "Scores per CV fold")
        tables.setTabToolTip(0, "The chosen SVR on each fold's held-out rows: r within the fold (one "
                                "participant's rows under leave one participant out) and RMSE in weight")
        tables.addTab(self.grid, "Grid search")  # short: both tabs in sight at 1280 x 800 (no scroll arrows)
        tables.setTabToolTip(1, "The cross-validated MSE of every point of the SVR grid")
        left = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        left.addWidget(self.text)
        left.addWidget(tables)
        right = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        right.addWidget(self.scatter)
        right.addWidget(self.residuals)
        split = QtWidgets.QSplitter()
        split.addWidget(left)
        split.addWidget(right)
        split.setSizes([450, 450])
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.edge_bar)
        layout.addWidget(split)
        session.log_changed.connect(self._on_line)
        session.results_changed.connect(self.show_results)

    @staticmethod
    def _plot(title: str, x_label: str, y_label: str) -> pg.PlotWidget:
        w = pg.PlotWidget(background="w")
        # a title sets the plot's smallest width: at its default size the long one is wider than the
        # plot gets at 1280x800, and the plot's right edge (the last tick label) would be cut off
        w.setTitle(title, size="9pt")
        w.showGrid(x=True, y=True, alpha=0.2)
        w.setLabel("bottom", x_label)
        w.setLabel("left", y_label)
        w.setMenuEnabled(False)
        for axis in ("left", "bottom"):
            w.getAxis(axis).enableAutoSIPrefix(False)   # weights read as weights, not x0.001
        return w

    def _on_line(self, line: str) -> None:
        if not line:
            self.text.clear()
        else:
            self.text.appendPlainText(line)

    def show_results(self) -> None:
        """The tables and plots of the last training."""
        o = self.session.outcome
        assert o is not None
        self.folds.show_frame(self.session.fold_table)
        self.grid.show_frame(self.session.grid_results)
        edges, wider = self.session.grid_edges, self.session.wider_grid()
        self.edge_bar.setVisible(bool(edges))
        self.edge_note.setText("Chosen at the grid's edge (the best may lie outside it): " + "; ".join(edges))
        self.wider_button.setVisible(bool(wider))
        self.wider_button.setText(f"Use the wider grid ({wider})")
        pairs = held_out_pairs(o)
        for w in (self.scatter, self.residuals):
            w.clear()
            w.addLegend(offset=(8, 8), brush=pg.mkBrush(255, 255, 255, 200))
        self.scatter.plot([0, 1], [0, 1], pen=pg.mkPen("#808080", style=QtCore.Qt.PenStyle.DashLine))
        for b, name in enumerate(o.face.blendshapes):
            y, pred = pairs["measured"][:, b], pairs["predicted"][:, b]
            ok = np.isfinite(y) & np.isfinite(pred)
            brush = pg.mkBrush(_FACE_COLORS[b % len(_FACE_COLORS)] + "80")
            label = name.replace("_", " ")
            self.scatter.plot(y[ok], pred[ok], pen=None, symbol="o", symbolSize=4, symbolPen=None,
                              symbolBrush=brush, name=label)
            self.residuals.plot(pred[ok], pred[ok] - y[ok], pen=None, symbol="o", symbolSize=4,
                                symbolPen=None, symbolBrush=brush, name=label)
        self.residuals.addLine(y=0, pen=pg.mkPen("#808080", style=QtCore.Qt.PenStyle.DashLine))


class QtCompare(QtWidgets.QWidget):
    """Two bundles side by side: their stored metrics and their predictions over one session."""

    def __init__(self, session: TrainSession, on_error: Callable[[str, bool], None],
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self._on_error = on_error
        self.paths = [QtWidgets.QLineEdit(placeholderText=f"model {k} folder") for k in "AB"]
        self.choice = QtWidgets.QComboBox()
        self.compare_button = QtWidgets.QPushButton("Compare")
        self.compare_button.clicked.connect(self.compare)
        self.data_label = caption("")
        self.table = QtFrameTable()
        self.plots = pg.GraphicsLayoutWidget()
        self.plots.setBackground("w")
        self.axes: dict[str, pg.PlotItem] = {}
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(self._path_rows())
        layout.addWidget(self.data_label)
        self.scores_caption = caption("How each model was trained and the scores stored in its "
                                      "model.json (each by its own CV scheme, named per model):")
        layout.addWidget(self.scores_caption)
        layout.addWidget(self.table, 2)
        layout.addWidget(caption("<span style='color:#1f77b4'>measured</span>, "
                                 "<span style='color:#d62728'>model A</span>, "
                                 "<span style='color:#2ca02c'>model B</span> "
                                 "(TL model and the participant's expressiveness)"))
        layout.addWidget(self.plots, 3)
        session.comparison_changed.connect(self.show_comparison)
        for signal in (session.selection_changed, session.sessions_changed):
            signal.connect(self.show_data)
        for edit in self.paths:
            edit.textChanged.connect(self.show_data)
        self.choice.activated.connect(self._on_session_picked)
        self.show_data()

    def _on_session_picked(self, _index: int) -> None:
        """A session picked after a comparison: compare again on it (the table and plots follow)."""
        c = self.session.comparison
        if c is not None and self.choice.currentText() != c["session"] and not self.session.busy:
            self.compare()

    def _path_rows(self) -> QtWidgets.QGridLayout:
        grid = QtWidgets.QGridLayout()
        for i, edit in enumerate(self.paths):
            browse = QtWidgets.QPushButton("Browse...")
            browse.clicked.connect(lambda _=False, e=edit: self._browse(e))
            grid.addWidget(QtWidgets.QLabel(f"Model {'AB'[i]}"), i, 0)
            grid.addWidget(edit, i, 1)
            grid.addWidget(browse, i, 2)
        grid.addWidget(QtWidgets.QLabel("Session"), 2, 0)
        grid.addWidget(self.choice, 2, 1)
        grid.addWidget(self.compare_button, 2, 2)
        grid.setColumnStretch(1, 1)
        return grid

    def show_data(self, *_: Any) -> None:
        """Say which sessions Compare will use and offer them in the Session list."""
        a, b = (e.text().strip() for e in self.paths)
        try:
            entries, what = self.session.comparison_data(a, b)
        except UserError as exc:
            self.data_label.setText(str(exc) if a and b else
                                    "Compare uses the ticked sessions or, with nothing ticked, the "
                                    "sessions both models were trained on.")
            return
        self.data_label.setText(f"Compares on {what}.")
        self.data_label.setToolTip("\n".join(e.session_id for e in entries))
        if entries:
            self._offer_sessions([e.session_id for e in entries])

    def _offer_sessions(self, session_ids: list[str], current: str | None = None) -> None:
        """The Session list's choices (the current one kept when still offered)."""
        current = current or self.choice.currentText()
        self.choice.blockSignals(True)
        self.choice.clear()
        self.choice.addItems(session_ids)
        if current in session_ids:
            self.choice.setCurrentText(current)
        self.choice.blockSignals(False)

    def _browse(self, edit: QtWidgets.QLineEdit) -> None:
        path = QtWidgets.QFileDialog.getExistingDirectory(self, "Model bundle folder")
        if path:
            edit.setText(path)

    def compare(self) -> None:
        """Compare the two folders on the chosen session (errors shown in the stage).

        The data are the ticked sessions, or with nothing ticked the sessions both models were
        trained on (:meth:`TrainSession.comparison_data`); :attr:`data_label` says which.
        """
        a, b = (e.text().strip() for e in self.paths)
        if not a or not b:
            self._on_error("compare: expected two model folders, found "
                           f"{'none' if not (a or b) else 'one'}", True)
            return
        try:
            self.session.compare(a, b, self.choice.currentText() or None)
        except UserError as exc:
            self._on_error(str(exc), True)

    def show_comparison(self) -> None:
        """Metrics side by side and the curves of both models."""
        c = self.session.comparison
        assert c is not None
        for edit, summary in zip(self.paths, (c["a"], c["b"])):
            edit.setText(str(summary.path))
        self._offer_sessions(c["sessions"], c["session"])
        self.data_label.setText(f"Compared on {c['data']}.")
        cv_a, cv_b = (s.settings.get("CV scheme", "not recorded") for s in (c["a"], c["b"]))
        self.scores_caption.setText(cv_caption(cv_a, cv_b))
        self.scores_caption.setStyleSheet("" if cv_a == cv_b else "color:#b00020;")
        self.table.show_frame(_side_by_side(c["a"], c["b"]))
        self._draw(c)

    def _draw(self, c: dict[str, Any]) -> None:
        self.plots.clear()
        keys = ["nhr", *self.session.blendshapes.names]
        m, t = c["measured"], c["measured"]["t_s"] / 60.0
        for i, key in enumerate(keys):
            ax = self.plots.addPlot(row=i // 3, col=i % 3, title=key.replace("_", " ").replace("nhr", "NHR"))
            ax.setYRange(0, 1, padding=0.03)
            ax.showGrid(x=True, y=True, alpha=0.2)
            ax.setLabel("bottom", "time (min)")
            if key in m:
                ax.plot(t, m[key], pen=pg.mkPen(_REAL, width=2), connect="finite")
            for which, color in (("a", _PRED), ("b", _B)):
                curves = c[which].curves
                if key in curves:
                    ax.plot(curves["t_s"] / 60.0, curves[key], pen=pg.mkPen(color, width=1.5))
            self.axes[key] = ax


def _side_by_side(a: Any, b: Any) -> pd.DataFrame:
    """How each bundle was trained, then one row per metric; a column per bundle and B - A."""
    rows = []
    for key in dict.fromkeys([*a.settings, *b.settings]):
        rows.append({"metric": key, "A": a.settings.get(key, "not recorded"),
                     "B": b.settings.get(key, "not recorded")})
    for label, s in (("A", a), ("B", b)):
        for _, r in s.hr.iterrows():
            rows.append({"metric": f"HR {r['model']} r", label: r["r"]})
            rows.append({"metric": f"HR {r['model']} RMSE %", label: r["RMSE %"]})
        svr = s.face[s.face["model"] == "svr"] if "model" in s.face else s.face
        for _, r in svr.iterrows():
            rows.append({"metric": f"face {r['blendshape']} r", label: r["r"]})
    frame = pd.DataFrame(rows)
    out = frame.groupby("metric", sort=False).first().reset_index()
    out.insert(1, "model A", out.pop("A") if "A" in out else np.nan)
    out.insert(2, "model B", out.pop("B") if "B" in out else np.nan)
    out["B - A"] = [_difference(x, y) for x, y in zip(out["model A"], out["model B"])]
    return out


def _difference(a: Any, b: Any) -> Any:
    """B - A of two scores; for settings, ``same`` or ``differs`` (blank if either is missing)."""
    if isinstance(a, (float, int, np.floating)) and isinstance(b, (float, int, np.floating)):
        return float(b) - float(a)
    if isinstance(a, str) and isinstance(b, str):
        return "same" if a == b else "differs"
    return ""


# --------------------------------------------------------------------------- the stage


class QtTrainStage(QtWidgets.QWidget):
    """The Train stage (data, settings, run, results, export, compare).

    Parameters
    ----------
    session : TrainSession
        The model this stage views and drives.
    parent : QWidget, optional
        Parent widget.
    """

    def __init__(self, session: TrainSession, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        guard_none_refcount()  # PySide6 6.12 on CPython 3.11 leaks references to None (see there)
        self.session = session
        self.status = QtWidgets.QLabel("Pick sessions (or load a table), then Train.", wordWrap=True)
        self.picker = QtDataPicker(session, self.show_status)
        self.settings_panel = QtSettingsPanel(session, self.show_status)
        self.hr_results = QtHeartRateResults(session)
        self.face_results = QtFaceResults(session)
        self.comparison = QtCompare(session, self.show_status)
        self.run_log = QtRunLog(session)
        self.run_log.wider_button.clicked.connect(self.use_wider_grid)
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(self.hr_results, "Heart rate (Fig. 2)")
        self.tabs.addTab(self.face_results, "Face (Fig. 3)")
        self.tabs.addTab(self.comparison, "Compare models")
        self.tabs.addTab(self.run_log, "Run log")
        self.card = QtWidgets.QTextBrowser()
        self.card.setOpenExternalLinks(False)
        self.card.setPlaceholderText("The exported model's card (MODEL_CARD.md) shows here after Export model...")
        self.tabs.addTab(self.card, "Card")
        self._build()
        self._connect_session()
        self.timer = QtCore.QTimer(self, interval=POLL_MS)
        self.timer.timeout.connect(session.poll)
        self.timer.start()

    def use_wider_grid(self) -> str:
        """One click after a grid-edge warning: the next wider grid for the next training; return it."""
        wider = self.session.wider_grid()
        if wider:
            self.settings_panel.grid.setCurrentText(wider)
            self.show_status(f"SVR grid: {wider} for the next training (Train again to use it)", False)
            self.run_log.wider_button.hide()
        return wider

    def _build(self) -> None:
        self.train_button = QtWidgets.QPushButton("Train")
        self.train_button.clicked.connect(self.train)
        self.cancel_button = QtWidgets.QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.cancel_button.clicked.connect(self.session.cancel)
        self.export_button = QtWidgets.QPushButton("Export model...")
        self.export_button.setEnabled(False)
        self.export_button.clicked.connect(self._ask_export)
        self.progress = QtWidgets.QProgressBar(maximum=1000, textVisible=True)
        self.progress.setFormat("idle")
        run = QtWidgets.QHBoxLayout()
        for w in (self.train_button, self.cancel_button, self.export_button):
            run.addWidget(w)
        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.picker, 1)
        left.addWidget(self.settings_panel)
        left.addLayout(run)
        left.addWidget(self.progress)
        left.addWidget(self.status)
        left_widget = QtWidgets.QWidget()
        left_widget.setLayout(left)
        split = QtWidgets.QSplitter()
        split.addWidget(left_widget)
        split.addWidget(self.tabs)
        split.setSizes([610, 790])
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(split)

    def _connect_session(self) -> None:
        s = self.session
        s.progress_changed.connect(self._on_progress)
        s.status_changed.connect(self.show_status)
        s.busy_changed.connect(self._on_busy)
        s.results_changed.connect(lambda: self.export_button.setEnabled(True))
        s.export_changed.connect(self._on_exported)
        for signal in (s.selection_changed, s.sessions_changed):
            signal.connect(self._update_train_button)
        self._update_train_button()

    def _update_train_button(self, busy: bool | None = None) -> None:
        """Train only with something to train on, and not while a job runs."""
        busy = self.session.busy if busy is None else busy
        self.train_button.setEnabled(self.session.can_train and not busy)
        self.train_button.setToolTip("" if self.session.can_train else
                                     "Tick sessions (or load a table) to train")

    def show_status(self, text: str, is_error: bool = False) -> None:
        """Show a message under the buttons (errors in red, a note about the labels in bold amber)."""
        self.status.setStyleSheet("color:#b00020;" if is_error else
                                  "color:#806000; font-weight:bold;" if "; note: " in text else "color:#404040;")
        self.status.setText(text)

    def train(self) -> None:
        """Start training (errors shown in the stage, a rejected rater name among them)."""
        if not self.settings_panel.commit_rater():
            return
        try:
            self.session.start_training()
        except UserError as exc:
            self.show_status(str(exc), True)

    def export(self, path: str | Path) -> bool:
        """Export to ``path``; an existing folder is replaced only if the user agrees."""
        path = Path(path)
        overwrite = False
        if path.exists():
            overwrite = self.confirm_overwrite(path)
            if not overwrite:
                self.show_status(f"not exported: {path} exists and was kept", False)
                return False
        try:
            self.session.export(path, overwrite=overwrite)
        except (UserError, OSError) as exc:
            self.show_status(str(exc), True)
            return False
        return True

    def confirm_overwrite(self, path: Path) -> bool:
        """Ask whether to replace the model folder ``path`` (tests replace this method)."""
        answer = QtWidgets.QMessageBox.question(
            self, "Replace model?", f"{path} exists. Replace the model folder?")
        return answer == QtWidgets.QMessageBox.StandardButton.Yes

    def export_start(self) -> Path:
        """Where Export model... starts: a new folder name in the lab's ``models/`` (an absolute path)."""
        models = self.session.sessions_dir.resolve() / "models"
        name, n = "new_model", 2
        while (models / name).exists():
            name, n = f"new_model_{n}", n + 1
        return models / name

    def _ask_export(self) -> None:
        start = self.export_start()
        try:  # the dialog opens in models/ (made on first use; a read-only lab starts in the lab)
            start.parent.mkdir(exist_ok=True)
        except OSError:
            start = start.parent.parent / start.name
        path = QtWidgets.QFileDialog.getSaveFileName(
            self, "Export model: name the new model folder", str(start), "",
            options=QtWidgets.QFileDialog.Option.ShowDirsOnly)[0]
        if path:
            self.export(path)

    def _on_progress(self, fraction: float, text: str) -> None:
        self.progress.setValue(int(round(fraction * 1000)))
        self.progress.setFormat(f"{text} ({fraction:.0%})")

    def _on_busy(self, busy: bool) -> None:
        for w in (self.picker, self.settings_panel, self.comparison.compare_button):
            w.setEnabled(not busy)
        self._update_train_button(busy)
        self.export_button.setEnabled(not busy and self.session.outcome is not None)
        self.cancel_button.setEnabled(busy and self.session.cancellable)   # an export always finishes

    def _on_exported(self, path: Path) -> None:
        card = Path(path) / "MODEL_CARD.md"
        try:
            self.card.setMarkdown(card.read_text(encoding="utf-8"))
            self.card.setToolTip(str(card))
        except OSError as exc:
            self.card.setPlainText(f"{card}: could not be read ({exc})")
        for edit in self.comparison.paths:
            if not edit.text():
                edit.setText(str(path))
                break

    # ---- hosting
    def shutdown(self) -> None:
        """Stop polling and cancel a running training."""
        self.timer.stop()
        self.session.shutdown()

    def settled(self) -> bool:
        """True when no background job runs."""
        return not self.session.busy

    def may_close(self) -> bool:
        """Ask before closing while a job runs."""
        if not self.session.busy:
            return True
        answer = QtWidgets.QMessageBox.question(self, "Training running", "A job is running. Stop it and close?")
        if answer == QtWidgets.QMessageBox.StandardButton.Yes:
            self.session.cancel()
            return True
        return False
