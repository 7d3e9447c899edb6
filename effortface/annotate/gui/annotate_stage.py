"""The Annotate stage: key-frame the blendshape weights from the video, check inter-rater agreement.

:class:`QtAnnotateStage` (hosted by the main window, or run alone with ``python -m effortface.annotate.gui``)
holds the session browser, the rater code, the key-frame editor of the open session and the
reliability round. :class:`QtKeyframeEditor` views one
:class:`~effortface.annotate.annotate_session.AnnotateSession` (Qt-free: frame, blendshape, the rater's tracks,
undo history, autosave) and a :class:`~effortface.annotate.video_index.VideoIndex` (frame-exact decode cache
with prefetch): video and face preview side by side, the protocol panel, transport controls, heart
rate and the curve editor on the session's time axis (a splitter between the pictures and the
curves lets the curve editor grow), the undo history beside the curves (click a step to go back to
it), a timecode on the video, coloured curves that can be switched off, several keys selected and
moved or scaled together, keyboard zoom and a loop over a selection. Keyboard first: see
:data:`~effortface.annotate.gui.protocol_panel.HELP_TEXT`. The session list shows each rater's
complete tracks (:mod:`effortface.annotate.completeness`), e.g. ``R1 4/4``. Every edit is saved at once (atomic write), so
closing never asks and a crash loses nothing. Editing the rater code hides the open session and the
reliability round at once, until the new code is confirmed (blind raters never see another's keys
or ratings). The session list is read again each time the stage is shown (and on F5 / Rescan), and
playback pauses whenever the editor is out of sight.

The machine rater: "Pre-annotate" (side toolbar) rates the chosen sessions in the background
(:class:`~effortface.annotate.preannotate_run.PreannotateRun`: progress in the status line, the same
button cancels); the editor then draws the machine curves dashed under the rater's keys (one
"Machine" toggle per blendshape), shades the frames without a face, and "Accept machine" (A) turns
the machine curve of the current blendshape into key-frames over the loop, the selected keys' span
or else the visible time (Ramer-Douglas-Peucker within the tolerance shown, 0.03 by default; no key
where no face; one undo step). The reliability round's blind rating shows nothing of the machine.
"""

from __future__ import annotations

import functools
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from effortface.annotate.completeness import session_status, summary
from effortface.annotate.export import write_keyframes_json, write_weights_csv
from effortface.annotate.face import render_face
from effortface.annotate.gui.image_view import QtImageView
from effortface.annotate.gui.protocol_panel import HELP_TEXT, QtProtocolPanel
from effortface.core.gui.qt_compat import guard_none_refcount
from effortface.annotate.gui.reliability_panel import QtReliabilityPanel
from effortface.annotate.gui.timeline import FOLLOW_MODES, QtTimeline
from effortface.annotate.annotate_session import AnnotateSession, check_rater
from effortface.annotate.machine_guide import ACCEPT_TOLERANCE, KeyFit
from effortface.annotate.preannotate_run import PreannotateRun, has_track
from effortface.annotate.video_index import VideoIndex
from effortface.core.errors import UserError
from effortface.core.gui.widgets import QtElidedLabel
from effortface.core.session.folder import VIDEO_FRAMES_CSV, list_sessions, read_session_info, read_video_frames

SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: the side panel (sessions, rater) is this wide, and may shrink to SIDE_MIN_WIDTH on a small screen
SIDE_WIDTH, SIDE_MIN_WIDTH = 230, 170
PLAY_TICK_MS = 15
WEIGHT_NUDGE = 0.05
#: a selection of keys is scaled by this factor (]) or its inverse ([) about its mean weight
SCALE_STEP = 1.25
ZOOM_STEP = 1.5
#: the QSettings key of the timeline's follow mode (page, centre, off)
FOLLOW_KEY = "annotate/follow"
_ERROR_STYLE = "color:#842029;"
_INFO_STYLE = "color:#305030;"


