"""The reliability round: rate the pose set blind, then see the agreement report.

:class:`QtReliabilityPanel` views a :class:`~effortface.annotate.annotate_session.BlindRound` (one rater's blind
ratings of ``reliability/poses.csv``) and the lab's :class:`~effortface.annotate.agreement.AgreementReport`:
per-pose and per-blendshape tables (mean absolute difference in % of the weight range, ICC(A,1) and
ICC(C,1) each with its 95 % confidence interval, Krippendorff's alpha), flagged poses in red and the
Bland-Altman plot of every rater pair; when the sessions carry a machine track
(``machine/face_landmarker.csv``), the machine rater's table apart from the humans (ICC(A,1), alpha and
mean absolute difference against each human and the human mean, 95 % bootstrap intervals;
:func:`~effortface.annotate.agreement.machine_report`). The report appears only once this rater has rated every pose, so nobody sees the others'
ratings before giving their own. A lab without a pose set can propose one from HR and phase
extremes (written to ``reliability/poses.csv``, never over an existing one).

Each blendshape of a pose starts **unrated** (the spin box shows "unrated", one step below 0): an
untouched shape is never saved as a rating, Save stores only the rated ones and says which are still
unrated. The face drawn from the typed weights sits beside the pose's frame, so the rater matches
one to the other; keyboard entry: type a weight, Enter goes to the next blendshape and saves the
pose after the last one, Ctrl+Enter saves at once.
"""

from __future__ import annotations

import html
from collections.abc import Collection
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.annotate.agreement import (FLAG_PCT, MACHINE_LABEL, N_POSES, AgreementReport, MachineReport,
                                           agreement_report, format_ci, gather_poses, gather_ratings,
                                           machine_ratings, machine_report, machine_summary_line,
                                           propose_poses)
from effortface.annotate.face import render_face
from effortface.annotate.gui.image_view import QtImageView
from effortface.annotate.reliability import Pose, write_poses
from effortface.annotate.annotate_session import BlindRound
from effortface.capture_tool.camera import read_frame
from effortface.core.errors import UserError
from effortface.core.session.folder import list_sessions, read_session

#: the Bland-Altman choice that overlays every rater pair
ALL_PAIRS = "all pairs"
_PAIR_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2")
_FLAG_BRUSH = QtGui.QBrush(QtGui.QColor("#f8d7da"))
#: the spin box value that means "not rated yet" (shown as "unrated"; never saved)
UNRATED = -0.01
#: smallest pose frame and face picture (4:3): small enough for the report's tables at 1280x800
_PICTURE_MIN = (130, 98)
_ROW_PX = 22


class _TablesFirstSplitter(QtWidgets.QSplitter):
    """A vertical splitter whose extra height, when the window grows, goes to its growing tables (poses and
    pairs, the machine's rows) once the Bland-Altman plot has :data:`_PLOT_ENOUGH_PX`; a smaller window
    shrinks all."""

    plot_index = 2
    #: the blendshape table shows its five rows at its minimum: it never needs more
    fixed_index = 0

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt override
        before = self.sizes()
        super().resizeEvent(event)
        grown = event.size().height() - event.oldSize().height()
        if event.oldSize().height() <= 0 or grown <= 0 or len(before) <= self.plot_index:
            return
        plot_gain = max(0, min(grown, _PLOT_ENOUGH_PX - before[self.plot_index]))
        tables = [i for i, w in enumerate(before) if i not in (self.plot_index, self.fixed_index) and w > 0
                  and (pane := self.widget(i)) is not None and pane.isVisible()]
        if not tables:
            return
        sizes = list(before)
        sizes[self.plot_index] += plot_gain
        share, rest = divmod(grown - plot_gain, len(tables))
        for n, i in enumerate(tables):
            sizes[i] += share + (1 if n < rest else 0)
        self.setSizes(sizes)


