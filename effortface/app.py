"""The effortface application: one main window hosting the stages Capture, Annotate, Train, Synthesize.

``effortface app [DIR]`` opens it on a folder of sessions; ``--screenshot PATH [--stage NAME]
[--size WxH]`` renders one stage offscreen to a PNG and exits (tests, docs, a look without a display).
The window has a menu bar (File: open a lab folder, quit; Edit: undo/redo of the current stage's
model, for a stage that has one; View: the four stages, Ctrl+1..4; Help: the keyboard map, the
shipped documents, About), a status bar naming the stage and the folder, and remembers its geometry
and the stages' splitter positions in QSettings.
Unexpected errors anywhere (GUI thread or worker threads) are logged and shown in a dialog
(the rule: expected errors are shown inside the window and the previous state is kept); expected ones are shown inside the stage that raised them.
"""

from __future__ import annotations

import argparse
import functools
import html
import logging
import os
import sys
import threading
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path
from types import TracebackType
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from effortface.core.docs import DESIGN, SCIENCE, doc_path
from effortface.core.errors import UserError
from effortface.core.fileio import check_new_png
from effortface.core.gui.gui_gc import collect_in_gui_thread
from effortface.core.gui.qt_messages import install_message_filter

log = logging.getLogger("effortface.app")

#: stage key (``--stage``) -> title in the stage list
#: the settings key of the model folder Train exported last (offered in Synthesize)
LAST_MODEL_KEY = "synth/last_model"
STAGES = {"capture": "Capture", "annotate": "Annotate", "train": "Train", "synthesize": "Synthesize"}
#: what each stage does (shown if a stage cannot be built, e.g. a missing optional module)
_WHAT = {
    "capture": "records a heart-rate strap and the face video with participant data and phases",
    "annotate": "key-frames the four blendshape weights on the session videos, one blendshape at "
                "a time, and checks inter-rater agreement",
    "train": "fits the heart-rate model and the four face SVRs, evaluates them like the paper and "
             "exports a model bundle (headless: effortface train / evaluate)",
    "synthesize": "drives a character's face from a motion clip with an exported model "
                  "(headless: effortface synth)",
}
ORGANIZATION, APPLICATION = "effortface", "effortface"
SCREENSHOT_SIZE = (1400, 900)
#: keys the main window itself handles (Help > Keyboard map; the stages' keys follow)
WINDOW_KEYS = (
    ("Ctrl+1 .. Ctrl+4", "show Capture, Annotate, Train, Synthesize"),
    ("Ctrl+O", "open a lab folder"),
    ("Ctrl+Q", "quit"),
)
#: keys of the Annotate stage (the guide, docs/guide/annotate.md)
ANNOTATE_KEYS = (
    ("Left / Right", "previous / next frame"),
    ("Shift+Left / Shift+Right", "ten frames back / on"),
    ("Home / End", "first / last frame"),
    ("Space", "play / pause"),
    ("0 .. 9", "key the weight 0.0 .. 0.9 at this frame"),
    ("M", "key the weight 1.0"),
    ("Up / Down", "nudge the weight"),
    ("Del", "delete the key"),
    ("N", "next blendshape, after a pass over the video"),
    ("Ctrl+Z / Ctrl+Y", "undo / redo (also Edit menu)"),
    ("Ctrl+C / Ctrl+V", "copy / paste keys"),
    ("Ctrl+G", "go to frame"),
    ("K", "key the weight typed in the weight box"),
    ("Backspace", "delete the key (as Del)"),
    ("Ctrl+Shift+Z", "redo (as Ctrl+Y)"),
    ("Ctrl+A / Esc", "select every key of the track / clear the selection"),
    ("Shift+click", "add a key to the selection"),
    ("Alt+Left / Alt+Right", "move the selected keys one frame (refused if a key would leave the video)"),
    ("Alt+Shift+Left / Alt+Shift+Right", "move the selected keys ten frames"),
    ("Alt+Up / Alt+Down", "raise / lower the selected keys' weights"),
    ("[ / ]", "flatten / stretch the selected keys' weights about their mean"),
    ("+ / = / -", "zoom the timeline in / in / out"),
    ("F", "frame the whole track"),
    ("L", "loop over the selected keys (else the visible time); L again: off"),
    ("Ctrl+B", "hide / show the session list"),
    ("A", "accept the machine rater's curve as keys over the loop, the selection or the time shown"),
)