class QtKeyframeEditor(QtWidgets.QWidget):
    """Video, face preview, protocol panel, transport and timeline of one annotation session.

    Parameters
    ----------
    session : AnnotateSession
        The rater's session (the editor writes back only through its methods).
    video : VideoIndex
        The session video (owned by the editor from now on: closed by :meth:`shutdown`).
    report : callable, optional
        ``report(message, is_error)`` shows a one-line message (the stage's status line).
    """

    def __init__(self, session: AnnotateSession, video: VideoIndex,
                 report: Callable[[str, bool], None] | None = None,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session, self.video = session, video
        self.report = report or (lambda message, is_error: None)
        self._face_weights: tuple[float, ...] | None = None
        self._play_timer = QtCore.QTimer(self, interval=PLAY_TICK_MS, timerType=QtCore.Qt.TimerType.PreciseTimer)
        self._play_timer.timeout.connect(self._play_tick)
        self._play_from: tuple[float, float] = (0.0, 0.0)
        self.loop: tuple[int, int] | None = None  # frames played over and over (L)
        self._build()
        self._add_shortcuts()
        self._return_focus_from_boxes()
        session.frame_changed.connect(self._show_frame)
        session.keys_changed.connect(lambda *_: self._show_face())
        session.file_changed.connect(self._show_saved)
        session.history_changed.connect(self._show_history)
        session.status_changed.connect(self._on_status)
        session.passes_changed.connect(lambda name: self.report(self._pass_note(name), False))
        self._show_frame(session.frame)

    # ---------------------------------------------------------------------------------- layout
    def _build(self) -> None:
        self.video_view = QtImageView("video", (240, 180))
        self.video_view.setFocusPolicy(QtCore.Qt.FocusPolicy.StrongFocus)
        self.face_view = QtImageView("face preview", (160, 120))
        self.face_view.setToolTip("The parametric face drawn from the four current weights: match it to the participant")
        self.protocol = QtProtocolPanel(self.session)
        self.timeline = QtTimeline(self.session)
        self.timeline.setMinimumHeight(150)
        pictures = QtWidgets.QHBoxLayout()
        pictures.addLayout(self._captioned(self.video_view, "Video"), 4)
        pictures.addLayout(self._captioned(self.face_view, "Face from the current weights"), 3)
        # a top pane made short with the splitter scrolls the panel, never clips it (at 1280x800 it fits)
        self.protocol_scroll = QtWidgets.QScrollArea()
        self.protocol_scroll.setWidget(self.protocol)
        self.protocol_scroll.setWidgetResizable(True)
        self.protocol_scroll.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
        self.protocol_scroll.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.protocol_scroll.setFixedWidth(self.protocol.sizeHint().width() + 16)
        pictures.addWidget(self.protocol_scroll, 0)
        top = QtWidgets.QWidget()
        top_layout = QtWidgets.QVBoxLayout(top)
        top_layout.setContentsMargins(0, 0, 0, 0)
        top_layout.addLayout(pictures, 1)
        top_layout.addLayout(self._build_transport())
        self.splitter = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        self.splitter.setChildrenCollapsible(False)
        self.splitter.addWidget(top)
        self.splitter.addWidget(self._build_curves_pane())
        self.splitter.setStretchFactor(0, 1)
        self.splitter.setStretchFactor(1, 2)  # a taller window mostly grows the curve editor
        # the curves' size hints would take half the height: start at 55:45 (the protocol panel fits
        # unscrolled at 1280x800 with room to spare, the video gets the rest)
        self.splitter.setSizes([500, 500])  # a tall curve editor; the splitter moves either way
        self._grown_from: int | None = None
        help_label = QtWidgets.QLabel(HELP_TEXT, wordWrap=True)
        help_label.setStyleSheet("color:#505050;")
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.splitter, 1)
        layout.addWidget(help_label)

    def _build_curves_pane(self) -> QtWidgets.QWidget:
        """The curve toggles over the timeline, the undo history beside it."""
        toggles = QtWidgets.QHBoxLayout()
        toggles.addWidget(QtWidgets.QLabel("Curves:"))
        self.curve_toggles: dict[str, QtWidgets.QCheckBox] = {}
        for name in self.session.blendshape_names:
            box = QtWidgets.QCheckBox(name)
            box.setChecked(True)
            box.setStyleSheet(f"QCheckBox {{ color:{self.timeline.colour(name)}; font-weight:bold; }}")
            box.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
            box.setToolTip(f"Show {name}'s curve behind the current one (the current one is always shown)")
            box.toggled.connect(functools.partial(self.timeline.set_shown, name))
            self.curve_toggles[name] = box
            toggles.addWidget(box)
        toggles.addStretch(1)
        self.loop_label = QtWidgets.QLabel("")
        toggles.addWidget(self.loop_label)
        toggles.addWidget(QtWidgets.QLabel("Follow:"))
        self.follow_box = QtWidgets.QComboBox()
        self.follow_box.addItems(list(FOLLOW_MODES))
        self.follow_box.setCurrentText(self.timeline.follow)
        self.follow_box.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)  # the keys stay the video's
        self.follow_box.setToolTip("How the timeline follows the play head: page (a new page when the cursor "
                                   "leaves the view), centre (the cursor stays in the middle), off (the view "
                                   "stays where you put it)")
        self.follow_box.currentTextChanged.connect(self.set_follow)
        toggles.addWidget(self.follow_box)
        machine_row = self._build_machine_row()
        self.history_view = QtWidgets.QListWidget()
        self.history_view.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.history_view.setToolTip("Your edits, oldest first; greyed: undone (redo with Ctrl+Y). "
                                     "Click a step to undo or redo back to it.")
        self.history_view.itemClicked.connect(self._on_history_click)
        history = QtWidgets.QVBoxLayout()
        history.setContentsMargins(0, 0, 0, 0)
        history.addWidget(QtWidgets.QLabel("<b>Undo history</b>"))
        history.addWidget(self.history_view, 1)
        history_box = QtWidgets.QWidget()
        history_box.setLayout(history)
        history_box.setFixedWidth(230)
        row = QtWidgets.QHBoxLayout()
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(self.timeline, 1)
        row.addWidget(history_box)
        pane = QtWidgets.QWidget()
        column = QtWidgets.QVBoxLayout(pane)
        column.setContentsMargins(0, 0, 0, 0)
        column.addLayout(toggles)
        column.addWidget(machine_row)
        column.addLayout(row, 1)
        machine_row.setVisible(self.session.machine is not None)  # it has a parent now: never a window
        self._show_history()
        return pane

    def set_follow(self, mode: str) -> None:
        """How the timeline follows the play head (one of :data:`~effortface.annotate.gui.timeline.FOLLOW_MODES`;
        an unknown mode, e.g. from an older settings file, is ignored)."""
        if mode not in FOLLOW_MODES:
            return
        self.timeline.follow = mode
        if self.follow_box.currentText() != mode:
            self.follow_box.setCurrentText(mode)
        self.timeline.follow_cursor(self.session.t_s)

    def _build_machine_row(self) -> QtWidgets.QWidget:
        """Machine guide toggles per blendshape, the accept tolerance and "Accept machine" (hidden without a track)."""
        row = QtWidgets.QHBoxLayout()
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(QtWidgets.QLabel("Machine (dashed):"))
        self.machine_toggles: dict[str, QtWidgets.QCheckBox] = {}
        for name in self.session.blendshape_names:
            box = QtWidgets.QCheckBox(name)
            box.setChecked(True)
            box.setStyleSheet(f"QCheckBox {{ color:{self.timeline.colour(name)}; }}")
            box.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
            box.setToolTip(f"Show the machine rater's {name} curve (dashed) as a guide under your keys")
            box.toggled.connect(functools.partial(self.timeline.set_machine_shown, name))
            self.machine_toggles[name] = box
            row.addWidget(box)
        row.addStretch(1)
        row.addWidget(QtWidgets.QLabel("tolerance"))
        self.accept_tolerance = QtWidgets.QDoubleSpinBox(minimum=0.0, maximum=0.5, value=ACCEPT_TOLERANCE,
                                                         decimals=3, singleStep=0.005)
        self.accept_tolerance.setFocusPolicy(QtCore.Qt.FocusPolicy.ClickFocus)
        self.accept_tolerance.setToolTip("Accept machine smooths the machine curve (1 s running median) and adds "
                                         "keys where it moves most, at most one per 3 s, until within this weight: "
                                         "larger, fewer keys. The keys stay the machine's (grey) until you edit them")
        row.addWidget(self.accept_tolerance)
        self.accept_button = QtWidgets.QPushButton("Accept machine (A)")
        self.accept_button.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.accept_button.setToolTip("Replace the current blendshape's keys by the machine curve over the loop, "
                                      "the selected keys' span, or else the time shown; none where no face; "
                                      "one undo step")
        self.accept_button.clicked.connect(lambda: self._guarded(self.accept_machine))
        row.addWidget(self.accept_button)
        self.machine_row = QtWidgets.QWidget()
        self.machine_row.setLayout(row)
        # hidden until it has a parent: setVisible(True) on a parentless widget opens it as a window of its
        # own, which takes the keyboard from the main window (_build_curves_pane shows it once laid out)
        self.machine_row.hide()
        return self.machine_row

    def accept_range(self) -> tuple[int, int]:
        """The frames "Accept machine" acts on: the loop, else the selected keys' span, else the time shown."""
        if self.loop is not None:
            return self.loop
        chosen = self.timeline.selection
        if len(chosen) >= 2:
            return chosen[0], chosen[-1]
        return self.timeline.visible_frames()

    def accept_machine(self) -> KeyFit:
        """Turn the machine curve into sparse key-frames over :meth:`accept_range` (one undo step)."""
        first, last = self.accept_range()
        return self.session.accept_machine(first, last, self.accept_tolerance.value())

    def refresh_machine(self) -> None:
        """Read the machine track again (after Pre-annotate) and show or hide its controls."""
        self.session.reload_machine()
        self.timeline.refresh_machine()
        self.machine_row.setVisible(self.session.machine is not None)

    def _pass_note(self, name: str) -> str:
        nxt = self.session.next_blendshape
        return f"pass on {name} done: press N for {nxt}" if nxt else f"pass on {name} done: every blendshape keyed"

    def _on_status(self, text: str, is_error: bool) -> None:
        """What the model did; while the current pass is done, the hint to go on stays in the line."""
        name = self.session.blendshape
        self.report(f"{text} \u00b7 {self._pass_note(name)}" if name in self.session.passes_done and not is_error
                    else text, is_error)

    def _show_history(self) -> None:
        """List the undo steps (the last one current) and the undone ones (grey)."""
        done, undone = self.session.history
        self.history_view.clear()
        self.history_view.addItem("(opened)")
        for label in done:
            self.history_view.addItem(label)
        current = self.history_view.count() - 1
        for label in undone:
            item = QtWidgets.QListWidgetItem(label)
            item.setForeground(QtGui.QColor("#a0a0a0"))
            self.history_view.addItem(item)
        self.history_view.setCurrentRow(current)
        self.history_view.scrollToItem(self.history_view.item(current))

    def _on_history_click(self, item: QtWidgets.QListWidgetItem) -> None:
        """Undo or redo until the clicked step is the last one done."""
        current = len(self.session.history[0])
        self._guarded(lambda: self.session.undo_to(current - self.history_view.row(item)))

    @staticmethod
    def _captioned(widget: QtWidgets.QWidget, caption: str) -> QtWidgets.QVBoxLayout:
        box = QtWidgets.QVBoxLayout()
        box.addWidget(QtWidgets.QLabel(f"<b>{caption}</b>"))
        box.addWidget(widget, 1)
        return box

    def _build_transport(self) -> QtWidgets.QHBoxLayout:
        row = QtWidgets.QHBoxLayout()
        steps = (("|\u25c0", "first frame (Home)", lambda: self.session.set_frame(0)),
                 ("\u25c0\u25c0", "10 frames back (Shift+\u2190)", lambda: self.session.step(-10)),
                 ("\u25c0", "one frame back (\u2190)", lambda: self.session.step(-1)),
                 ("\u25b6", "one frame on (\u2192)", lambda: self.session.step(1)),
                 ("\u25b6\u25b6", "10 frames on (Shift+\u2192)", lambda: self.session.step(10)),
                 ("\u25b6|", "last frame (End)", lambda: self.session.set_frame(self.session.n_frames - 1)))
        self.play_button = QtWidgets.QPushButton("Play (Space)")
        self.play_button.setCheckable(True)
        self.play_button.toggled.connect(self.set_playing)
        for i, (text, tip, slot) in enumerate(steps):
            if i == 3:
                row.addWidget(self.play_button)
            button = QtWidgets.QToolButton()
            button.setText(text)
            button.setToolTip(tip)
            button.setAutoRepeat(True)
            button.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
            button.clicked.connect(slot)
            row.addWidget(button)
        self._build_go_to(row)
        return row

    def _build_go_to(self, row: QtWidgets.QHBoxLayout) -> None:
        """Speed, frame and time boxes and the save state, after the transport buttons (one row).

        The save state elides when the window is narrow, so the row never widens the stage.
        """
        self.speed = QtWidgets.QComboBox()
        self.speed.addItems([f"{s:g}x" for s in SPEEDS])
        self.speed.setCurrentIndex(SPEEDS.index(1.0))
        self.speed.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.speed.currentIndexChanged.connect(lambda *_: self._restart_clock())
        self.frame_box = QtWidgets.QSpinBox(minimum=0, maximum=self.session.n_frames - 1)
        self.frame_box.editingFinished.connect(lambda: self._go(lambda: self.session.set_frame(self.frame_box.value())))
        self.time_box = QtWidgets.QDoubleSpinBox(minimum=0.0, maximum=self.session.times.duration_s, decimals=3,
                                                 suffix=" s")
        self.time_box.editingFinished.connect(lambda: self._go(lambda: self.session.go_to_time(self.time_box.value())))
        for box in (self.frame_box, self.time_box):
            box.setKeyboardTracking(False)
            box.setToolTip("Type a frame or time and press Enter; Esc cancels")
            box.installEventFilter(self)
        self.position = QtWidgets.QLabel(f"/ {self.session.n_frames - 1}")  # the last frame, after the frame box
        for label, widget in (("speed", self.speed), ("frame", self.frame_box), ("time", self.time_box)):
            row.addSpacing(8)
            row.addWidget(QtWidgets.QLabel(label))
            row.addWidget(widget)
            if widget is self.frame_box:
                row.addWidget(self.position)
        row.addSpacing(8)
        self.saved_label = QtElidedLabel("no edit yet", min_chars=8, mode=QtCore.Qt.TextElideMode.ElideRight)
        self.saved_label.setStyleSheet(_INFO_STYLE)
        row.addWidget(self.saved_label, 1)

    def _add_shortcuts(self) -> None:
        m = self.session
        Key = QtCore.Qt.Key
        bindings: list[tuple[Any, Callable[[], Any]]] = [
            (Key.Key_Right, lambda: m.step(1)), (Key.Key_Left, lambda: m.step(-1)),
            ("Shift+Right", lambda: m.step(10)), ("Shift+Left", lambda: m.step(-10)),
            (Key.Key_Home, lambda: m.set_frame(0)), (Key.Key_End, lambda: m.set_frame(m.n_frames - 1)),
            (Key.Key_K, lambda: m.set_key(self.protocol.number.value())),
            (Key.Key_M, lambda: m.set_key(1.0)),
            (Key.Key_Up, lambda: self.nudge(WEIGHT_NUDGE)), (Key.Key_Down, lambda: self.nudge(-WEIGHT_NUDGE)),
            (Key.Key_Delete, self.delete_key), (Key.Key_Backspace, self.delete_key),
            (Key.Key_Space, lambda: self.play_button.toggle()),
            (Key.Key_N, m.start_next_pass),
            (QtGui.QKeySequence.StandardKey.Undo, m.undo), ("Ctrl+Shift+Z", m.redo), ("Ctrl+Y", m.redo),
            (QtGui.QKeySequence.StandardKey.Copy, self.copy_key), (QtGui.QKeySequence.StandardKey.Paste, self.paste),
            ("Ctrl+G", self._select_frame_box),
            ("Ctrl+A", self.timeline.select_all), (Key.Key_Escape, self._escape),
            ("Alt+Right", lambda: self.shift_selection(1)), ("Alt+Left", lambda: self.shift_selection(-1)),
            ("Alt+Shift+Right", lambda: self.shift_selection(10)), ("Alt+Shift+Left", lambda: self.shift_selection(-10)),
            ("Alt+Up", lambda: self.shift_selection(0, WEIGHT_NUDGE)),
            ("Alt+Down", lambda: self.shift_selection(0, -WEIGHT_NUDGE)),
            (Key.Key_BracketRight, lambda: self.shift_selection(0, 0.0, SCALE_STEP)),
            (Key.Key_BracketLeft, lambda: self.shift_selection(0, 0.0, 1 / SCALE_STEP)),
            (Key.Key_Plus, lambda: self.timeline.zoom(ZOOM_STEP)), (Key.Key_Equal, lambda: self.timeline.zoom(ZOOM_STEP)),
            (Key.Key_Minus, lambda: self.timeline.zoom(1 / ZOOM_STEP)), (Key.Key_F, self.timeline.frame_all),
            (Key.Key_L, self.toggle_loop), (Key.Key_A, self.accept_machine),
        ]
        bindings += [(getattr(Key, f"Key_{d}"), functools.partial(m.set_key, d / 10)) for d in range(10)]
        for seq, slot in bindings:
            action = QtGui.QAction(self)
            action.setShortcut(QtGui.QKeySequence(seq))
            action.setShortcutContext(QtCore.Qt.ShortcutContext.WidgetWithChildrenShortcut)
            action.triggered.connect(lambda *_, s=slot: self._guarded(s))
            self.addAction(action)

    def _return_focus_from_boxes(self) -> None:
        """Enter (or Esc) in the weight or tolerance box hands the keyboard back to the video, as the frame
        and time boxes do: Right and the digits key frames again at once."""
        for box in (self.protocol.number, self.accept_tolerance):
            box.editingFinished.connect(functools.partial(self._focus_video_from, box))
            box.installEventFilter(self)

    def _focus_video_from(self, box: QtWidgets.QWidget) -> None:
        if box.hasFocus():
            self.video_view.setFocus()

    def _select_frame_box(self) -> None:
        """Ctrl+G: type the frame to go to."""
        self.frame_box.setFocus()
        self.frame_box.selectAll()

    # ------------------------------------------------------------------------------- actions
    def _guarded(self, slot: Callable[[], Any]) -> None:
        """Run a user action; show an expected error in the status line and keep the state (E4)."""
        try:
            slot()
        except (UserError, FileExistsError, KeyError) as exc:
            self.report(str(exc).strip("'\""), True)

    def _go(self, slot: Callable[[], Any]) -> None:
        self._guarded(slot)
        self.video_view.setFocus()

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 - Qt override
        """Esc in the frame or time box cancels the go-to and hands the keys back to the video."""
        if (isinstance(event, QtGui.QKeyEvent) and event.type() == QtCore.QEvent.Type.KeyPress
                and event.key() == QtCore.Qt.Key.Key_Escape):
            if watched in (self.frame_box, self.time_box):
                self.cancel_go_to()
                return True
            if watched in (self.protocol.number, self.accept_tolerance):
                self.video_view.setFocus()
                return True
        return super().eventFilter(watched, event)

    def _escape(self) -> None:
        """Esc: cancel a go-to being typed, leave the weight or tolerance box, else clear the key selection."""
        if self.frame_box.hasFocus() or self.time_box.hasFocus():
            self.cancel_go_to()
        elif self.protocol.number.hasFocus() or self.accept_tolerance.hasFocus():
            self.video_view.setFocus()
        else:
            self.timeline.select_key(None)

    def cancel_go_to(self) -> None:
        """Put the current frame and time back in their boxes and focus the video view."""
        for box, value in ((self.frame_box, self.session.frame), (self.time_box, self.session.t_s)):
            box.blockSignals(True)
            box.setValue(value)  # type: ignore[arg-type]  # int frame to frame_box, float t_s to time_box
            box.blockSignals(False)
        self.video_view.setFocus()

    def nudge(self, delta: float) -> None:
        """Key the current frame at its weight + ``delta`` (clipped to [0, 1])."""
        w = self.session.weight()
        self.session.set_key(min(max((0.0 if math.isnan(w) else w) + delta, 0.0), 1.0))

    def delete_key(self) -> None:
        """Delete the current blendshape's key on the current frame (where a selected key always is)."""
        frame = self.session.frame
        if self.session.delete_key(frame) is None:
            self.report(f"no {self.session.blendshape} key on frame {frame} to delete", True)

    def copy_key(self) -> None:
        """Copy the selected range of keys (several selected: first to last), else the current frame's key."""
        chosen = self.timeline.selection
        first, last = (chosen[0], chosen[-1]) if len(chosen) > 1 else (self.session.frame, self.session.frame)
        n = self.session.copy(first, last)
        where = f"frames {first}-{last}" if last > first else f"frame {first}"
        self.report(f"copied {n} key{'s' * (n != 1)} of {self.session.blendshape} ({where})", n == 0)

    def shift_selection(self, d_frames: int, d_weight: float = 0.0, scale: float = 1.0) -> None:
        """Move (frames, weight) or scale the selected keys together: one undo step."""
        chosen = self.timeline.selection or ([self.session.frame] if self.session.key_at() else [])
        if not chosen:
            self.report("select keys first (click, Shift+click, Ctrl+A)", True)
            return
        try:
            moved = self.session.shift_keys(chosen, d_frames, d_weight, scale)
        except UserError as exc:  # e.g. a key at the video's edge: nothing moved, and the line says why
            self.report(str(exc), True)
            return
        self.timeline.set_selection(moved)

    def toggle_loop(self) -> None:
        """L: loop playback over the selected keys' span (two or more), else the visible time; L again: off."""
        if self.loop is not None:
            self.loop = None
            self.loop_label.setText("")
            self.report("loop off", False)
            return
        chosen = self.timeline.selection
        if len(chosen) > 1:
            self.loop = (chosen[0], chosen[-1])
        else:
            lo, hi = self.timeline.curve_plot.viewRange()[0]
            self.loop = (self.session.times.frame_at(max(lo, 0.0)), self.session.times.frame_at(hi))
        a, b = self.loop
        self.loop_label.setText(f"⟲ loop {self.session.times.t_at(a):.1f}-{self.session.times.t_at(b):.1f} s (L: off)")
        self.report(f"looping frames {a}-{b}: Space plays them over and over", False)

    def paste(self) -> None:
        """Paste the copied keys at the current frame."""
        n = self.session.paste()
        self.report(f"pasted {n} key{'s' * (n != 1)} at frame {self.session.frame}", n == 0)

    # ------------------------------------------------------------------------------- playback
    @property
    def playing(self) -> bool:
        """Whether the video is playing."""
        return self._play_timer.isActive()

    def set_playing(self, on: bool) -> None:
        """Start or stop playback at the chosen speed (real session time, frames from the timestamps)."""
        if on and self.loop is not None and not self.loop[0] <= self.session.frame < self.loop[1]:
            self.session.set_frame(self.loop[0])
        elif on and self.session.frame >= self.session.n_frames - 1:
            self.session.set_frame(0)
        if on:
            self._restart_clock()
            self._play_timer.start()
        else:
            self._play_timer.stop()
        if self.play_button.isChecked() != on:
            self.play_button.setChecked(on)
        self.play_button.setText("Pause (Space)" if on else "Play (Space)")

    def hideEvent(self, event: QtGui.QHideEvent) -> None:  # noqa: N802 - Qt override
        """Pause playback when the editor goes out of sight (another stage, tab or rater)."""
        self.set_playing(False)
        super().hideEvent(event)

    def _restart_clock(self) -> None:
        self._play_from = (self.session.t_s, time.perf_counter())

    def _play_tick(self) -> None:
        t0_s, wall0 = self._play_from
        speed = SPEEDS[self.speed.currentIndex()]
        self.session.go_to_time(t0_s + speed * (time.perf_counter() - wall0))
        if self.loop is not None and self.session.frame >= self.loop[1]:
            self.session.set_frame(self.loop[0])
            self._restart_clock()
        elif self.session.frame >= self.session.n_frames - 1:
            self.set_playing(False)

    # ------------------------------------------------------------------------------- display
    def _show_frame(self, frame: int) -> None:
        try:
            self.video_view.set_image(self.video.get(frame))
        except UserError as exc:
            self.video_view.setText(str(exc))
        self.video_view.set_overlay(f"{timecode(self.session.t_s)}  frame {frame}")
        for box, value in ((self.frame_box, frame), (self.time_box, self.session.t_s)):
            if not box.hasFocus():
                box.blockSignals(True)
                box.setValue(value)  # type: ignore[arg-type]  # int frame to frame_box, float t_s to time_box
                box.blockSignals(False)
        self._show_face()

    def _show_saved(self, path: Path) -> None:
        self.saved_label.setText(f"\u2714 all keys saved at {time.strftime('%H:%M:%S')}")
        self.saved_label.setToolTip(f"every key is saved to {path} as soon as it is set")

    def _show_face(self) -> None:
        weights = tuple(0.0 if math.isnan(w) else w for w in self.session.weights().values())
        if weights == self._face_weights:
            return
        self._face_weights = weights
        self.face_view.set_image(render_face(weights, (320, 240)))

    def shutdown(self) -> None:
        """Stop playback, forget the model's listeners, close the video and free the rater file."""
        self._play_timer.stop()
        self.session.disconnect_all()
        self.session.close()
        self.video.close()


