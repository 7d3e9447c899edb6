"""The effortface application: one main window hosting the stages Capture, Annotate, Train, Synthesize.

``effortface app [DIR]`` opens it on a folder of sessions; ``--screenshot PATH [--stage NAME]``
renders one stage offscreen to a PNG and exits (tests, docs, a look without a display).
Unexpected errors anywhere (GUI thread or worker threads) are logged and shown in a dialog
(STYLE.md E4); expected ones are shown inside the stage that raised them.
"""

from __future__ import annotations

import argparse
import html
import logging
import os
import sys
import threading
import traceback
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

from PySide6 import QtCore, QtGui, QtWidgets

from effortface.core.errors import UserError
from effortface.core.fileio import check_new_png
from effortface.core.gui.gui_gc import collect_in_gui_thread

log = logging.getLogger("effortface.app")

#: stage key (``--stage``) -> title in the stage list
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
    from effortface.capture_tool.session import list_sessions, read_session_info

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
    from effortface.train.gui.synth_stage import QtSynthStage
    from effortface.train.synth_session import SynthSession

    return QtSynthStage(SynthSession(background=True), motion_dir=sessions_dir)


class MainWindow(QtWidgets.QMainWindow):
    """The main window: a stage list on the left, the chosen stage on the right.

    Capture is built at once (it offers to recover crashed sessions at start); the other stages
    are built the first time they are shown. A stage whose code is missing or cannot start shows
    a placeholder that says why and lists the sessions. A stage with a ``focus_main()`` method
    gets the keyboard each time it is shown (it gives the focus to its main widget).

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
        self.stages: dict[str, QtWidgets.QWidget] = {}
        self.stage_list = QtWidgets.QListWidget()
        self.stack = QtWidgets.QStackedWidget()
        self._slots: dict[str, QtWidgets.QWidget] = {}
        self.recording_indicator = QtWidgets.QLabel(wordWrap=True)
        self._build()
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
        self.statusBar().addPermanentWidget(self.folder_label, 1)
        self.stage_list.setCurrentRow(0)

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
        return self.stages[key]

    def _on_stage_changed(self, row: int) -> None:
        key = list(STAGES)[row]
        widget = self._ensure_stage(key)
        self.stack.setCurrentIndex(row)
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

    def shutdown(self) -> None:
        """Stop every stage's timers and background work without asking or saving (screenshots)."""
        for widget in self.stages.values():
            stop = getattr(widget, "shutdown", None)
            if stop is not None:
                stop()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:  # noqa: N802 - Qt override
        """Ask every stage whether it may close (Capture asks while recording); save the layout."""
        for widget in self.stages.values():
            may_close = getattr(widget, "may_close", None)
            if may_close is not None and not may_close():
                event.ignore()
                return
        self.settings.setValue("main_window/geometry", self.saveGeometry())
        self.settings.sync()
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


def render_screenshot(window: MainWindow, stage: str, out: Path) -> Path:
    """Show ``stage`` in ``window`` at the documentation size and save it as a PNG."""
    window.show_stage(stage)
    window.resize(*SCREENSHOT_SIZE)
    window.show()
    wait_settled(window)
    if not window.grab().save(str(out), "PNG"):
        raise UserError(f"--screenshot: expected a writable PNG path, could not write {str(out)!r}")
    return out


def main(args: argparse.Namespace) -> int:
    """Run the application (or render a screenshot) and return the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        ``dir`` (sessions folder), ``screenshot`` (PNG path or None), ``stage`` (stage key).

    Raises
    ------
    UserError
        On a bad DIR, ``--stage`` or ``--screenshot``.
    """
    sessions_dir = _check_dir(args.dir)
    if args.stage not in STAGES:
        raise UserError(f"--stage: expected one of {', '.join(STAGES)}, found {args.stage!r}")
    out = _check_screenshot_path(args.screenshot) if args.screenshot else None
    has_display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                       or os.environ.get("QT_QPA_PLATFORM") or sys.platform in ("win32", "darwin"))
    if out is not None:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    elif not has_display:
        raise UserError("display: expected $DISPLAY or $WAYLAND_DISPLAY to open the window, found neither "
                        "(use --screenshot PATH to render a stage offscreen)")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([sys.argv[0]])
    app.setOrganizationName(ORGANIZATION)
    app.setApplicationName(APPLICATION)
    with collect_in_gui_thread():
        return _run_window(app, MainWindow(sessions_dir), args.stage, out)


def _run_window(app: QtCore.QCoreApplication, window: MainWindow, stage: str, out: Path | None) -> int:
    """Render ``stage`` to ``out`` and close, or show the window until the user quits."""
    if out is not None:
        render_screenshot(window, stage, out)
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