def _key_rows(sections: Iterable[tuple[str, Iterable[tuple[str, str]]]]) -> str:
    """HTML rows of the keyboard map: each section's title, then one row per key."""
    return "".join(f"<tr><td colspan=2><b>{title}</b></td></tr>"
                   + "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(v)}</td></tr>" for k, v in keys)
                   for title, keys in sections)


class QtKeyboardMap(QtWidgets.QDialog):
    """Help > Keyboard map: the keys in a scroll area no taller than the screen's available height (the
    whole map in sight at 1280x800; a smaller screen scrolls it).

    Parameters
    ----------
    text : str
        The map as rich text (:meth:`MainWindow.keyboard_map_html`).
    parent : QWidget, optional
        The main window.
    """

    def __init__(self, text: str, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("effortface: keyboard map")
        self.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
        self.label = QtWidgets.QLabel(text)
        self.label.setTextFormat(QtCore.Qt.TextFormat.RichText)
        self.label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.label.setMargin(6)
        self.label.setWordWrap(True)  # a narrow screen wraps the descriptions, never scrolls sideways
        self.scroll_area = QtWidgets.QScrollArea()
        self.scroll_area.setWidgetResizable(True)
        self.scroll_area.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.scroll_area.setWidget(self.label)
        self.scroll_area.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.StandardButton.Close)
        buttons.rejected.connect(self.close)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.scroll_area, 1)
        layout.addWidget(buttons)
        self._fit_screen(parent.screen() if parent is not None else QtGui.QGuiApplication.primaryScreen())

    def text(self) -> str:
        """The map's rich text."""
        return self.label.text()

    def _fit_screen(self, screen: QtGui.QScreen | None) -> None:
        """As big as the map, at most the available screen (less the title bar's room)."""
        room = screen.availableGeometry().size() if screen is not None else QtCore.QSize(1280, 800)
        max_h, max_w = room.height() - 40, room.width() - 40
        self.setMaximumSize(max_w, max_h)
        doc = QtGui.QTextDocument()
        doc.setDefaultFont(self.label.font())
        doc.setHtml(self.label.text())
        width = min(int(doc.idealWidth()) + 60, max_w)  # unwrapped, with the margins and a scroll bar
        want_h = self.label.heightForWidth(width - 40) + 70  # the Close button's row
        self.resize(width, min(want_h, max_h))


def guard_refcounts() -> bool:
    """Protect the process from the reference leak of PySide6 6.12.0 on CPython 3.11, if present.

    Every void Qt call made from Python drops a reference to None (and ``Signal.emit`` one to
    True); a window that redraws for minutes would abort with "Fatal Python error: none_dealloc".
    The Annotate stage's guard (:mod:`effortface.core.gui.qt_compat`) detects the bug and neutralises it
    process-wide; PySide6 below 6.12 does not have it. Returns whether the guard is on.
    """
    try:
        from effortface.core.gui.qt_compat import guard_none_refcount
    except ImportError:  # pragma: no cover - the annotate GUI is part of the distribution
        return False
    return guard_none_refcount()


def make_settings() -> QtCore.QSettings:
    """The user's UI preferences (last port, window geometry); ``EFFORTFACE_SETTINGS`` overrides the file."""
    path = os.environ.get("EFFORTFACE_SETTINGS")
    if path:
        return QtCore.QSettings(path, QtCore.QSettings.Format.IniFormat)
    return QtCore.QSettings(ORGANIZATION, APPLICATION)