#: the Bland-Altman plot grows up to this height before a taller window goes to the tables
_PLOT_ENOUGH_PX = 240


def machine_summary(rep: MachineReport) -> str:
    """:func:`~effortface.annotate.agreement.machine_summary_line` with its head in bold (rich text)."""
    head, sep, rest = machine_summary_line(rep).partition(": ")
    return f"<b>{html.escape(head)}{sep.strip()}</b> {html.escape(rest)}"


def _table(headers: list[str], fit: bool = False) -> QtWidgets.QTableWidget:
    """A read-only table; ``fit``: columns as wide as their content, the last one takes the rest."""
    table = QtWidgets.QTableWidget(0, len(headers))
    table.setHorizontalHeaderLabels(headers)
    table.verticalHeader().setVisible(False)
    table.verticalHeader().setDefaultSectionSize(_ROW_PX)
    table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
    table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
    header = table.horizontalHeader()
    if fit:  # before the stretch is set (it keeps the size the last column has then as its minimum),
        header.setMinimumSectionSize(36)  # so the last column shrinks to its content, not to 100 pixels
        header.setDefaultSectionSize(36)
    header.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
    header.setStretchLastSection(True)
    return table


def _fit_rows(table: QtWidgets.QTableWidget, rows: int) -> None:
    """At least as tall as its header and ``rows`` rows (with a horizontal scroll bar's room if it has one)."""
    scroll = table.horizontalScrollBar().sizeHint().height() if table.horizontalScrollBar().isVisible() else 0
    table.setMinimumHeight(table.horizontalHeader().sizeHint().height() + rows * _ROW_PX
                           + 2 * table.frameWidth() + scroll)


def _fill(table: QtWidgets.QTableWidget, rows: list[list[str]], flagged: Collection[int] = frozenset()) -> None:
    table.setRowCount(len(rows))
    for r, row in enumerate(rows):
        for c, text in enumerate(row):
            item = QtWidgets.QTableWidgetItem(text)
            if r in flagged:
                item.setBackground(_FLAG_BRUSH)
            table.setItem(r, c, item)