def time_left(elapsed_s: float, fraction: float) -> str:
    """``"about 2 min 10 s left"`` at the pace so far (``"estimating..."`` before 2 % or 2 s)."""
    if fraction < 0.02 or elapsed_s < 2.0:
        return "estimating time left..."
    left_s = elapsed_s * (1.0 - fraction) / fraction
    minutes, seconds = divmod(int(round(left_s)), 60)
    return f"about {minutes} min {seconds:02d} s left" if minutes else f"about {seconds} s left"


def timecode(t_s: float) -> str:
    """``h:mm:ss.mmm`` of a session time."""
    ms = int(round(max(t_s, 0.0) * 1000))
    return f"{ms // 3_600_000}:{ms // 60_000 % 60:02d}:{ms // 1000 % 60:02d}.{ms % 1000:03d}"


def _centred_note() -> QtWidgets.QLabel:
    label = QtWidgets.QLabel(alignment=QtCore.Qt.AlignmentFlag.AlignCenter, wordWrap=True)
    label.setMinimumWidth(200)
    return label


class QtAnnotateStage(QtWidgets.QWidget):
    """The Annotate stage: session browser, rater, key-frame editor and reliability round.

    Parameters
    ----------
    sessions_dir : Path
        The lab's folder of sessions.
    settings : QSettings, optional
        Remembers the rater code (``annotate/rater``).
    cache_frames : int
        Decoded frames the video cache keeps.
    """

    def __init__(self, sessions_dir: str | os.PathLike, settings: QtCore.QSettings | None = None,
                 cache_frames: int = 256, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        guard_none_refcount()  # PySide6 6.12.0 on CPython 3.11 leaks references to None: see qt_compat
        self.sessions_dir = Path(sessions_dir)
        self.settings = settings
        self.cache_frames = cache_frames
        self.editor: QtKeyframeEditor | None = None
        self.preannotate = PreannotateRun()
        self.preannotate.progress_changed.connect(self._show_preannotate_progress)
        self._pre_started = 0.0
        self.preannotate.finished.connect(self._preannotated)
        self._pre_timer = QtCore.QTimer(self, interval=100)
        self._pre_timer.timeout.connect(self.preannotate.poll)
        #: asked before replacing machine tracks (tests replace it): ``confirm_replace(n_sessions) -> bool``
        self.confirm_replace: Callable[[int], bool] = self._ask_replace
        self._build()
        self.refresh_sessions()

    # ---------------------------------------------------------------------------------- layout
    def _build(self) -> None:
        self.sessions = QtWidgets.QListWidget()
        self.sessions.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.ExtendedSelection)
        self.sessions.itemDoubleClicked.connect(lambda *_: self.open_selected())
        rater = str(self.settings.value("annotate/rater", "")) if self.settings is not None else ""
        self.rater = QtWidgets.QLineEdit(rater, placeholderText="your code, e.g. R1", maxLength=32)
        self.rater.textChanged.connect(self._on_rater_edited)
        self.rater.editingFinished.connect(self._on_rater_confirmed)
        self.rater.returnPressed.connect(lambda: self.open_selected() if self.tabs.currentIndex() == 0 else None)
        self.open_button = QtWidgets.QPushButton("Open session")
        self.open_button.clicked.connect(self.open_selected)
        self.rescan_button = QtWidgets.QPushButton("Rescan (F5)")
        self.rescan_button.setToolTip("List the sessions recorded since")
        self.rescan_button.clicked.connect(self.refresh_sessions)
        self.preannotate_button = QtWidgets.QPushButton("Pre-annotate")
        self.preannotate_button.setToolTip("Rate the chosen sessions (Ctrl/Shift+click for several) with the machine "
                                           "rater (face landmarker): its curves become dashed guides in the editor. "
                                           "Click again to cancel")
        self.preannotate_button.clicked.connect(self.toggle_preannotate)
        self.status = QtWidgets.QLabel(wordWrap=True)
        self.status.setMinimumHeight(36)
        self.editor_host = QtWidgets.QStackedWidget()
        self.placeholder = _centred_note()
        self.editor_host.addWidget(self.placeholder)
        self.reliability: QtReliabilityPanel | None = None
        self.reliability_host = QtWidgets.QStackedWidget()
        self.reliability_note = _centred_note()
        self.reliability_host.addWidget(self.reliability_note)
        self._show_notes()
        self.tabs: QtWidgets.QTabWidget = QtWidgets.QTabWidget()  # typed here: a lambda above reads it
        self.tabs.addTab(self.editor_host, "Key-frames")
        self.tabs.addTab(self.reliability_host, "Reliability round")
        self.tabs.currentChanged.connect(self._on_tab)
        layout = QtWidgets.QHBoxLayout(self)
        self.side = self._build_side()
        layout.addWidget(self.side)
        layout.addWidget(self.tabs, 1)
        self.side_button = QtWidgets.QToolButton()
        self.side_button.setText("\u25c0 Hide sessions")
        self.side_button.setToolTip("Hide or show the session list, for a wider video and timeline (Ctrl+B)")
        self.side_button.clicked.connect(self.toggle_side)
        self.tabs.setCornerWidget(self.side_button, QtCore.Qt.Corner.TopLeftCorner)
        self._add_shortcut("F5", self.refresh_sessions)
        self._add_shortcut("Ctrl+B", self.toggle_side)

    def toggle_side(self) -> bool:
        """Hide the session list (more room for the video and the timeline), or show it again;
        return whether it is shown."""
        shown = self.side.isHidden()
        self.side.setVisible(shown)
        self.side_button.setText("\u25c0 Hide sessions" if shown else "\u25b6 Sessions")
        return shown

    def _build_side(self) -> QtWidgets.QWidget:
        buttons = QtWidgets.QHBoxLayout()
        buttons.addWidget(self.open_button, 1)
        buttons.addWidget(self.rescan_button)
        left = QtWidgets.QVBoxLayout()
        sessions_title = QtWidgets.QLabel("<b>Sessions</b> (each rater's complete tracks)", wordWrap=True)
        sessions_title.setToolTip("R1 4/4: rater R1 has 4 complete tracks of 4 (keys over the whole video with no "
                                  "gap over 30 s, pass finished); only complete tracks are used for training")
        left.addWidget(sessions_title)
        left.addWidget(self.sessions, 1)
        left.addWidget(QtWidgets.QLabel("<b>Rater</b> (you see only your own keys)", wordWrap=True))
        left.addWidget(self.rater)
        left.addLayout(buttons)
        left.addWidget(self.preannotate_button)
        self.pre_progress = QtWidgets.QProgressBar(maximum=1000, textVisible=True)
        self.pre_progress.setToolTip("Pre-annotate: the share of the chosen sessions' frames rated, and the time "
                                     "left at the pace so far")
        self.pre_progress.hide()
        left.addWidget(self.pre_progress)
        left.addWidget(self._build_toolbar())
        left.addWidget(self.status)
        side = QtWidgets.QWidget()
        side.setLayout(left)
        side.setMinimumWidth(SIDE_MIN_WIDTH)
        side.setMaximumWidth(SIDE_WIDTH)
        side.setSizePolicy(QtWidgets.QSizePolicy.Policy.Preferred, QtWidgets.QSizePolicy.Policy.Preferred)
        self.sessions.setTextElideMode(QtCore.Qt.TextElideMode.ElideRight)  # the id's date stays readable;
        # the whole line (and each rater's tracks) is in the item's tooltip
        self.sessions.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        return side

    def _add_shortcut(self, seq: str, slot: Callable[[], Any]) -> None:
        action = QtGui.QAction(self)
        action.setShortcut(QtGui.QKeySequence(seq))
        action.setShortcutContext(QtCore.Qt.ShortcutContext.WidgetWithChildrenShortcut)
        action.triggered.connect(lambda *_: slot())
        self.addAction(action)

    def _build_toolbar(self) -> QtWidgets.QWidget:
        bar = QtWidgets.QToolBar()
        bar.setToolButtonStyle(QtCore.Qt.ToolButtonStyle.ToolButtonTextOnly)
        self.undo_action = bar.addAction("Undo", lambda: self._on_editor(lambda e: e.session.undo()))
        self.redo_action = bar.addAction("Redo", lambda: self._on_editor(lambda e: e.session.redo()))
        self._refresh_undo()
        export = QtWidgets.QMenu("Export", self)
        self.export_weights_action = export.addAction("Per-frame weights CSV\u2026", lambda: self.export_weights())
        self.export_keys_action = export.addAction("Key-frames JSON\u2026", lambda: self.export_keyframes())
        button = QtWidgets.QToolButton(popupMode=QtWidgets.QToolButton.ToolButtonPopupMode.InstantPopup)
        button.setText("Export \u25be")
        button.setMenu(export)
        bar.addWidget(button)
        self.export_menu = export
        return bar

    def chosen_sessions(self) -> list[Path]:
        """The sessions selected in the list (Ctrl/Shift+click for several), else the current one."""
        items = self.sessions.selectedItems() or ([self.sessions.currentItem()] if self.sessions.currentItem() else [])
        return [Path(i.data(QtCore.Qt.ItemDataRole.UserRole)) for i in items if i is not None]

    def toggle_preannotate(self) -> None:
        """Start Pre-annotate on the chosen sessions, or cancel the run under way."""
        if self.preannotate.busy:
            self.preannotate.cancel()
            self.show_message("pre-annotate: cancelling...")
            return
        chosen = self.chosen_sessions()
        if not chosen:
            self.show_message("pre-annotate: choose sessions in the list first", True)
            return
        existing = sum(has_track(s) for s in chosen)
        force = bool(existing) and self.confirm_replace(existing)
        self.preannotate.start(chosen, force=force)
        self._pre_started = time.perf_counter()
        self.pre_progress.setValue(0)
        self.pre_progress.setFormat("starting...")
        self.pre_progress.show()
        self.preannotate_button.setText("Cancel pre-annotate")
        self.show_message(f"pre-annotate: {len(chosen)} session{'s' * (len(chosen) != 1)} started")
        self._pre_timer.start()

    def _ask_replace(self, n: int) -> bool:
        answer = QtWidgets.QMessageBox.question(
            self, "Pre-annotate", f"{n} of the chosen sessions have a machine track already. Replace them?")
        return answer == QtWidgets.QMessageBox.StandardButton.Yes

    def _show_preannotate_progress(self, fraction: float, text: str) -> None:
        """The bar: share done and the time left at the pace so far; the status line: what is being rated."""
        elapsed_s = time.perf_counter() - self._pre_started
        self.pre_progress.setValue(int(round(1000 * min(max(fraction, 0.0), 1.0))))
        self.pre_progress.setFormat(f"{100 * fraction:.0f} %, {time_left(elapsed_s, fraction)}")
        self.show_message(f"pre-annotate: {text}")

    def _preannotated(self, text: str, is_error: bool, outcome: Any) -> None:
        self.pre_progress.hide()
        self._pre_timer.stop()
        self.preannotate_button.setText("Pre-annotate")
        self.show_message(text, is_error)
        if self.editor is not None:
            self.editor.refresh_machine()

    def _on_editor(self, fn: Callable[[QtKeyframeEditor], Any]) -> None:
        editor = self.shown_editor()
        if editor is None:
            self.show_message("open a session first", True)
        else:
            fn(editor)

    def _refresh_undo(self) -> None:
        """Undo/Redo enabled only when there is something to undo/redo, their tooltips say what."""
        editor = self.shown_editor()
        m = editor.session if editor is not None else None
        self.undo_action.setEnabled(bool(m and m.can_undo))
        self.redo_action.setEnabled(bool(m and m.can_redo))
        self.undo_action.setToolTip(f"Undo {m.undo_text} (Ctrl+Z)" if m and m.can_undo else "Nothing to undo")
        self.redo_action.setToolTip(f"Redo {m.redo_text} (Ctrl+Y)" if m and m.can_redo else "Nothing to redo")

    def shown_editor(self) -> QtKeyframeEditor | None:
        """The open session's editor if it is shown (its rater is the confirmed rater code), else None."""
        return self.editor if self.editor is not None and self.editor_host.currentWidget() is self.editor else None

    def undo_target(self) -> AnnotateSession | None:
        """The model the main window's Edit > Undo/Redo drive: the shown editor's session, or None."""
        editor = self.shown_editor()
        return editor.session if editor is not None else None

    # ----------------------------------------------------------------------------------- rater
    def _on_rater_edited(self, text: str) -> None:
        """Hide the open session and the reliability round as soon as the code no longer names their rater.

        They come back only when a code is confirmed (Enter, leaving the field, Open session), so a
        rater typing ``R12`` never sees ``R1``'s keys or report on the way.
        """
        rater = text.strip()
        hidden = False
        if (editor := self.shown_editor()) is not None and editor.session.rater != rater:
            self.editor_host.setCurrentWidget(self.placeholder)
            hidden = True
        if self.reliability is not None and self.reliability.rater != rater:
            hidden = hidden or self.reliability_host.currentWidget() is self.reliability
            self.reliability_host.setCurrentWidget(self.reliability_note)
        if hidden:
            self.show_message("rater code changed: press Enter to confirm it")
        self._show_notes()
        self._refresh_undo()

    def _on_rater_confirmed(self) -> None:
        """The typed code is confirmed: show that rater's open session or reliability round."""
        rater = self.rater.text().strip()
        if self.editor is not None and self.editor.session.rater == rater:
            self.editor_host.setCurrentWidget(self.editor)
            self.show_message(f"rater {rater}: {self.editor.session.session.info.session_id} shown again")
        elif "press Enter" in self.status.text():
            self.show_message(f"rater {rater or '(none)'} confirmed: open a session" if self.tabs.currentIndex() == 0
                              else f"rater {rater or '(none)'} confirmed")
        if self.tabs.currentIndex() == 1:
            self.open_reliability()
        self._refresh_undo()

    def _show_notes(self) -> None:
        rater = self.rater.text().strip() or "your code"
        self.placeholder.setText(
            f"The open session is hidden while the rater code changes: press Enter or Open session "
            f"to open the selected session as {rater}." if self.editor is not None
            else "Choose a session, type your rater code and press Open session.")
        self.reliability_note.setText("Type your rater code and press Enter to join the reliability round.")

    def _on_tab(self, index: int) -> None:
        if index == 1:
            self.open_reliability()
        else:
            self.focus_main()

    def show_message(self, message: str, is_error: bool = False) -> None:
        """One line in the status area (errors in red)."""
        self.status.setStyleSheet(_ERROR_STYLE if is_error else _INFO_STYLE)
        self.status.setText(message)

    # -------------------------------------------------------------------------------- sessions
    def refresh_sessions(self) -> None:
        """List the session folders that have video (again), keeping the selected one selected."""
        item = self.sessions.currentItem()
        selected = Path(item.data(QtCore.Qt.ItemDataRole.UserRole)) if item is not None else None
        self.sessions.clear()
        try:
            folders = list_sessions(self.sessions_dir)
        except UserError as exc:
            self.show_message(str(exc), True)
            return
        for folder in folders:  # list_sessions leaves out a session being recorded
            if not (folder / "video_frames.csv").is_file() or not _complete(folder):
                continue
            text, tip = self._describe(folder)
            item = QtWidgets.QListWidgetItem(text)
            item.setData(QtCore.Qt.ItemDataRole.UserRole, str(folder))
            item.setToolTip(tip)
            self.sessions.addItem(item)
        if self.sessions.count():
            self.sessions.setCurrentRow(0)
        if selected is not None:
            self._select_listed(selected)

    def showEvent(self, event: QtGui.QShowEvent) -> None:  # noqa: N802 - Qt override
        """List the sessions again each time the stage is shown (Capture may have recorded one)."""
        super().showEvent(event)
        if not event.spontaneous():
            self.refresh_sessions()

    def focus_main(self) -> None:
        """Give the keyboard to the stage's main widget (the video of the open session, else the list)."""
        reliability, editor = self.reliability, self.shown_editor()
        if self.tabs.currentIndex() == 1 and reliability is not None \
                and self.reliability_host.currentWidget() is reliability:
            reliability.poses.setFocus()
        elif editor is not None:
            editor.video_view.setFocus()
        else:
            self.sessions.setFocus()

    @staticmethod
    def _describe(folder: Path) -> tuple[str, str]:
        """The list text (name, participant, each rater's complete tracks) and its tooltip (details)."""
        try:
            info = read_session_info(folder)
            p = info.participant
            who = f"{p.sex or '?'}, {p.age:g} y" if p.age else (p.sex or "")
        except UserError:
            who = "unreadable session.json"
        try:
            status = session_status(folder, read_video_frames(folder / VIDEO_FRAMES_CSV))
        except (UserError, OSError) as exc:
            return f"{folder.name}\n   {who}\n   annotations: unreadable", str(exc)
        raters = "  ".join(f"{r} {summary(st)}" for r, st in status.items()) or "not annotated yet"
        details = "\n".join(f"{r}: " + "; ".join(f"{n} " + ("complete" if s.complete else s.reason)
                                                for n, s in st.items()) for r, st in status.items())
        return (f"{folder.name}\n   {who}\n   {raters}",
                f"{folder}\n{details or 'not annotated yet'}\n(complete: keys over the whole video with no gap "
                "over 30 s, pass finished; only complete tracks are used for training)")

    def open_selected(self) -> None:
        """Open the selected session for the typed rater."""
        item = self.sessions.currentItem()
        if item is None:
            self.show_message("choose a session first", True)
            return
        self.open_session(Path(item.data(QtCore.Qt.ItemDataRole.UserRole)), self.rater.text().strip())

    def open_session(self, folder: str | os.PathLike, rater: str) -> QtKeyframeEditor | None:
        """Open ``folder`` for ``rater`` (their file only); an expected error is shown, not raised."""
        try:
            check_rater(rater)
            session = AnnotateSession(folder, rater)
            video = VideoIndex.from_session(folder, cache_frames=self.cache_frames)
        except UserError as exc:
            self.show_message(str(exc), True)
            return None
        self.close_session()
        if self.rater.text().strip() != rater:
            self.rater.setText(rater)  # the field names whose keys are shown
        self._select_listed(Path(folder))
        self.editor = QtKeyframeEditor(session, video, self.show_message)
        self.editor_host.addWidget(self.editor)
        self.editor_host.setCurrentWidget(self.editor)
        session.history_changed.connect(self._refresh_undo)
        session.passes_changed.connect(lambda *_: self._describe_open())
        session.file_changed.connect(lambda *_: self._describe_open())
        self._refresh_undo()
        self.tabs.setCurrentIndex(0)
        self.editor.video_view.setFocus()
        if self.settings is not None:
            self.settings.setValue("annotate/rater", rater)
            self.editor.set_follow(str(self.settings.value(FOLLOW_KEY, self.editor.timeline.follow)))
            settings = self.settings
            self.editor.follow_box.currentTextChanged.connect(lambda mode: settings.setValue(FOLLOW_KEY, mode))
            self._resume(self.editor)
        keys = sum(len(t) for t in session.annotations.tracks.values())
        self.show_message(f"{session.session.info.session_id}: rater {rater}, {keys} keys "
                          f"({'file ' + session.path.name if session.path.exists() else 'new file on first key'})")
        return self.editor

    def _describe_open(self) -> None:
        """Update the open session's line in the list (its completeness changes as the rater keys)."""
        if self.editor is None:
            return
        folder = self.editor.session.session.path
        for row in range(self.sessions.count()):
            item = self.sessions.item(row)
            if Path(item.data(QtCore.Qt.ItemDataRole.UserRole)) == folder:
                text, tip = self._describe(folder)
                item.setText(text)
                item.setToolTip(tip)

    def _select_listed(self, folder: Path) -> None:
        """Highlight ``folder`` in the session list (when it is listed)."""
        for row in range(self.sessions.count()):
            if Path(self.sessions.item(row).data(QtCore.Qt.ItemDataRole.UserRole)) == folder:
                self.sessions.setCurrentRow(row)

    def _place_key(self, session: AnnotateSession) -> str:
        return f"annotate/place/{session.session.info.session_id}/{session.rater}"

    def _resume(self, editor: QtKeyframeEditor) -> None:
        """Go back to the blendshape and frame where this rater left this session (remembered at close)."""
        assert self.settings is not None
        place = str(self.settings.value(self._place_key(editor.session), ""))
        name, _, frame = place.rpartition("@")
        if name in editor.session.blendshape_names and frame.isdigit():
            editor.session.set_blendshape(name)
            editor.session.set_frame(int(frame))
            editor.timeline.follow_cursor(editor.session.t_s)

    def close_session(self) -> None:
        """Close the open session (nothing to save: every edit is already on disk; the place the rater
        stopped at is remembered for the next opening)."""
        if self.editor is not None and self.settings is not None:
            m = self.editor.session
            self.settings.setValue(self._place_key(m), f"{m.blendshape}@{m.frame}")
        if self.editor is not None:
            self.editor.shutdown()
            self.editor_host.removeWidget(self.editor)
            self.editor.deleteLater()
            self.editor = None
            self._show_notes()
            self._refresh_undo()

    def open_reliability(self) -> QtReliabilityPanel | None:
        """Show the reliability round for the typed rater."""
        rater = self.rater.text().strip()
        try:
            check_rater(rater)
        except UserError as exc:
            self.reliability_host.setCurrentWidget(self.reliability_note)
            self.show_message(str(exc), True)
            return None
        if self.reliability is None:
            self.reliability = QtReliabilityPanel(self.sessions_dir, rater)
            self.reliability_host.addWidget(self.reliability)
        elif self.reliability.rater != rater:
            self.reliability.set_rater(rater)
        self.reliability_host.setCurrentWidget(self.reliability)
        return self.reliability

    # ---------------------------------------------------------------------------------- export
    def export_weights(self, path: str | os.PathLike | None = None, *, overwrite: bool = False) -> Path | None:
        """Write the open session's per-frame weights CSV (asks for a file name when ``path`` is None)."""
        return self._export("weights.csv", "CSV (*.csv)", path, overwrite,
                            lambda e, p, o: write_weights_csv(e.session.annotations, e.session.times, p, overwrite=o))

    def export_keyframes(self, path: str | os.PathLike | None = None, *, overwrite: bool = False) -> Path | None:
        """Write the open session's key-frame JSON (asks for a file name when ``path`` is None)."""
        return self._export("keyframes.json", "JSON (*.json)", path, overwrite,
                            lambda e, p, o: write_keyframes_json(e.session.annotations, p, overwrite=o))

    def _export(self, suffix: str, filter_: str, path: str | os.PathLike | None, overwrite: bool,
                write: Callable[[QtKeyframeEditor, Path, bool], Path]) -> Path | None:
        editor = self.shown_editor()
        if editor is None:
            self.show_message("open a session first", True)
            return None
        if path is None:  # the dialog asks before replacing a file: that is the explicit choice
            default = editor.session.session.path / f"{editor.session.rater}_{suffix}"
            chosen, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Export", str(default), filter_)
            if not chosen:
                return None
            path, overwrite = chosen, True
        try:
            out = write(editor, Path(path), overwrite)
        except (FileExistsError, OSError, UserError) as exc:
            self.show_message(str(exc), True)
            return None
        self.show_message(f"exported {out}")
        return out

    # ------------------------------------------------------------------------------ lifecycle
    def may_close(self) -> bool:
        """Always: every key is saved when it is set."""
        return True

    def shutdown(self) -> None:
        """Stop playback, the video prefetch thread and a Pre-annotate run."""
        self._pre_timer.stop()
        self.preannotate.shutdown()
        self.close_session()


def _complete(folder: Path) -> bool:
    """True for a session its capture finished (an incomplete one is recovered in Capture first);
    an unreadable session.json is listed too, with its error, rather than hidden."""
    try:
        return read_session_info(folder).complete
    except UserError:
        return True