class QtPlaceholderStage(QtWidgets.QWidget):
    """A stage that could not be built: says what it does, why it is missing, and lists the sessions.

    Parameters
    ----------
    key : str
        Stage key (``annotate``, ``train``, ``synthesize``).
    sessions_dir : Path
        The folder of sessions the application was opened on.
    reason : str
        Why the real stage could not be built (shown to the user).
    """

    def __init__(self, key: str, sessions_dir: Path, reason: str = "",
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        why = f"<p>Not available here: {html.escape(reason)}</p>" if reason else ""
        title = QtWidgets.QLabel(f"<h2>{STAGES[key]}</h2><p>This stage {_WHAT[key]}.</p>{why}",
                                 wordWrap=True)
        self.sessions = QtWidgets.QListWidget()
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(title)
        layout.addWidget(QtWidgets.QLabel(f"Sessions in {sessions_dir}:"))
        layout.addWidget(self.sessions, 1)
        self.refresh(sessions_dir)

    def refresh(self, sessions_dir: Path) -> None:
        """List the session folders of ``sessions_dir`` with their state."""
        self.sessions.clear()
        for line in describe_sessions(sessions_dir):
            self.sessions.addItem(line)


def folder_note(sessions_dir: Path) -> str:
    """The status-bar line naming where recordings and key-frames are written."""
    from effortface.samplelab import data_root

    note = f"Recordings and key-frames are saved in {sessions_dir.resolve()}"
    if data_root() in sessions_dir.resolve().parents:
        note += " (your copy of the sample lab, in the user data folder)"
    return note


def describe_sessions(sessions_dir: Path) -> list[str]:
    """One line per session in ``sessions_dir`` (id, participant, complete or not)."""
    from effortface.core.session.folder import list_sessions, read_session_info

    if not sessions_dir.is_dir():
        return [f"(no folder {sessions_dir} yet: Capture creates it with the first recording)"]
    lines = []
    for folder in list_sessions(sessions_dir):
        try:
            info = read_session_info(folder)
        except UserError as exc:
            lines.append(f"{folder.name}: unreadable ({exc})")
            continue
        state = "complete" if info.complete else "INCOMPLETE (recover it in Capture)"
        lines.append(f"{info.session_id}   participant {info.participant.code}   {state}")
    return lines or [f"(no sessions in {sessions_dir} yet)"]


def make_stage(key: str, sessions_dir: Path, settings: QtCore.QSettings) -> QtWidgets.QWidget:
    """Build the widget of stage ``key`` (imports its Qt code only now).

    Raises
    ------
    ImportError, UserError
        If the stage's code is not there yet or cannot open its data (the caller shows why in
        a :class:`QtPlaceholderStage`).
    """
    if key == "capture":
        from effortface.capture_tool.capture_session import CaptureSession
        from effortface.capture_tool.gui.capture_stage import QtCaptureStage

        return QtCaptureStage(CaptureSession(sessions_dir), settings)
    if key == "annotate":
        from effortface.annotate.gui.annotate_stage import QtAnnotateStage

        return QtAnnotateStage(sessions_dir, settings)
    if key == "train":
        from effortface.train.gui.train_stage import QtTrainStage
        from effortface.train.train_session import TrainSession

        return QtTrainStage(TrainSession(sessions_dir))
    from effortface.synth.gui.synth_stage import QtSynthStage
    from effortface.synth.synth_session import SynthSession

    return QtSynthStage(SynthSession(background=True), motion_dir=sessions_dir)


class MainWindow(QtWidgets.QMainWindow):
    """The main window: a stage list on the left, the chosen stage on the right.

    Capture is built at once (it offers to recover crashed sessions at start); the other stages
    are built the first time they are shown. A stage whose code is missing or cannot start shows
    a placeholder that says why and lists the sessions. A stage with a ``focus_main()`` method
    gets the keyboard each time it is shown (it gives the focus to its main widget); a stage with an
    ``undo_target()`` method (returning a model with ``undo()``, ``redo()``, ``can_undo``,
    ``can_redo``, or None) gets the Edit menu's Undo/Redo. The window's geometry and each stage's
    splitters (``splitters/<stage>/<index>`` in the settings) are saved on close.

    Parameters
    ----------
    sessions_dir : path-like
        Folder of session folders (new recordings go there too).
    settings : QSettings, optional
        UI preferences (default: :func:`make_settings`).
    """

    def __init__(self, sessions_dir: str | os.PathLike, settings: QtCore.QSettings | None = None) -> None:
        super().__init__()
        guard_refcounts()
        self.sessions_dir = Path(sessions_dir)
        self.settings = settings if settings is not None else make_settings()
        self.setWindowTitle(f"effortface - {self.sessions_dir}")
        self.folder_label = QtWidgets.QLabel(folder_note(self.sessions_dir))
        self.folder_label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.stage_label = QtWidgets.QLabel()
        self.stages: dict[str, QtWidgets.QWidget] = {}
        self.stage_list = QtWidgets.QListWidget()
        self.stack = QtWidgets.QStackedWidget()
        self._slots: dict[str, QtWidgets.QWidget] = {}
        self.stage_actions: dict[str, QtGui.QAction] = {}
        self.recording_indicator = QtWidgets.QLabel(wordWrap=True)
        self._build()
        self._build_menus()
        self._connect_capture()
        self._restore_geometry()

    def _build(self) -> None:
        self.stage_list.setFixedWidth(150)
        font = self.stage_list.font()
        font.setPointSize(font.pointSize() + 3)
        self.stage_list.setFont(font)
        for key, title in STAGES.items():
            self.stage_list.addItem(title)
            slot = QtWidgets.QWidget()
            QtWidgets.QVBoxLayout(slot).setContentsMargins(0, 0, 0, 0)
            self._slots[key] = slot
            self.stack.addWidget(slot)
        self._ensure_stage("capture")
        self.stage_list.currentRowChanged.connect(self._on_stage_changed)
        central = QtWidgets.QWidget()
        layout = QtWidgets.QHBoxLayout(central)
        layout.setContentsMargins(4, 4, 4, 4)
        left = QtWidgets.QVBoxLayout()
        left.addWidget(self.stage_list, 1)
        left.addWidget(self.recording_indicator)
        layout.addLayout(left)
        layout.addWidget(self.stack, 1)
        self.setCentralWidget(central)
        self.statusBar().addWidget(self.stage_label)
        self.statusBar().addPermanentWidget(self.folder_label, 1)
        self.stage_list.setCurrentRow(0)

    # ------------------------------------------------------------------------------------ menus
    def _build_menus(self) -> None:
        """File, Edit, View and Help."""
        bar = self.menuBar()
        file_menu = bar.addMenu("&File")
        self.open_action = file_menu.addAction("&Open lab folder\u2026", self.choose_folder)
        self.open_action.setShortcut(QtGui.QKeySequence.StandardKey.Open)
        file_menu.addSeparator()
        quit_action = file_menu.addAction("&Quit", self.close)
        quit_action.setShortcut(QtGui.QKeySequence.StandardKey.Quit)
        self.edit_menu = bar.addMenu("&Edit")
        # the stage binds Ctrl+Z / Ctrl+Y itself, on its own widgets: the menu shows the keys after a
        # tab (not as shortcuts of its own, which Qt would find ambiguous with the stage's)
        self.undo_action = self.edit_menu.addAction("&Undo\tCtrl+Z", self.undo)
        self.redo_action = self.edit_menu.addAction("&Redo\tCtrl+Y", self.redo)
        self.edit_menu.aboutToShow.connect(self._update_edit_actions)
        view_menu = bar.addMenu("&View")
        for row, (key, title) in enumerate(STAGES.items()):
            action = view_menu.addAction(title, functools.partial(self.show_stage, key))
            action.setShortcut(QtGui.QKeySequence(f"Ctrl+{row + 1}"))
            action.setCheckable(True)
            self.stage_actions[key] = action
        help_menu = bar.addMenu("&Help")
        help_menu.addAction("&Keyboard map", self.show_keyboard_map)
        for cited, what in ((DESIGN, "Design: formats and commands"), (SCIENCE, "Science: the model")):
            help_menu.addAction(f"{what} ({cited})", functools.partial(self.open_doc, cited))
        help_menu.addSeparator()
        help_menu.addAction("&About effortface", self.show_about)
        self._update_edit_actions()

    def undo_target(self) -> Any:
        """The current stage's model with undo/redo (the stage's ``undo_target()``), or None."""
        target = getattr(self.current_stage(), "undo_target", None)
        return target() if target is not None else None

    def _update_edit_actions(self) -> None:
        target = self.undo_target()
        self.undo_action.setEnabled(bool(target is not None and getattr(target, "can_undo", False)))
        self.redo_action.setEnabled(bool(target is not None and getattr(target, "can_redo", False)))

    def undo(self) -> None:
        """Edit > Undo: undo the last edit of the current stage's model."""
        target = self.undo_target()
        self._after_undo_redo("undo", target is not None and target.undo())

    def redo(self) -> None:
        """Edit > Redo: redo the last undone edit of the current stage's model."""
        target = self.undo_target()
        self._after_undo_redo("redo", target is not None and target.redo())

    def _after_undo_redo(self, what: str, done: bool) -> None:
        """Say in the status bar when there was nothing to undo/redo; update the Edit menu."""
        if not done:
            where = "" if self.undo_target() is not None else " here"
            self.statusBar().showMessage(f"{STAGES[self.current_key()]}: nothing to {what}{where}", 5000)
        self._update_edit_actions()

    def keyboard_map_html(self) -> str:
        """The keyboard map (Help menu): the window's keys, Capture's hotkeys, Annotate's keys (the
        several-key edits too) and Synthesize's player keys."""
        from effortface.capture_tool.gui.phases import (END_KEY, EXERCISE_KEY, LOAD_KEY, MARKER_KEY, PHASE_KEYS,
                                                        PHASE_TITLES, REP_KEY, SYNC_KEY)

        capture = [(key, f"phase: {PHASE_TITLES[phase]}") for phase, key in PHASE_KEYS.items()]
        capture += [(EXERCISE_KEY, "phase: the exercise picked, with its parameters"), (END_KEY, "end the phase"),
                    (REP_KEY, "one repetition"), (MARKER_KEY, "marker"), (LOAD_KEY, "load / speed change"),
                    (SYNC_KEY, "sync test (a white flash)")]
        from effortface.synth.gui.synth_stage import PLAYER_KEYS

        # two columns (the window's, Capture's and Synthesize's keys | Annotate's): half the height of one list
        columns = ((("Everywhere", WINDOW_KEYS), ("Capture", capture), ("Synthesize", PLAYER_KEYS)),
                   (("Annotate", ANNOTATE_KEYS),))
        cells = "".join(f"<td valign=top style='padding-right:18px'><table cellspacing=3>{_key_rows(column)}"
                        "</table></td>" for column in columns)
        return f"<table><tr>{cells}</tr></table>"

    def show_keyboard_map(self) -> QtKeyboardMap:
        """Help > Keyboard map (a non-modal box, returned): two columns, never taller than the screen."""
        box = QtKeyboardMap(self.keyboard_map_html(), self)
        box.open()
        return box

    def about_html(self) -> str:
        """Help > About: the version, what the program is, where its documents are."""
        from effortface import __version__

        docs = "".join(f"<br>{html.escape(c)}: {html.escape(str(doc_path(c)))}" for c in (DESIGN, SCIENCE))
        return (f"<h3>effortface {__version__}</h3><p>Facial expressions of physical effort: capture, "
                "annotate, train, synthesize (after Boukhalfi, Desrosiers &amp; Paquette, WSCG 2015).</p>"
                f"<p>Documents:{docs}</p>")

    def show_about(self) -> QtWidgets.QMessageBox:
        """Help > About (a non-modal box, returned)."""
        return self._info_box("About effortface", self.about_html())

    def _info_box(self, title: str, text: str) -> QtWidgets.QMessageBox:
        box = QtWidgets.QMessageBox(QtWidgets.QMessageBox.Icon.Information, title, text, parent=self)
        box.setTextFormat(QtCore.Qt.TextFormat.RichText)
        box.setAttribute(QtCore.Qt.WidgetAttribute.WA_DeleteOnClose)
        box.open()
        return box

    def open_doc(self, cited: str) -> bool:
        """Open a shipped document (``docs/DESIGN.md``) with the desktop's viewer."""
        path = doc_path(cited)
        self.statusBar().showMessage(f"opening {path}", 5000)
        return QtGui.QDesktopServices.openUrl(QtCore.QUrl.fromLocalFile(str(path)))

    # ------------------------------------------------------------------------------ lab folder
    def choose_folder(self) -> None:
        """File > Open lab folder: ask for a folder of sessions and open it."""
        folder = QtWidgets.QFileDialog.getExistingDirectory(self, "Open lab folder", str(self.sessions_dir))
        if folder:
            self.open_folder(folder)

    def open_folder(self, folder: str | os.PathLike) -> bool:
        """Re-open every stage on ``folder`` (refused while a stage may not close, e.g. recording).

        Returns
        -------
        bool
            Whether the folder was opened.
        """
        if not self._stages_may_close():
            return False
        self._save_layout()
        self.shutdown()
        for widget in self.stages.values():
            widget.setParent(None)
            widget.deleteLater()
        self.stages.clear()
        self.sessions_dir = Path(folder)
        self.setWindowTitle(f"effortface - {self.sessions_dir}")
        self.folder_label.setText(folder_note(self.sessions_dir))
        self._ensure_stage("capture")
        self._on_stage_changed(self.stage_list.currentRow())
        return True
    def _connect_capture(self) -> None:
        """A recording shows in every stage (the indicator under the stage list), and the Capture
        stage's hotkeys (F1-F8, enabled while recording) work from every stage."""
        self.recording_indicator.setFixedWidth(150)
        self.recording_indicator.setMargin(6)
        self.recording_indicator.hide()
        capture = self.stages.get("capture")
        session = getattr(capture, "session", None)
        if capture is None or session is None:
            return
        self.addActions(getattr(capture, "hotkeys", []))
        self._indicator_timer = QtCore.QTimer(self, interval=500)
        self._indicator_timer.timeout.connect(self._show_recording_indicator)
        session.state_changed.connect(lambda _state: self._show_recording_indicator())
        session.phase_changed.connect(lambda _phase: self._show_recording_indicator())

    def _show_recording_indicator(self) -> None:
        """'REC h:mm:ss, participant, phase' in red under the stage list while Capture records."""
        session = self.stages["capture"].session  # type: ignore[attr-defined]  # a QtCaptureStage
        recorder = session.recorder
        item = self.stage_list.item(0)
        if session.state not in ("recording", "stopping") or recorder is None:
            self.recording_indicator.hide()
            self._indicator_timer.stop()
            item.setText(STAGES["capture"])
            return
        elapsed = int(recorder.clock())
        phase = session.current_exercise or "no phase"
        self.recording_indicator.setText(
            f"<b>\u25CF REC {elapsed // 3600}:{elapsed % 3600 // 60:02d}:{elapsed % 60:02d}</b><br>"
            f"{html.escape(recorder.participant.code)}, {html.escape(phase)}<br>"
            f"<small>F1-F8 work in every stage</small>")
        self.recording_indicator.setStyleSheet("background: #b00020; color: white; border-radius: 4px;")
        self.recording_indicator.show()
        item.setText(f"{STAGES['capture']} \u25CF")
        if not self._indicator_timer.isActive():
            self._indicator_timer.start()

    def _ensure_stage(self, key: str) -> QtWidgets.QWidget:
        """Build stage ``key`` into its slot if not done yet; return its widget."""
        if key not in self.stages:
            try:
                widget = make_stage(key, self.sessions_dir, self.settings)
            except Exception as exc:  # noqa: BLE001 - one broken stage must not take the window down
                log.warning("stage %s not available: %s", key, exc, exc_info=not isinstance(exc, UserError))
                widget = QtPlaceholderStage(key, self.sessions_dir, reason=str(exc))
            self._slots[key].layout().addWidget(widget)  # type: ignore[union-attr]  # built with one
            self.stages[key] = widget
            self._restore_splitters(key, widget)
            self._link_last_model(key, widget)
        return self.stages[key]

    def _link_last_model(self, key: str, widget: QtWidgets.QWidget) -> None:
        """The model Train exported last is remembered (``synth/last_model``) and offered in Synthesize."""
        session = getattr(widget, "session", None)
        if key == "train" and hasattr(session, "export_changed"):
            session.export_changed.connect(self._model_exported)  # type: ignore[union-attr]
        if key == "synthesize" and hasattr(widget, "offer_model"):
            last = str(self.settings.value(LAST_MODEL_KEY, "") or "")
            if last and Path(last).is_dir():
                widget.offer_model(last)

    def _model_exported(self, path: object) -> None:
        """Train exported a model to ``path``: remember it, and offer it in Synthesize if built."""
        self.settings.setValue(LAST_MODEL_KEY, str(path))
        synth = self.stages.get("synthesize")
        if synth is not None and hasattr(synth, "offer_model"):
            synth.offer_model(str(path))

    def current_key(self) -> str:
        """The key of the stage shown."""
        return list(STAGES)[max(self.stage_list.currentRow(), 0)]

    def current_stage(self) -> QtWidgets.QWidget | None:
        """The widget of the stage shown (None before it is built)."""
        return self.stages.get(self.current_key())

    def _on_stage_changed(self, row: int) -> None:
        key = list(STAGES)[row]
        widget = self._ensure_stage(key)
        self.stack.setCurrentIndex(row)
        for other, action in self.stage_actions.items():
            action.setChecked(other == key)
        self.stage_label.setText(f"{STAGES[key]}  (Ctrl+{row + 1})")
        if self.stage_actions:
            self._update_edit_actions()
        if isinstance(widget, QtPlaceholderStage):
            widget.refresh(self.sessions_dir)
        focus_main = getattr(widget, "focus_main", None)
        if focus_main is not None:  # the keys go to the stage's main widget, not the stage list
            focus_main()

    def show_stage(self, key: str) -> QtWidgets.QWidget:
        """Switch to stage ``key`` and return its widget.

        Raises
        ------
        UserError
            If ``key`` is not a stage.
        """
        if key not in STAGES:
            raise UserError(f"--stage: expected one of {', '.join(STAGES)}, found {key!r}")
        self.stage_list.setCurrentRow(list(STAGES).index(key))
        return self._ensure_stage(key)

    def _restore_geometry(self) -> None:
        geometry = self.settings.value("main_window/geometry")
        if isinstance(geometry, QtCore.QByteArray) and not geometry.isEmpty():
            self.restoreGeometry(geometry)
        else:
            self.resize(*SCREENSHOT_SIZE)

    @staticmethod
    def _splitters(widget: QtWidgets.QWidget) -> list[QtWidgets.QSplitter]:
        """The splitters of a stage, in creation order (their settings keys are their index)."""
        return widget.findChildren(QtWidgets.QSplitter)

    def _restore_splitters(self, key: str, widget: QtWidgets.QWidget) -> None:
        """Put back the splitter positions saved for stage ``key`` (``splitters/<stage>/<i>``)."""
        for index, splitter in enumerate(self._splitters(widget)):
            state = self.settings.value(f"splitters/{key}/{index}")
            if isinstance(state, QtCore.QByteArray) and not state.isEmpty():
                splitter.restoreState(state)

    def _save_layout(self) -> None:
        """Save the window geometry and every built stage's splitter positions."""
        self.settings.setValue("main_window/geometry", self.saveGeometry())
        for key, widget in self.stages.items():
            for index, splitter in enumerate(self._splitters(widget)):
                self.settings.setValue(f"splitters/{key}/{index}", splitter.saveState())
        self.settings.sync()

    def _stages_may_close(self) -> bool:
        """Ask every stage whether it may close (Capture asks while recording)."""
        for widget in self.stages.values():
            may_close = getattr(widget, "may_close", None)
            if may_close is not None and not may_close():
                return False
        return True

    def shutdown(self) -> None:
        """Stop every stage's timers and background work without asking or saving (screenshots)."""
        for widget in self.stages.values():
            stop = getattr(widget, "shutdown", None)
            if stop is not None:
                stop()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:  # noqa: N802 - Qt override
        """Ask every stage whether it may close (Capture asks while recording); save the layout."""
        if not self._stages_may_close():
            event.ignore()
            return
        self._save_layout()
        self.shutdown()
        event.accept()


# ---------------------------------------------------------------------------- exception hooks
class _ErrorRelay(QtCore.QObject):
    """Carries an error report from any thread to a dialog on the GUI thread."""

    error = QtCore.Signal(str, str)  # summary, details


def install_exception_hooks(parent: QtWidgets.QWidget | None = None,
                            show: Callable[[str, str], None] | None = None) -> Callable[[], None]:
    """Route unexpected exceptions (``sys.excepthook``, ``threading.excepthook``) to the log and a dialog.

    Parameters
    ----------
    parent : QWidget, optional
        Parent of the dialog.
    show : callable, optional
        ``show(summary, details)`` on the GUI thread (default: a critical QMessageBox).

    Returns
    -------
    callable
        Restores the previous hooks.
    """
    relay = _ErrorRelay()
    relay.error.connect(show or (lambda summary, details: _error_dialog(parent, summary, details)),
                        QtCore.Qt.ConnectionType.QueuedConnection)
    old_sys, old_thread = sys.excepthook, threading.excepthook

    def _report(exc_type: type[BaseException], exc: BaseException, tb: TracebackType | None,
                where: str) -> None:
        details = "".join(traceback.format_exception(exc_type, exc, tb))
        log.error("unexpected error in %s:\n%s", where, details)
        relay.error.emit(f"Unexpected error in {where}: {exc_type.__name__}: {exc}", details)

    def _sys_hook(exc_type: type[BaseException], exc: BaseException, tb: TracebackType | None) -> None:
        _report(exc_type, exc, tb, "the application")

    def _thread_hook(args: threading.ExceptHookArgs) -> None:
        name = args.thread.name if args.thread is not None else "a worker thread"
        _report(args.exc_type, args.exc_value or args.exc_type(), args.exc_traceback, f"thread {name!r}")

    sys.excepthook, threading.excepthook = _sys_hook, _thread_hook
    _relays.append(relay)

    def restore() -> None:
        """Put the previous hooks back."""
        sys.excepthook, threading.excepthook = old_sys, old_thread
        if relay in _relays:
            _relays.remove(relay)

    return restore


_relays: list[_ErrorRelay] = []  # keeps relays alive as long as their hooks are installed


def _error_dialog(parent: QtWidgets.QWidget | None, summary: str, details: str) -> None:
    box = QtWidgets.QMessageBox(QtWidgets.QMessageBox.Icon.Critical, "effortface: unexpected error",
                                summary + "\n\nThe recording, if any, goes on. The details are in the log.",
                                parent=parent)
    box.setDetailedText(details)
    box.exec()


# ---------------------------------------------------------------------------------- entry point
def _check_screenshot_path(path: str) -> Path:
    return check_new_png("--screenshot", path)


def _check_dir(path: str) -> Path:
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise UserError(f"DIR: expected a folder of sessions, found a file {path!r}")
    return folder


def wait_settled(window: MainWindow, timeout_s: float = 5.0) -> bool:
    """Process events until every stage's background checks are done (or ``timeout_s``)."""
    deadline = QtCore.QDeadlineTimer(int(timeout_s * 1000))
    while not deadline.hasExpired():
        QtWidgets.QApplication.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 50)
        settled = [getattr(w, "settled", lambda: True)() for w in window.stages.values()]
        if all(settled):
            break
        QtCore.QThread.msleep(20)
    for _ in range(3):
        QtWidgets.QApplication.processEvents()
    return all(getattr(w, "settled", lambda: True)() for w in window.stages.values())