class QtReliabilityPanel(QtWidgets.QWidget):
    """Blind pose ratings and the agreement report of a lab folder (see the module docstring).

    Parameters
    ----------
    lab_dir : Path
        The folder of sessions (with ``reliability/``).
    rater : str
        The rater rating the poses.
    """

    def __init__(self, lab_dir: Path, rater: str, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.lab_dir = Path(lab_dir)
        self.rater = rater
        self.round: BlindRound | None = None
        self.report: AgreementReport | None = None
        self.machine: MachineReport | None = None
        self._machine_key: tuple | None = None  # the ratings the machine section was computed from
        self._build()
        self.reload()

    # ---------------------------------------------------------------------------------- layout
    def _build(self) -> None:
        self.status = QtWidgets.QLabel(wordWrap=True)
        self.propose_button = QtWidgets.QPushButton(f"Propose {N_POSES} poses from HR and phase extremes")
        self.propose_button.clicked.connect(self.propose)
        self.poses = _table(["pose", "session", "frame", "rated"])
        self.poses.currentCellChanged.connect(lambda row, *_: self._show_pose(row))
        self.image = QtImageView("pose frame", _PICTURE_MIN)
        self.face = QtImageView("face from your weights", _PICTURE_MIN)
        for view in (self.image, self.face):  # as tall as their width allows (4:3), no empty band
            view.setSizePolicy(QtWidgets.QSizePolicy.Policy.Expanding, QtWidgets.QSizePolicy.Policy.Fixed)
        self.face.setToolTip("The face drawn from the weights you typed (unrated: 0): match it to the frame")
        self.image.installEventFilter(self)
        self.spins: dict[str, QtWidgets.QDoubleSpinBox] = {}
        form = QtWidgets.QFormLayout()
        self.save_button = QtWidgets.QPushButton("Save my rating of this pose (Ctrl+Enter)")
        self.save_button.clicked.connect(self.save_pose)
        rate_box = QtWidgets.QGroupBox("Rate the selected pose (blind)")
        pictures = QtWidgets.QHBoxLayout()
        pictures.addWidget(self.image, 1)
        pictures.addWidget(self.face, 1)
        rate_layout = QtWidgets.QVBoxLayout(rate_box)
        rate_layout.addLayout(pictures, 1)
        rate_layout.addLayout(form)
        rate_layout.addWidget(self.save_button)
        self.correct_box = QtWidgets.QWidget()
        correct = QtWidgets.QHBoxLayout(self.correct_box)
        correct.setContentsMargins(0, 0, 0, 0)
        self.correct_shape = QtWidgets.QComboBox()
        self.correct_value = QtWidgets.QDoubleSpinBox(minimum=0.0, maximum=1.0, singleStep=0.05, decimals=2)
        self.correct_reason = QtWidgets.QLineEdit(placeholderText="reason (required)")
        self.correct_button = QtWidgets.QPushButton("Correct")
        self.correct_button.setToolTip("Correct a typo after the round: logged in reliability/corrections_<rater>.csv "
                                       "(time UTC, pose, blendshape, old, new, reason)")
        self.correct_button.clicked.connect(self.correct)
        for w in (self.correct_shape, self.correct_value, self.correct_reason, self.correct_button):
            correct.addWidget(w, 1 if w is self.correct_reason else 0)
        rate_layout.addWidget(self.correct_box)
        self.correct_box.setVisible(False)
        self._form = form
        save = QtGui.QShortcut(QtGui.QKeySequence("Ctrl+Return"), self, self.save_pose)
        save.setContext(QtCore.Qt.ShortcutContext.WidgetWithChildrenShortcut)
        left = QtWidgets.QVBoxLayout()
        left.setContentsMargins(0, 0, 0, 0)
        left.addWidget(self.propose_button)
        left.addWidget(self.poses, 1)
        left.addWidget(rate_box, 0)
        left_widget = QtWidgets.QWidget()
        left_widget.setLayout(left)
        left_widget.setMinimumWidth(2 * _PICTURE_MIN[0] + 30)  # the two pictures side by side
        left_widget.setMaximumWidth(460)
        self._row = QtWidgets.QHBoxLayout()
        self._row.addWidget(left_widget, 1)  # the pictures grow with its width, up to 460 px
        self._row.addWidget(self._build_report(), 2)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.status)
        layout.addLayout(self._row, 1)

    def _build_report(self) -> QtWidgets.QWidget:
        box = QtWidgets.QGroupBox("Agreement report")
        self.threshold = QtWidgets.QDoubleSpinBox(minimum=0.0, maximum=100.0, value=FLAG_PCT, suffix=" %",
                                                  decimals=1, singleStep=1.0)
        self.threshold.valueChanged.connect(lambda *_: self.refresh_report())
        self.report_note = QtWidgets.QLabel(wordWrap=True)
        self.per_pose = _table(["pose", "|diff| %", "review"], fit=True)  # sorted worst first
        self.per_shape = _table(["blendshape", "n", "diff %", "ICC(A,1)", "95 % CI", "ICC(C,1)", "95 % CI",
                                 "alpha"], fit=True)
        _fit_rows(self.per_shape, 5)  # the four blendshapes and "all", no scrolling (again when filled)
        self.per_shape.setToolTip("n: rated items; diff %: mean |difference| between raters in % of the weight "
                                  "range; ICC(A,1) absolute agreement, ICC(C,1) consistency; alpha: Krippendorff")
        self.pairs = _table(["pair", "n", "bias", "lower limit", "upper limit"], fit=True)
        self.pairs.setToolTip("Bland-Altman: bias = mean of rater a - rater b; limits of agreement = bias \u00b1 1.96 SD")
        self.ba_plot = pg.PlotWidget(background="w", title="Bland-Altman: rater a - rater b")
        self.ba_plot.setLabel("bottom", "mean weight of the pair")
        self.ba_plot.setLabel("left", "difference")
        legend = self.ba_plot.addLegend(offset=(-5, 5), brush=pg.mkBrush(255, 255, 255, 235),
                                        pen=pg.mkPen("#909090"))
        legend.setZValue(1000)  # drawn over the bias and limit lines, never struck through
        self.ba_plot.setMinimumHeight(160)
        self.ba_pair = QtWidgets.QComboBox()
        self.ba_pair.setToolTip("The rater pair drawn (one at a time reads best; a row of the pairs table "
                                "picks it too)")
        self.ba_pair.currentIndexChanged.connect(lambda *_: self._replot())
        self.pairs.currentCellChanged.connect(self._pick_pair_row)
        self._report: AgreementReport | None = None
        for axis in ("left", "bottom"):
            self.ba_plot.getAxis(axis).enableAutoSIPrefix(False)
        threshold_row = QtWidgets.QHBoxLayout()
        threshold_row.addWidget(QtWidgets.QLabel("Flag poses over"))
        threshold_row.addWidget(self.threshold)
        threshold_row.addStretch(1)
        threshold_row.addWidget(QtWidgets.QLabel("Bland-Altman of"))
        threshold_row.addWidget(self.ba_pair)
        lower = QtWidgets.QHBoxLayout()
        lower.setContentsMargins(0, 0, 0, 0)
        lower.addWidget(self.per_pose, 2)
        lower.addWidget(self.pairs, 3)
        lower_widget = QtWidgets.QWidget()
        lower_widget.setLayout(lower)
        _fit_rows(self.pairs, 3)  # three raters' pairs unscrolled (the worst poses come first above them)
        results = _TablesFirstSplitter(QtCore.Qt.Orientation.Vertical)
        results.setChildrenCollapsible(False)
        results.addWidget(self.per_shape)
        results.addWidget(lower_widget)
        results.addWidget(self.ba_plot)
        # a group box is at least as wide as its title: the details go in a wrapped label
        self.machine_box = QtWidgets.QGroupBox("Machine rater, apart from the humans")
        self.machine_note = QtWidgets.QLabel(wordWrap=True)
        self.machine_table = _table(["against", "blendshape", "n", "ICC(A,1)", "95 % CI", "alpha", "95 % CI",
                                     "MAD %", "95 % CI"], fit=True)
        self.machine_table.setToolTip("The machine (machine/face_landmarker.csv at the pose frames) against each "
                                      "human and the human mean; never in the human mean. 95 % CI: bootstrap over "
                                      "poses. MAD %: mean |machine - reference| in % of the weight range")
        machine_layout = QtWidgets.QVBoxLayout(self.machine_box)
        machine_layout.addWidget(self.machine_note)
        machine_layout.addWidget(self.machine_table, 1)
        _fit_rows(self.machine_table, 4)  # four rows unscrolled; the rest scrolls (20 with three raters)
        self.machine_box.setVisible(False)
        results.addWidget(self.machine_box)
        results.setStretchFactor(0, 2)
        results.setStretchFactor(1, 2)
        results.setStretchFactor(2, 2)
        results.setStretchFactor(3, 3)
        self.hidden_note = QtWidgets.QLabel(alignment=QtCore.Qt.AlignmentFlag.AlignCenter, wordWrap=True)
        self.hidden_note.setStyleSheet("color:#505050; font-size:14px;")
        self.results = QtWidgets.QStackedWidget()
        self.results.addWidget(self.hidden_note)
        self.results.addWidget(results)
        layout = QtWidgets.QVBoxLayout(box)
        layout.addLayout(threshold_row)
        layout.addWidget(self.report_note)
        layout.addWidget(self.results, 1)
        return box

    # ----------------------------------------------------------------------------------- data
    def set_rater(self, rater: str) -> None:
        """Switch to another rater's blind round."""
        self.rater = rater
        self.reload()

    def reload(self) -> None:
        """Re-read the pose set and this rater's ratings; show or hide the report."""
        try:
            self.round = BlindRound(self.lab_dir, self.rater)
        except UserError as exc:
            self.round = None
            self.status.setText(str(exc))
        self.propose_button.setVisible(self.round is None)
        self._rebuild_spins()
        self._fill_poses()
        self.refresh_report()

    def _rebuild_spins(self) -> None:
        while self._form.rowCount():
            self._form.removeRow(0)
        self.spins = {}
        names = self.round.blendshapes.names if self.round else ()
        for name in names:
            spin = QtWidgets.QDoubleSpinBox(minimum=UNRATED, maximum=1.0, singleStep=0.05, decimals=2)
            spin.setSpecialValueText("unrated")  # the minimum: never saved as a rating
            spin.setValue(UNRATED)
            spin.setToolTip("Type a weight 0-1 and press Enter (next blendshape; after the last: save). "
                            "Below 0: unrated")
            spin.valueChanged.connect(lambda *_: self._show_face())
            spin.installEventFilter(self)
            self.spins[name] = spin
            self._form.addRow(name, spin)
        self.save_button.setEnabled(bool(names))
        self.correct_shape.clear()
        self.correct_shape.addItems(list(names))

    def _fit_pictures(self) -> None:
        """Keep the pose frame and the face 4:3 at the width they get (on the frame's own resize: the
        panel's resize comes before its children's, so their width would be the previous one)."""
        height = max(_PICTURE_MIN[1], min(int(self.image.width() * 0.75), 260))
        for view in (self.image, self.face):
            if view.height() != height:
                view.setFixedHeight(height)

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 - Qt override
        """The pose frame resized: fit both pictures. Enter in a rating box: the next blendshape's
        box, and after the last one, save the pose."""
        if watched is self.image and event.type() == QtCore.QEvent.Type.Resize:
            self._fit_pictures()
            return False
        if (isinstance(event, QtGui.QKeyEvent) and event.type() == QtCore.QEvent.Type.KeyPress
                and event.key() in (QtCore.Qt.Key.Key_Return, QtCore.Qt.Key.Key_Enter)
                and not event.modifiers() & QtCore.Qt.KeyboardModifier.ControlModifier
                and watched in self.spins.values()):
            spin = watched
            assert isinstance(spin, QtWidgets.QDoubleSpinBox)
            spin.interpretText()
            boxes = list(self.spins.values())
            i = boxes.index(spin)
            if i + 1 < len(boxes):
                boxes[i + 1].setFocus()
                boxes[i + 1].selectAll()
            else:
                self.save_pose()
                if boxes and boxes[0].isEnabled():
                    boxes[0].setFocus()
                    boxes[0].selectAll()
            return True
        return super().eventFilter(watched, event)

    def typed(self) -> dict[str, float | None]:
        """The weights in the boxes, None where unrated."""
        return {n: (None if s.value() <= UNRATED + 1e-9 else round(s.value(), 4)) for n, s in self.spins.items()}

    def _show_face(self) -> None:
        weights = [0.0 if w is None else w for w in self.typed().values()]
        if weights:
            self.face.set_image(render_face(weights, (320, 240)))

    def _fill_poses(self) -> None:
        if self.round is None:
            _fill(self.poses, [])
            return
        done = sum(self.round.is_done(p.pose_id) for p in self.round.poses)
        n = len(self.round.poses)
        self.status.setText(f"Rater {self.rater}: {done} of {n} poses rated " + (
            "(round done: the agreement report is shown and your ratings are locked)" if done == n
            else "(blind: other raters' ratings stay hidden until you finish)"))
        _fill(self.poses, [[p.pose_id, p.session_id.split("_")[0], str(p.frame),
                            "\u2713" if self.round.is_done(p.pose_id) else ""] for p in self.round.poses])
        if self.poses.currentRow() < 0 and self.round.poses:
            self.poses.setCurrentCell(0, 0)  # selects the first pose and shows it
        else:
            self._show_pose(self.poses.currentRow())  # same row, new rater or ratings: show them

    def _show_pose(self, row: int) -> None:
        if self.round is None or not 0 <= row < len(self.round.poses):
            return
        pose = self.round.poses[row]
        try:
            self.image.set_image(read_frame(self.lab_dir / pose.session_id / "video.avi", pose.frame))
        except UserError as exc:
            self.image.setText(str(exc))
        in_lab_file = any((pose.pose_id, n) in self.round.locked for n in self.spins)
        locked = in_lab_file or self.round.complete
        for name, spin in self.spins.items():
            value = self.round.rating(pose.pose_id, name)
            spin.blockSignals(True)
            spin.setValue(UNRATED if value is None else value)
            spin.blockSignals(False)
            spin.setEnabled(not locked)
        self._show_face()
        self.save_button.setEnabled(not locked)
        self.save_button.setText("Rated in the lab's ratings.csv" if in_lab_file
                                 else "Round done: ratings locked" if locked else "Save my rating of this pose (Ctrl+Enter)")
        self.save_button.setToolTip("You have seen the agreement report: correct a typo below, with a reason"
                                    if locked and not in_lab_file else "")
        self.correct_box.setVisible(self.round.complete and not in_lab_file)

    def correct(self) -> None:
        """Correct the chosen blendshape of the selected pose after the round, with the typed reason (logged)."""
        row = self.poses.currentRow()
        if self.round is None or row < 0:
            return
        pose = self.round.poses[row]
        try:
            change = self.round.correct_rating(pose.pose_id, self.correct_shape.currentText(),
                                               self.correct_value.value(), self.correct_reason.text())
        except UserError as exc:
            self.status.setText(str(exc))
            return
        except OSError as exc:  # a full disk...: the log and the ratings are both as they were
            self.status.setText(f"{exc.filename}: could not save the correction ({exc.strerror or exc}); "
                                "nothing was logged or changed")
            return
        self.correct_reason.clear()
        self._show_pose(row)
        self.refresh_report()
        self.status.setText(f"{change.pose_id} {change.blendshape}: corrected {change.old:.2f} -> {change.new:.2f} "
                            f"({change.reason}); logged in reliability/{self.round.corrections_path.name}")

    def save_pose(self) -> None:
        """Save this rater's weights for the selected pose (atomic write of their ratings file)."""
        row = self.poses.currentRow()
        if self.round is None or row < 0:
            return
        pose = self.round.poses[row]
        typed = self.typed()
        rated = {n: w for n, w in typed.items() if w is not None}
        unrated = [n for n, w in typed.items() if w is None]
        if not rated:
            self.status.setText(f"{pose.pose_id}: every blendshape is unrated: type a weight (0-1) first; "
                                "an unrated shape is never saved as a rating")
            return
        try:
            for name, weight in rated.items():
                self.round.set_rating(pose.pose_id, name, weight)
        except UserError as exc:
            self.status.setText(str(exc))
            return
        self._fill_poses()
        if unrated:  # stay on the pose: the rest is still to rate
            self.status.setText(f"{pose.pose_id}: saved {len(rated)} rating{'s' * (len(rated) != 1)}; "
                                f"still unrated (not saved): {', '.join(unrated)}")
            return
        self.poses.setCurrentCell(min(row + 1, len(self.round.poses) - 1), 0)
        self.refresh_report()

    def propose(self) -> None:
        """Propose the pose set from the sessions' HR and phase extremes into ``reliability/poses.csv``."""
        try:
            sessions = [read_session(p) for p in list_sessions(self.lab_dir)]
            sessions = [s for s in sessions if s.frame_times_s]
            if not sessions:
                raise UserError(f"{self.lab_dir}: expected sessions with video, found none")
            per = -(-N_POSES // len(sessions))
            poses: list[Pose] = []
            for s in sessions:
                poses += propose_poses(s, per, first_id=len(poses) + 1)
            write_poses(self.lab_dir / "reliability" / "poses.csv", poses[:N_POSES])
        except (UserError, FileExistsError) as exc:
            self.status.setText(str(exc))
            return
        self.reload()

    # --------------------------------------------------------------------------------- report
    def refresh_report(self) -> None:
        """Compute and show the report if this rater has finished the round."""
        self.report = None
        if self.round is None or not self.round.complete:
            n = len(self.round.poses) if self.round else 0
            self.report_note.setText("")
            self.hidden_note.setText(
                f"The agreement report (tables and Bland-Altman plot) appears once you have rated all {n} "
                "poses.\n\nUntil then the other raters' ratings stay hidden, so your ratings are blind."
                if self.round else "No pose set yet: propose one (left) or ask the lab for reliability/poses.csv.")
            self._show_report()
            return
        try:
            ratings, source = gather_ratings(self.lab_dir)
            self.report = agreement_report(ratings, flag_pct=self.threshold.value(), source=source)
            self._refresh_machine(ratings)
        except UserError as exc:
            self.report_note.setText(str(exc))
        else:
            o = self.report.overall
            self.report_note.setText(
                f"{len(self.report.raters)} raters, {len(self.report.poses)} poses: mean |difference| "
                f"<b>{o.disagreement_pct:.1f} %</b> of the weight range (paper: 11 %), ICC(A,1) {o.icc_a1:.2f} "
                f"(95 % CI {o.icc_a1_ci[0]:.2f}-{o.icc_a1_ci[1]:.2f}), "
                f"alpha {o.alpha:.2f}. Flagged for review: {', '.join(self.report.flagged) or 'none'}.")
        self._show_report()

    def _refresh_machine(self, ratings: list) -> None:
        """The machine section, recomputed only when the ratings or the machine's values changed."""
        machine, no_face = machine_ratings(self.lab_dir, gather_poses(self.lab_dir))
        key = (tuple(ratings), tuple(machine))
        if key != self._machine_key:
            self.machine = machine_report(ratings, machine, no_face=no_face)
            self._machine_key = key

    def _show_machine(self) -> None:
        rep = self.machine if self.report is not None else None
        self.machine_box.setVisible(rep is not None)
        if rep is None:
            _fill(self.machine_table, [])
            return
        self.machine_note.setText(f"{machine_summary(rep)}<br>{rep.label[0].upper()}{rep.label[1:]} at the pose "
                                  f"frames: {rep.n_poses} poses; no face: {', '.join(rep.no_face) or 'none'}. "
                                  "Never in the human mean.")
        _fill(self.machine_table, [[s.reference, s.name, str(s.n_items), f"{s.icc_a1:.3f}", format_ci(s.icc_a1_ci),
                                    f"{s.alpha:.3f}", format_ci(s.alpha_ci), f"{s.mad_pct:.1f}",
                                    f"[{s.mad_pct_ci[0]:.1f}, {s.mad_pct_ci[1]:.1f}]"] for s in rep.stats])

    def _show_report(self) -> None:
        rep = self.report
        self._show_machine()
        self.results.setCurrentIndex(0 if rep is None else 1)
        # rating blind, the pictures take half the room; with the report, its tables take two thirds
        self._row.setStretch(1, 1 if rep is None else 2)
        if rep is None:
            _fill(self.per_pose, [])
            _fill(self.per_shape, [])
            _fill(self.pairs, [])
            self.ba_plot.clear()
            return
        poses = sorted(rep.per_pose_pct.items(), key=lambda pv: -pv[1])  # worst first: flagged on top
        _fill(self.per_pose, [[p, f"{v:.1f}", "FLAG" if p in rep.flagged else ""] for p, v in poses],
              {i for i, (p, _) in enumerate(poses) if p in rep.flagged})
        _fill(self.per_shape, [[s.name, str(s.n_items), f"{s.disagreement_pct:.1f}", f"{s.icc_a1:.3f}",
                                format_ci(s.icc_a1_ci), f"{s.icc_c1:.3f}", format_ci(s.icc_c1_ci),
                                f"{s.alpha:.3f}"] for s in [*rep.per_blendshape, rep.overall]])
        _fit_rows(self.per_shape, self.per_shape.rowCount())
        _fill(self.pairs, [[f"{p.rater_a}-{p.rater_b}", str(p.n), f"{p.bias:+.3f}", f"{p.loa_low:+.3f}",
                            f"{p.loa_high:+.3f}"] for p in rep.pairs])
        self._plot_bland_altman(rep)

    def _plot_bland_altman(self, rep: AgreementReport) -> None:
        """Offer the report's pairs (one at a time, or all) and draw the one chosen."""
        names = [f"{p.rater_a}-{p.rater_b}" for p in rep.pairs]
        mine = self._my_pairs_label() if any(self.rater in (p.rater_a, p.rater_b) for p in rep.pairs) else ""
        keep = self.ba_pair.currentText()
        self._report = rep
        self.ba_pair.blockSignals(True)
        self.ba_pair.clear()
        self.ba_pair.addItems([ALL_PAIRS, *names] + ([mine] if mine else []))
        # by default the pairs of the rater who reads the report (their own agreement first)
        self.ba_pair.setCurrentText(keep if keep and keep in (*names, ALL_PAIRS, mine) else
                                    mine or (names[0] if names else ALL_PAIRS))
        self.ba_pair.blockSignals(False)
        self._replot()

    def _my_pairs_label(self) -> str:
        """The Bland-Altman choice of every pair this panel's rater is in."""
        return f"{self.rater}'s pairs"

    def _pick_pair_row(self, row: int, *_: int) -> None:
        """A row of the pairs table picks that pair's Bland-Altman plot."""
        if row >= 0:
            self.ba_pair.setCurrentIndex(row + 1)

    def _replot(self) -> None:
        """Draw the chosen pair's Bland-Altman plot (all pairs overlaid if asked)."""
        rep = self._report
        if rep is None:
            return
        plot = self.ba_plot
        plot.clear()
        chosen = self.ba_pair.currentText()
        mine = chosen == self._my_pairs_label()
        drawn = [(i, p) for i, p in enumerate(rep.pairs) if chosen in (ALL_PAIRS, f"{p.rater_a}-{p.rater_b}")
                 or (mine and self.rater in (p.rater_a, p.rater_b))]
        plot.setTitle(f"Bland-Altman: {chosen if chosen != ALL_PAIRS else 'rater a - rater b, every pair'}")
        for i, p in drawn:
            colour = _PAIR_COLOURS[i % len(_PAIR_COLOURS)]
            plot.plot(p.means, p.diffs, pen=None, symbol="o", symbolSize=6, symbolPen=None,
                      symbolBrush=pg.mkColor(colour), name=f"{p.rater_a}-{p.rater_b}")
            for y, style in ((p.bias, QtCore.Qt.PenStyle.SolidLine), (p.loa_low, QtCore.Qt.PenStyle.DashLine),
                             (p.loa_high, QtCore.Qt.PenStyle.DashLine)):
                plot.addItem(pg.InfiniteLine(y, angle=0, pen=pg.mkPen(colour, style=style)))
        spread = max(0.3, float(np.max([np.max(np.abs(p.diffs)) for _, p in drawn] or [0.0])) * 1.15)
        plot.setXRange(0, 1, padding=0.02)
        plot.setYRange(-spread, spread, padding=0)