def parse_size(text: str | None) -> tuple[int, int]:
    """``--size WxH`` (``1280x800``) as (width, height) in pixels; None gives :data:`SCREENSHOT_SIZE`.

    Raises
    ------
    UserError
        Unless ``text`` is two whole numbers from 320 to 8192 joined by ``x``.
    """
    if text is None:
        return SCREENSHOT_SIZE
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() and 320 <= int(p) <= 8192 for p in parts):
        raise UserError(f"--size: expected WIDTHxHEIGHT in pixels (320-8192 each, e.g. 1280x800), found {text!r}")
    return int(parts[0]), int(parts[1])


def render_screenshot(window: MainWindow, stage: str, out: Path,
                      size: tuple[int, int] = SCREENSHOT_SIZE) -> Path:
    """Show ``stage`` in ``window`` at ``size`` (default: the documentation size), save it as a PNG."""
    window.show_stage(stage)
    window.resize(*size)
    window.show()
    wait_settled(window)
    if not window.grab().save(str(out), "PNG"):
        raise UserError(f"--screenshot: expected a writable PNG path, could not write {str(out)!r}")
    return out


def check_display(offscreen: bool) -> None:
    """Refuse in one line when there is no display to open a window on (``offscreen``: a screenshot
    is rendered offscreen instead, so any machine will do). Called before anything is built or copied.

    Raises
    ------
    UserError
        No ``$DISPLAY``, ``$WAYLAND_DISPLAY`` or ``$QT_QPA_PLATFORM`` on Linux and not a screenshot.
    """
    if offscreen:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
        return
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
            or os.environ.get("QT_QPA_PLATFORM") or sys.platform in ("win32", "darwin")):
        raise UserError("display: expected $DISPLAY or $WAYLAND_DISPLAY to open the window, found neither "
                        "(use --screenshot PATH to render a stage offscreen)")


def main(args: argparse.Namespace) -> int:
    """Run the application (or render a screenshot) and return the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        ``dir`` (sessions folder), ``screenshot`` (PNG path or None), ``stage`` (stage key),
        optionally ``size`` (``WxH`` of the screenshot).

    Raises
    ------
    UserError
        On a bad DIR, ``--stage`` or ``--screenshot``.
    """
    sessions_dir = _check_dir(args.dir)
    if args.stage not in STAGES:
        raise UserError(f"--stage: expected one of {', '.join(STAGES)}, found {args.stage!r}")
    size = parse_size(getattr(args, "size", None))
    out = _check_screenshot_path(args.screenshot) if args.screenshot else None
    check_display(out is not None)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([sys.argv[0]])
    install_message_filter()  # Qt's propagateSizeHints() noise
    app.setOrganizationName(ORGANIZATION)
    app.setApplicationName(APPLICATION)
    with collect_in_gui_thread():
        return _run_window(app, MainWindow(sessions_dir), args.stage, out, size)


def _run_window(app: QtCore.QCoreApplication, window: MainWindow, stage: str, out: Path | None,
                size: tuple[int, int] = SCREENSHOT_SIZE) -> int:
    """Render ``stage`` to ``out`` at ``size`` and close, or show the window until the user quits."""
    if out is not None:
        render_screenshot(window, stage, out, size)
        print(out)
        window.shutdown()
        return 0
    restore = install_exception_hooks(window)
    try:
        window.show_stage(stage)
        window.show()
        return int(app.exec())
    finally:
        restore()
