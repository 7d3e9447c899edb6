"""The Capture stage: pre-flight with live heart rate, participant, live view, exercise log, Record/Stop.

:class:`QtCaptureStage` views a :class:`~effortface.capture_tool.capture_session.CaptureSession`
(the stage-model convention of :mod:`effortface.core`): it calls the session's methods, connects to
its ``<thing>_changed`` emitters in ``__init__``, and its QTimer calls
:meth:`~effortface.capture_tool.capture_session.CaptureSession.poll`, which delivers the background
start, stop, recovery and strap-monitor jobs and the live rows; the GUI thread never waits
(the rule: a view writes back only through model methods and keeps widget state only; worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget). The hotkeys F1-F8 are QActions (:attr:`QtCaptureStage.hotkeys`) that the main
window adds too, so they work from every stage while recording.
"""

from __future__ import annotations

import functools
import html
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.core.errors import UserError
from effortface.core.framing import Framing
from effortface.capture_tool.capture_session import (BUSY_STATES, CaptureSession, DeviceChoice, HrRow,
                                                      LiveUpdate, format_elapsed)
from effortface.capture_tool.corrections import CORRECTION_KIND
from effortface.capture_tool.gui.live_view import QtLiveView, format_bytes
from effortface.capture_tool.gui.participant_form import QtParticipantForm
from effortface.capture_tool.gui.phases import PHASE_TITLES, QtPhasePanel, catalog_models
from effortface.capture_tool.gui.preflight import QtPreflight
from effortface.capture_tool.monitor import MonitorStats
from effortface.core.session.folder import EVENTS_CSV, Event, id_taken_note, read_events, read_session_info
from effortface.capture_tool.strap_status import StrapView, plain_link_error

__all__ = ["CaptureSession", "QtCaptureStage"]

POLL_MS = 100
FLASH_MS = 250
DEFAULT_REST_BPM = 60.0
#: seconds between two skin-contact marks on the plot (a contact that flickers is not marked each time)
CONTACT_MARK_S = 1.0
#: event kinds drawn as lines on the HR plot: (text, colour)
_PLOTTED = {"phase_start": ("{title}", "#303030"), "marker": ("\u2691 {label}", "#6a3d9a"),
            "device_gap": ("strap lost", "#b00020"), "reconnect": ("strap back", "#1b7f3b"),
            "sync": ("sync flash", "#806000"), CORRECTION_KIND: ("= {label}", "#303030")}
#: event kinds listed in the recorded-events list (the others are the recorder's own)
_LISTED = ("phase_start", "phase_end", "marker", "sync", "reps", "speed", "grade", "power", "cadence", "rom",
           "load", CORRECTION_KIND, "device_gap", "reconnect")
#: what the Record button says in each state, and its colour (red unless listed)
_STATE_TEXT = {"idle": "\u25CF  Record", "starting": "Starting...", "recording": "\u25A0  Stop",
               "stopping": "Stopping...", "recovering": "Recovering..."}
_STATE_COLOUR = {"idle": "#1b7f3b", "recovering": "#6c757d"}
_BANNER_STYLE = {"warn": "background:#fff3cd; color:#664d03; border:1px solid #e0c060;",
                 "info": "background:#e7f1ff; color:#084298; border:1px solid #9ec5fe;",
                 "error": "background:#f8d7da; color:#842029; border:1px solid #e0a0a8;",
                 "none": "background: transparent; border: 1px solid transparent;"}


#: how the model says that watching the strap before Record failed
WATCH_ERROR = "Live heart rate: "


#: command-line option names in a model's message, in the app's words
_OPTION_WORDS = (("--camera ", "camera "), ("--camera:", "camera:"), ("--video ", "video file "),
                 ("--plan ", "plan "), ("--participant / body options: ", "participant: "), ("--port ", "strap port "))


def app_words(text: str) -> str:
    """A message in the app's words: no command-line option names (``--port /dev/ttyUSB9: expected a
    serial port, found no such device`` -> ``strap port /dev/ttyUSB9: no such device: the receiver is
    unplugged, or another port is meant``)."""
    head, sep, rest = text.partition(": ")
    if text.startswith("--port "):
        return "Strap port " + plain_link_error(text)
    if rest.startswith("--port "):
        return f"{head}: strap port {plain_link_error(rest)}"
    for option, words in _OPTION_WORDS:
        text = text.replace(option, words)
    return text


def saved_notes(folder: Path) -> list[str]:
    """What the after-Stop summary says beyond the counts, from the saved ``session.json``.

    A suffixed session id (another session of the participant started the same second) and, with
    video, how often the framing check found the face framed for the machine rater.

    Parameters
    ----------
    folder : Path
        The session folder just saved.

    Returns
    -------
    list of str
        Plain lines (no markup); empty when there is nothing to say or ``session.json`` cannot be read.
    """
    try:
        taken = id_taken_note(folder)
        framing = read_session_info(folder).extra.get("stats", {}).get("framing")
    except (UserError, OSError, AttributeError):
        return []
    taken = taken.removeprefix("note: ") if taken else ""
    lines = [taken[:1].upper() + taken[1:]] if taken else []
    if isinstance(framing, dict) and framing.get("error"):
        lines.append(f"Camera framing not checked: {framing['error']}")
    elif isinstance(framing, dict) and framing.get("samples"):
        n, framed = int(framing["samples"]), int(framing.get("framed", 0))
        line = f"Camera: the face was framed for the machine rater in {framed} of {n} looks"
        if framed * 2 < n and framing.get("last"):
            line += f" (last look: {framing['last']})"
        lines.append(line)
    return lines


def framing_banner(framing: Framing) -> str:
    """The banner for a face the machine rater may miss: ``Camera: move the camera closer: the face is 14 %
    of the frame; the rater needs 25 %`` (or no face found, and whether the image is dark)."""
    return f"Camera: {framing.line()}."


def tanaka_hr_max(age: float) -> float:
    """Age-predicted maximal HR, Tanaka 2001: ``208 - 0.7 age`` (SCIENCE.md section 3)."""
    return 208.0 - 0.7 * age


def describe_sync(sync: dict[str, Any] | None, has_video: bool = True) -> tuple[str, bool]:
    """One line about a session's sync test and whether it passed (or was not needed).

    Parameters
    ----------
    sync : dict or None
        ``session.json``'s ``sync`` (:func:`~effortface.capture_tool.capture_session.measure_sync`).
    has_video : bool
        Whether the session recorded video; without video there is nothing to synchronise.
    """
    if not has_video:
        return "Sync test: no video: no sync needed", True
    if not sync or not sync.get("flashes_t_s"):
        return "Sync test: not done (no flash, F8): the video-to-heart-rate offset is unknown", False
    offset = sync.get("video_offset_s")
    n = len(sync["flashes_t_s"])
    if offset is None:
        return f"Sync test: FAILED, {n} flash(es) not seen in the video ({sync.get('note', '')})", False
    return (f"Sync test: passed, video offset {offset * 1000:+.0f} ms "
            f"({len(sync.get('offsets_s', []))} of {n} flashes seen)"), True


class QtCaptureStage(QtWidgets.QWidget):
    """The whole Capture stage.

    Parameters
    ----------
    session : CaptureSession
        The model: starts, marks, polls and stops recordings.
    settings : QSettings
        UI preferences (last port, protocol, video file).
    parent : QWidget, optional
        Parent widget.
    """

    recording_changed = QtCore.Signal(bool)

    def __init__(self, session: CaptureSession, settings: QtCore.QSettings,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self._banner_reason = ""
        self._strap_banner = ""  # the strap's banner shown now (it goes when its cause does)
        self._framing_banner = ""  # the camera check's framing banner shown now (likewise)
        self._plot_is_monitor = False  # the HR plot shows the strap watched before Record (not a recording)
        self._contact_lost = 0
        self._contact_ok = True
        self._pending_note = ""  # a marker note logged at Stop, said in the summary
        self._contact_marked_s = -CONTACT_MARK_S
        self._last_row_s: float | None = None
        self._last_status: Any = None  # the recording's last status (the summary's figures)
        self._build(settings)
        self._connect()
        self._timer = QtCore.QTimer(self, interval=POLL_MS)
        self._timer.timeout.connect(session.poll)
        self._timer.start()
        self._update_zones()
        self._show_state(session.state)
        self.refresh_participants()
        self.check_incomplete()

    @property
    def hotkeys(self) -> list[QtGui.QAction]:
        """The F1-F8 actions (enabled while recording); the main window adds them for app-wide keys."""
        return self.phases.hotkeys

    # ------------------------------------------------------------------------------- layout
    def _build(self, settings: QtCore.QSettings) -> None:
        self.preflight = QtPreflight(settings, strap_in_use=self.session.watching,
                                     release_strap=self.session.release_monitor)
        self.form = QtParticipantForm()
        self.lsl_box = QtWidgets.QCheckBox("Publish to LSL (for LabRecorder)")
        self.lsl_box.setToolTip("While recording, also publish the strap as an LSL HeartRate stream and the "
                                "events as a Markers stream, as 'effortface capture --lsl' does")
        self.lsl_box.setChecked(bool(settings.value("capture/lsl", False, type=bool)))
        self.lsl_box.toggled.connect(lambda on: settings.setValue("capture/lsl", on))
        self.record_button = QtWidgets.QPushButton()
        self.record_button.setMinimumHeight(52)
        font = self.record_button.font()
        font.setPointSize(font.pointSize() + 5)
        font.setBold(True)
        self.record_button.setFont(font)
        self.import_button = QtWidgets.QPushButton("Import heart rate...")
        self.import_button.setToolTip("Import watch or app heart-rate files (FIT, TCX, GPX, Polar HRM, PWX, CSV/TSV) "
                                      "for the participant in the form: one session each, as "
                                      "'effortface import hr' does")
        self.session_label = QtWidgets.QLabel(wordWrap=True)
        self.session_label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.sync_label = QtWidgets.QLabel(wordWrap=True)
        self.notes = QtWidgets.QPlainTextEdit(placeholderText="experimenter notes (saved in session.json at Stop)")
        self.notes.setFixedHeight(64)
        self.event_list = QtWidgets.QListWidget()
        self.event_list.setMinimumHeight(110)
        # a long event (a link error's text) wraps in the fixed-width panel instead of scrolling sideways
        self.event_list.setWordWrap(True)
        self.event_list.setResizeMode(QtWidgets.QListView.ResizeMode.Adjust)
        self.event_list.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.correct_to = QtWidgets.QComboBox()
        self.correct_to.addItems(list(catalog_models()))
        self.correct_button = QtWidgets.QPushButton("Correct phase")
        self.correct_button.setToolTip("The selected phase was in fact this exercise: logs a correction row "
                                       "(events.csv is never rewritten)")
        self.banner = QtWidgets.QLabel(wordWrap=True)
        self.banner.setMargin(4)
        # the banner keeps its height when empty: a message never shifts the video
        self.banner.setFixedHeight(2 * self.banner.fontMetrics().lineSpacing() + 14)
        self.banner.setStyleSheet(_BANNER_STYLE["none"])
        self.recovery_bar = _RecoveryBar()
        self.live = QtLiveView()
        self.phases = QtPhasePanel()
        self.phases.set_speed_unit(str(settings.value("capture/speed_unit", "m/s")))
        self.phases.speed_unit.currentTextChanged.connect(lambda unit: settings.setValue("capture/speed_unit", unit))
        self.addActions(self.phases.hotkeys)
        self._hotkey_filter = _HotkeyFilter(self.phases.hotkeys, self.window)
        self.flash = QtWidgets.QWidget(self)
        self.flash.setStyleSheet("background: white;")
        self.flash.setAttribute(QtCore.Qt.WidgetAttribute.WA_StyledBackground, True)
        self.flash.hide()
        left = QtWidgets.QVBoxLayout()
        # the last recording's summary first: in sight after Stop, above the devices and the emptied form
        for widget in (self._summary_panel(), self.preflight, self.form, self.session_label, self.sync_label,
                       self._events_box(), self.notes):
            left.addWidget(widget)
        left.addStretch(1)
        left_box = QtWidgets.QWidget()
        left_box.setLayout(left)
        self.left_scroll = scroll = QtWidgets.QScrollArea(widgetResizable=True)
        scroll.setWidget(left_box)
        scroll.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        scroll.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
        column = QtWidgets.QVBoxLayout()
        column.setContentsMargins(0, 0, 0, 0)
        column.addWidget(scroll, 1)
        column.addWidget(self._action_bar())  # fixed under the scrolled form: Record/Stop always in sight
        left_column = QtWidgets.QWidget()
        left_column.setLayout(column)
        left_column.setFixedWidth(430)
        right = QtWidgets.QVBoxLayout()
        right.addWidget(self.banner)
        right.addWidget(self.recovery_bar)
        right.addWidget(self.live, 1)
        right.addWidget(self.phases)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(left_column)
        layout.addLayout(right, 1)

    def _action_bar(self) -> QtWidgets.QWidget:
        """The LSL switch and Record/Stop, fixed at the foot of the left column (never scrolled away)."""
        self.action_bar = QtWidgets.QFrame()
        self.action_bar.setFrameShape(QtWidgets.QFrame.Shape.StyledPanel)
        bar = QtWidgets.QVBoxLayout(self.action_bar)
        bar.setContentsMargins(6, 4, 6, 6)
        bar.addWidget(self.lsl_box)
        bar.addWidget(self.record_button)
        bar.addWidget(self.import_button)  # a watch's or app's file instead of a recording
        return self.action_bar

    def _summary_panel(self) -> QtWidgets.QGroupBox:
        """What the last recording saved (path, length, samples, events, dropped frames, sync): shown at the
        top of the left column from Stop until the next Record, its plot kept on the right (the strap
        watched again meanwhile has its own small plot, "Live strap (not recording)", beside the readout)."""
        self.summary = QtWidgets.QGroupBox("Last recording")
        self.summary_text = QtWidgets.QLabel(wordWrap=True)
        self.summary_text.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.summary_sync = QtWidgets.QLabel(wordWrap=True)
        box = QtWidgets.QVBoxLayout(self.summary)
        box.setContentsMargins(6, 2, 6, 4)
        box.addWidget(self.summary_text)
        box.addWidget(self.summary_sync)
        self.summary.hide()
        return self.summary

    def _events_box(self) -> QtWidgets.QGroupBox:
        box = QtWidgets.QGroupBox("Recorded events")
        layout = QtWidgets.QGridLayout(box)
        layout.addWidget(self.event_list, 0, 0, 1, 3)
        layout.addWidget(QtWidgets.QLabel("Selected phase was"), 1, 0)
        layout.addWidget(self.correct_to, 1, 1)
        layout.addWidget(self.correct_button, 1, 2)
        return box

    def _connect(self) -> None:
        self.record_button.clicked.connect(self.toggle_recording)
        self.import_button.clicked.connect(lambda: self.import_heart_rate())
        p = self.phases
        p.phase_requested.connect(lambda exercise, params: self._guarded(self.session.start_phase, exercise, params))
        p.end_requested.connect(lambda: self._guarded(self.session.end_phase))
        p.rep_requested.connect(lambda: self._guarded(self.session.count_rep))
        p.parameters_changed.connect(self._log_parameters)
        p.marker_requested.connect(lambda text: self._guarded(self.session.mark, "marker", text))
        p.sync_requested.connect(self.sync_test)
        p.plan_requested.connect(self.load_plan)
        self.correct_button.clicked.connect(self.correct_selected_phase)
        self.notes.textChanged.connect(lambda: self.session.set_notes(self.notes.toPlainText()))
        self.form.changed.connect(self._update_zones)
        self.form.changed.connect(self._clear_refusal)
        self.recovery_bar.recover.connect(self.session.recover_in_background)
        self.preflight.camera_frame.connect(self._show_camera_check)
        self.preflight.camera_framing.connect(self._show_camera_framing)
        self.preflight.strap_ready.connect(self._watch_strap)
        self.preflight.strap_changed.connect(self._show_strap)
        s = self.session
        s.state_changed.connect(self._show_state)
        s.recording_changed.connect(self._show_recording)
        s.live_changed.connect(self._show_update)
        s.status_changed.connect(self._show_status)
        s.incomplete_changed.connect(lambda sessions: self.recovery_bar.offer(sessions, s.recovery_failed))
        s.phase_changed.connect(self._show_phase)
        s.plan_changed.connect(self.phases.set_plan_text)
        s.monitor_changed.connect(self._show_monitor)
        s.sync_changed.connect(self._show_sync)

    def _show_camera_check(self, frame: np.ndarray | None) -> None:
        """Before recording, show the chosen camera's first frame (to check the framing)."""
        if not self.session.recording:
            caption = "camera check: first frame (live video starts with Record)" if frame is not None else ""
            self.live.set_frame(frame, caption)

    def _show_camera_framing(self, framing: Framing | None) -> None:
        """Before recording, a banner when the camera check's face is missing or too small for the machine
        rater (it goes when the framing is fixed or the camera changes)."""
        if self.session.recording or self._busy:
            return
        text = framing_banner(framing) if framing is not None and not framing.ok else ""
        if text:
            self._framing_banner = text
            self.show_banner(text, "warn")
        elif self._framing_banner:
            if self.banner_text() == self._framing_banner:
                self.clear_banner()
            self._framing_banner = ""

    def _clear_refusal(self) -> None:
        """A 'Record refused' banner goes once its cause does (the form says what is still needed)."""
        if self.banner_text().startswith("Record refused") and not self.form.validate():
            self.clear_banner()

    def _watch_strap(self, port: str, protocol: str) -> None:
        """The pre-flight found the strap's port: show its live heart rate (not while recording);
        '' (no port, or it does not open): stop showing the previous one."""
        if not port:
            self.session.unwatch_strap()
        elif not self.session.recording and not self._busy and not self.session.watching(port, protocol):
            self.session.watch_strap(port, protocol)

    def refresh_participants(self) -> None:
        """Offer the lab registry's participants in the form (a bad registry is said in the banner)."""
        try:
            self.form.set_known(*self.session.participant_records())
        except UserError as exc:
            self.show_banner(str(exc), "error")

    # ------------------------------------------------------------------------- record / stop
    @property
    def _busy(self) -> bool:
        """True while a start, stop or recovery runs."""
        return self.session.busy

    def toggle_recording(self) -> None:
        """Record if idle, stop if recording (the Record/Stop button)."""
        if self._busy:
            return
        if self.session.recording:
            self.stop_recording()
        else:
            self.start_recording()

    def start_recording(self) -> bool:
        """Validate the form and devices (asking about a missing strap), then start in the background.

        Record is refused, with the reason in the window, until the participant's sex, age, height,
        mass and training level are confirmed.

        Returns
        -------
        bool
            True if a start was requested.
        """
        if self.form.validate():
            if self.form.conflicts():  # the form states the conflict (once, record beside typed value)
                self.show_banner("Record refused: see the participant form", "error")
            else:
                self.show_banner("Record refused: " + self.form.message.text(), "error")
            return False
        choice = self._confirm_devices(self.preflight.choice())
        if choice is None:
            return False
        participant, label = self.form.participant(), self.form.session_label()
        update = self.form.update_record
        try:
            self.session.resolve_participant(participant, update=update)
        except UserError as exc:
            self.show_banner(f"Record refused: {exc}", "error")
            return False
        self.preflight.remember()
        self.session.start_in_background(participant, choice, label, self.lsl_box.isChecked(), update)
        return True

    def import_heart_rate(self, paths: list[str] | None = None) -> bool:
        """Import heart-rate files for the participant in the form (a file dialog when ``paths`` is None).

        The form must be complete, as for Record; the import runs in the background and its result
        (the sessions written, or the one-line refusal) is said in the banner.

        Returns
        -------
        bool
            True if an import was started.
        """
        if self.form.validate():
            self.show_banner("Import refused: " + self.form.message.text(), "error")
            return False
        if paths is None:
            paths, _ = QtWidgets.QFileDialog.getOpenFileNames(
                self, "Import heart rate", str(self.session.out_dir),
                "Heart-rate files (*.fit *.FIT *.tcx *.gpx *.hrm *.pwx *.csv *.tsv *.txt);;All files (*)")
        if not paths:
            return False
        from effortface.capture_tool.importers.session import import_hr_files

        person = self.form.participant()
        options = {f: getattr(person, f) for f in ("sex", "age", "height_m", "mass_kg", "training_level",
                                                     "hr_rest_bpm", "hr_max_bpm")}
        self.import_button.setEnabled(False)
        self.show_banner(f"Importing {len(paths)} heart-rate file(s)...")
        work = functools.partial(import_hr_files, update=self.form.update_record,
                                 label=self.form.session_label() or None,
                                 hint="choose 'Use the record' or 'Change the record'")
        self.preflight.jobs.submit("import", work, list(paths), self.session.out_dir, person.code, options,
                                   done=self._imported)
        return True

    def _imported(self, result: Any) -> None:
        self.import_button.setEnabled(self.session.state == "idle")
        if result.error is not None:
            self.show_banner(f"Import refused: {str(result.error).splitlines()[0]}", "error")
            return
        names = ", ".join(p.name for p in result.value)
        self.show_banner(f"Imported {len(result.value)} session(s) into {self.session.out_dir}: {names}")
        self.refresh_participants()

    def _confirm_devices(self, choice: DeviceChoice) -> DeviceChoice | None:
        """Ask once before recording without a ready strap or with a chosen camera that is not ready.

        One question names everything not ready; "No video" chosen on purpose is the operator's
        choice, not a fault: nothing is asked.
        """
        missing = self.preflight.missing()
        if not missing:
            return choice
        problems = []
        if "strap" in missing:
            problems.append("the heart-rate strap is not shown ready (if its port cannot be opened the "
                            "recording will not start)")
        if "camera" in missing:
            problems.append("the camera chosen is not ready (heart rate is recorded without video)")
        if not _ask(self, "Devices not ready", "Before Record: " + "; ".join(problems) + ". Record anyway?"):
            return None
        return DeviceChoice(choice.port, choice.protocol, None) if "camera" in missing else choice

    def stop_recording(self) -> bool:
        """Stop in the background; a marker note typed but not sent is logged first (and said).

        Video recorded without a sync test asks first (No: the recording goes on, for F8). Returns
        True if the stop was requested.
        """
        if self.session.needs_sync_reminder() and not _ask(
                self, "No sync test",
                "No sync test (F8) was done while the camera recorded: the video-to-heart-rate offset of "
                "this session will be unknown. Stop anyway?\n\nNo: go on recording, press F8 with the "
                "camera seeing the screen, then Stop."):
            self.show_banner("Still recording: press F8 (sync test) with the camera seeing the screen, "
                             "then Stop.", "warn")
            return False
        note = self.phases.take_marker_text()
        if note and self.session.recording:
            self._guarded(self.session.mark, "marker", note)
            self._pending_note = note
        self.session.stop_in_background()
        return True

    def stop_now(self) -> Path:
        """Stop and wait (used when the application closes)."""
        note = self.phases.take_marker_text()
        if note and self.session.recording:
            self.session.mark("marker", note)
        return self.session.stop()

    def may_close(self) -> bool:
        """Ask before closing while recording; on yes, stop the recording cleanly first."""
        if self._busy:
            self.show_banner("Wait a moment: a recording is starting, stopping or being recovered.", "warn")
            return False
        if not self.session.recording:
            return True
        text = "A recording is running. Stop it, save the session and close?"
        if not _ask(self, "Recording in progress", text):
            return False
        self.stop_now()
        return True

    def settled(self) -> bool:
        """True when no device check, start, stop or recovery is pending (screenshots, tests)."""
        return (self.session.jobs.idle() and self.preflight.jobs.idle()
                and not self.preflight._debounce.isActive())

    def shutdown(self) -> None:
        """Stop timers and background pools (the window is closing)."""
        app = QtWidgets.QApplication.instance()
        if app is not None:
            app.removeEventFilter(self._hotkey_filter)
        self._timer.stop()
        self.preflight.shutdown()
        self.session.shutdown()

    # ----------------------------------------------------------------------- phases, markers
    def _log_parameters(self, parameters: tuple[tuple[str, float], ...]) -> None:
        if not parameters:
            self.show_banner("F7: no parameter set to log (set a speed, load... first)", "warn")
            return
        self._guarded(self.session.log_parameters, parameters)

    def _show_phase(self, exercise: str | None) -> None:
        current = self.session.current_exercise
        start = self.session.phase_start_s
        since = format_elapsed(start) if start is not None and exercise is not None else ""
        self.phases.set_current(current if exercise is not None else None, since)

    def _guarded(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Call a model method; show an expected error in the banner instead of raising."""
        try:
            return fn(*args)
        except UserError as exc:
            self.show_banner(str(exc), "error")
            return None

    def load_plan(self, path: str) -> None:
        """Load (or clear, '') the protocol plan the next recording steps through."""
        self._guarded(self.session.load_plan, path or None)

    def correct_selected_phase(self) -> None:
        """Log that the phase selected in the event list was the exercise chosen beside it."""
        item = self.event_list.currentItem()
        event = item.data(QtCore.Qt.ItemDataRole.UserRole) if item is not None else None
        if not isinstance(event, Event) or event.kind != "phase_start":
            self.show_banner("Correct phase: select a phase start in the list of recorded events first", "warn")
            return
        if self._guarded(self.session.correct_phase, event, self.correct_to.currentText()) is not None:
            item.setText(self._event_text(event))

    def sync_test(self) -> None:
        """Flash the stage white and record the flash time as a ``sync`` event."""
        self.flash.setGeometry(self.rect())
        self.flash.raise_()
        self.flash.show()
        self.flash.repaint()
        if self._guarded(self.session.sync_flash) is None:
            self.flash.hide()
            return
        self.sync_label.setText("Sync test: flash logged; measured at Stop")
        QtCore.QTimer.singleShot(FLASH_MS, self.flash.hide)

    # ------------------------------------------------------------------------ model changes
    def _show_update(self, update: LiveUpdate) -> None:
        self._plot_rows(update.hr_rows)
        self._plot_events(update.events)
        self._list_events(update.events)
        if update.frame is not None:
            self.live.set_frame(update.frame, f"live camera: {update.status.frames} frames recorded")
        status = update.status
        self._last_status = status
        live = status.link_state == "connected"  # never show a stale HR while the strap is gone
        self.live.set_current(status.hr_bpm if live and self._contact_ok else None,
                              status.rr_ms if live and self._contact_ok else None)
        if update.hr_rows:
            self._last_row_s = update.hr_rows[-1].t_s
        since = status.elapsed_s - self._last_row_s if self._last_row_s is not None else None
        self.live.set_counters({
            "elapsed": format_elapsed(status.elapsed_s), "link": status.link_state,
            "rate": f"{status.samples / status.elapsed_s:.2f} Hz (mean)" if status.elapsed_s > 1 else "-",
            "last": "no sample yet" if since is None else f"{max(0.0, since):.1f} s ago",
            "samples": status.samples, "contact_loss": self._contact_lost,
            "contact": "-" if not live else ("yes" if self._contact_ok else "NO"),
            "bad": f"{update.frames_bad} / {status.bad_bytes} B", "frames": status.frames,
            "dropped": status.dropped_frames, "size": format_bytes(status.bytes_on_disk)})
        self._update_banner(status.link_state, update.camera_ended, self._contact_ok, status.fault, status.framing)

    def _show_strap(self, view: StrapView) -> None:
        """Before Record, the strap's one status: its banner (cleared when its cause goes) and HR readout."""
        if self.session.recording or self._busy:
            return
        if view.banner:
            self._strap_banner = view.banner
            self.show_banner(view.banner, "error" if view.state in ("busy", "missing", "failed") else "warn")
        elif self._strap_banner:
            if self.banner_text() == self._strap_banner:
                self.clear_banner()
            self._strap_banner = ""
        if view.hr_bpm is None:
            self.live.set_current(None, None)

    def _show_monitor(self, stats: MonitorStats | None) -> None:
        """Before Record: the chosen strap's live heart rate and stream figures (through the strap's one
        status, so that the Strap line, banner and HR readout agree)."""
        if self.session.recording:
            return
        self.preflight.strap.watched(stats)
        view = self.preflight.render_strap()
        if stats is None:
            if self._plot_is_monitor:  # the next strap watched starts its own plot
                self.live.clear()
                self._plot_is_monitor = False
            self.live.clear_monitor()
            self.live.set_current(None, None)
            self.live.set_counters({"link": "not watched", "rate": "-", "last": "-", "contact": "-"})
            return
        self.live.set_current(view.hr_bpm, stats.rr_ms if view.hr_bpm is not None else None)
        if stats.new:  # the stream drawn before Record, as LabRecorder and OpenSignals do
            t_s = np.array([t for t, _ in stats.new])
            hr_bpm = np.array([np.nan if hr is None else hr for _, hr in stats.new])
            if self.summary.isVisibleTo(self):  # after Stop: the last recording keeps the big plot with its
                self.live.add_monitor_samples(t_s, hr_bpm)  # summary; the strap goes to a place of its own
            else:
                if not self._plot_is_monitor:  # nothing recorded yet in this stage: the big plot is free
                    self.live.clear()
                    self._plot_is_monitor = True
                self.live.add_samples(t_s, hr_bpm)
        self.live.set_counters({
            "link": f"{stats.link_state} (not recording)",
            "rate": "-" if stats.rate_hz is None else f"{stats.rate_hz:.2f} Hz",
            "last": "no sample yet" if stats.since_last_s is None else f"{stats.since_last_s:.1f} s ago",
            "contact": "-" if stats.contact_fraction is None else
            f"{'yes' if stats.contact_now else 'NO'} ({stats.contact_fraction:.0%} of 10 s)",
            "bad": f"{stats.frames_bad} frames"})

    def _plot_rows(self, hr_rows: list[HrRow]) -> None:
        """Plot the rows (no contact as a gap); mark where contact is lost and comes back."""
        if hr_rows:
            t_s = np.array([r.t_s for r in hr_rows])
            hr = np.array([r.hr_bpm if r.valid and r.hr_bpm is not None else np.nan for r in hr_rows])
            self.live.add_samples(t_s, hr)
        for row in hr_rows:
            if row.valid != self._contact_ok:
                self._contact_ok = row.valid
                if row.t_s - self._contact_marked_s >= CONTACT_MARK_S:  # a flickering contact marks once
                    self._contact_marked_s = row.t_s
                    self.live.add_marker(row.t_s, "contact back" if row.valid else "no contact",
                                         "#1b7f3b" if row.valid else "#d35400")
        self._contact_lost += sum(not r.valid for r in hr_rows)

    def _plot_events(self, events: list[Event]) -> None:
        """Draw phases, markers, gaps, reconnects and sync flashes as lines on the HR plot."""
        for event in events:
            if event.kind == "device_gap" and event.label != "camera":
                self.live.add_gap(event.t_s)
            if event.kind in _PLOTTED and event.label not in ("session_start", "session_stop"):
                text, colour = _PLOTTED[event.kind]
                title = PHASE_TITLES.get(event.label, event.label)
                self.live.add_marker(event.t_s, text.format(label=event.label, title=title), colour)

    def _event_text(self, event: Event) -> str:
        corrected = self.session.corrected_label(event) if event.kind == "phase_start" else None
        value = plain_link_error(event.value) if event.kind == "device_gap" and event.value else event.value
        what = f"{event.kind} {event.label}" + (f" = {value}" if value else "")
        if corrected:
            what = f"{event.kind} {event.label} \u2192 corrected: {corrected}"
        return f"{format_elapsed(event.t_s)}  {what}"

    def _list_events(self, events: list[Event]) -> None:
        """Append the operator's events to the list (newest at the bottom, kept in view)."""
        for event in events:
            if event.kind not in _LISTED or event.label in ("session_start", "session_stop"):
                continue
            item = QtWidgets.QListWidgetItem(self._event_text(event))
            item.setToolTip(item.text())
            item.setData(QtCore.Qt.ItemDataRole.UserRole, event)
            self.event_list.addItem(item)
            self.event_list.scrollToBottom()

    def _update_banner(self, link_state: str, camera_ended: bool, contact_ok: bool,
                       fault: str | None = None, framing: Framing | None = None) -> None:
        """Show the most urgent problem (a fault: a file that cannot be written; strap lost, camera
        stopped, no contact; the face not framed for the machine rater) or clear."""
        if fault:
            reason = f"{fault}. Stop the recording and free some disk space."
        elif link_state == "reconnecting":
            reason = "Strap lost: reconnecting by itself. The recording goes on."
        elif camera_ended:
            reason = "The camera stopped delivering frames. The heart-rate recording goes on."
        elif not contact_ok:
            reason = "No skin contact: the strap reports no heart rate (check the strap is moist and tight)."
        elif framing is not None and not framing.ok:
            reason = framing_banner(framing)
        else:
            reason = ""
        if reason != self._banner_reason:
            self._banner_reason = reason
            if reason:
                self.show_banner(reason, "error" if fault else "warn")
            else:
                self.clear_banner()

    def show_banner(self, text: str, kind: str = "info") -> None:
        """Show a message above the live view (``info``, ``warn`` or ``error``); its space is kept."""
        self.banner.setStyleSheet(_BANNER_STYLE[kind])
        self.banner.setText(text)
        self.banner.setToolTip(text)

    def clear_banner(self) -> None:
        """Empty the banner (its space stays, so the video does not move)."""
        self.banner.setStyleSheet(_BANNER_STYLE["none"])
        self.banner.clear()

    def banner_text(self) -> str:
        """The message shown ('' when none)."""
        return self.banner.text()

    def _show_status(self, text: str, is_error: bool) -> None:
        if is_error and text.startswith(WATCH_ERROR) and not self.session.recording:
            self.preflight.strap.failed(text[len(WATCH_ERROR):])  # the strap's one status says it
            self.preflight.render_strap()
            return
        note = self._pending_note
        if note and not is_error and "Saved, complete" in text:
            text += f". The marker note typed but not sent was logged at Stop: {note!r}"
            self._pending_note = ""
        warn = not is_error and "No sync test" in text
        self.show_banner(app_words(text) if is_error else text, "error" if is_error else ("warn" if warn else "info"))

    def _show_sync(self, sync: dict[str, Any] | None) -> None:
        last = self.session.last_session
        text, passed = describe_sync(sync, has_video=last is None or (Path(last) / "video.avi").exists())
        style = "color: #1b7f3b;" if passed else "color: #b00020; font-weight: bold;"
        for label in (self.sync_label, self.summary_sync):
            label.setText(text)
            label.setStyleSheet(style)

    def _show_recording(self, path: Path | None) -> None:
        """A recording started into ``path`` (clear the live view), or stopped (None)."""
        if path is not None:
            self._contact_lost = 0
            self._contact_ok = True
            self._contact_marked_s = -CONTACT_MARK_S
            self._last_row_s = None
            self._plot_is_monitor = False
            self.live.clear()
            self.live.clear_monitor()  # the recording takes the big plot: no separate strap area
            self.event_list.clear()
            self.clear_banner()
            self.sync_label.setText("Sync test: not done yet (F8, with the camera seeing the screen)")
            self.sync_label.setStyleSheet("color: #806000;")
            self.form.show_session_name(path.name)
            self.session_label.setText(f"Recording into<br><b>{path}</b>")
            self.session_label.show()
            self.sync_label.show()
            self.summary.hide()
            self._last_status = None
            return
        self._banner_reason = ""
        # the next recording starts empty: the note was saved in this session, the marker note logged
        self.notes.clear()
        self.phases.marker_text.clear()
        self.live.set_current(None, None)
        self.live.set_counters({"link": "stopped"})
        self.live.preview_caption.setText("last frame recorded (stopped)")
        self.session_label.setText(f"Saved, complete:<br><b>{self.session.last_session}</b>")
        self._show_summary()
        self.session_label.hide()  # said in the summary panel, which stays until the next Record
        self.sync_label.hide()
        self.form.clear_after_recording()  # the next participant starts from an empty form
        self.refresh_participants()
        choice = self.preflight.choice()
        self._watch_strap(choice.port, choice.protocol)

    def _show_summary(self) -> None:
        """Fill and show the last recording's summary panel (the sync line follows when measured)."""
        path = Path(self.session.last_session) if self.session.last_session else None
        st = self._last_status
        has_video = path is not None and (path / "video.avi").exists()
        try:  # as saved (a marker note typed but not sent is logged at Stop)
            events = [e for e in read_events(path / EVENTS_CSV) if e.kind in _LISTED
                      and e.label not in ("session_start", "session_stop")] if path is not None else []
        except (UserError, OSError):
            events = []
        phases = sum(e.kind == "phase_start" for e in events)
        lines = [f"Saved, complete: <b>{path.name if path else '?'}</b> <span style='color:#505050;'>"
                 f"({path.parent if path else ''})</span>"]
        if st is not None:
            video = (f"{st.frames:,} video frames, {st.dropped_frames} dropped" if has_video
                     else "no video")
            lines.append(f"{format_elapsed(st.elapsed_s)} recorded · {st.samples:,} heart-rate samples "
                         f"· {video}")
        lines.append(f"{len(events)} event{'s' * (len(events) != 1)} logged ({phases} phase"
                     f"{'s' * (phases != 1)}): listed under Recorded events, drawn on the plot")
        lines += [html.escape(line) for line in (saved_notes(path) if path is not None else [])]
        self.summary_text.setText("<br>".join(lines))
        self.summary_text.setToolTip(str(path) if path else "")
        if not has_video:
            self._show_sync(None)
        self.summary.show()

    # ----------------------------------------------------------------------------- recovery
    def check_incomplete(self) -> list[Path]:
        """Offer recovery of sessions a crash left incomplete; return them."""
        return self.session.check_incomplete()

    # -------------------------------------------------------------------------------- state
    def _show_state(self, state: str) -> None:
        """What can be pressed and what the Record button says.

        Parameters
        ----------
        state : str
            ``idle``, ``starting``, ``recording``, ``stopping`` or ``recovering``.
        """
        recording = state == "recording"
        self.record_button.setText(_STATE_TEXT[state])
        colour = _STATE_COLOUR.get(state, "#b00020")
        self.record_button.setStyleSheet(f"color: white; background: {colour}; border-radius: 6px;")
        self.record_button.setEnabled(state not in BUSY_STATES)
        self.preflight.setEnabled(state == "idle")
        self.form.setEnabled(state == "idle")
        self.import_button.setEnabled(state == "idle")
        self.import_button.setVisible(state not in ("recording", "stopping"))
        # while recording, devices and participant are fixed: their room goes to the events and notes
        self.preflight.setVisible(state not in ("recording", "stopping"))
        self.form.setVisible(state not in ("recording", "stopping"))
        self.phases.set_recording(recording)
        app = QtWidgets.QApplication.instance()
        if app is not None:
            app.removeEventFilter(self._hotkey_filter)
            if recording:
                app.installEventFilter(self._hotkey_filter)
        self.correct_button.setEnabled(recording)
        self.recovery_bar.set_actions_enabled(state == "idle")
        if state == "idle":
            self.phases.set_current(None)
        self.recording_changed.emit(recording)

    def _update_zones(self) -> None:
        values = self.form.values()
        rest = values["hr_rest_bpm"] or DEFAULT_REST_BPM
        age = values["age"]
        hr_max = values["hr_max_bpm"] or (tanaka_hr_max(age) if age is not None else None)
        if hr_max is not None and hr_max > rest:
            self.live.set_zones(rest, hr_max)

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt override
        """Keep the flash overlay covering the stage."""
        super().resizeEvent(event)
        self.flash.setGeometry(self.rect())


class _HotkeyFilter(QtCore.QObject):
    """While recording, an F-key that a focused widget keeps for itself (an item view takes F2 to edit
    an item) still triggers the Capture hotkey: its key press is caught application-wide.

    Keys the shortcut system already delivered never arrive here as key presses, so nothing fires twice.
    """

    def __init__(self, actions: list[QtGui.QAction], window: Callable[[], QtWidgets.QWidget]) -> None:
        super().__init__()
        self._actions = actions
        self._window = window

    def eventFilter(self, watched: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 - Qt override
        """Trigger the enabled hotkey a key press in the main window matches; swallow that press."""
        if event.type() != QtCore.QEvent.Type.KeyPress or not isinstance(watched, QtWidgets.QWidget):
            return False
        if watched.window() is not self._window():
            return False
        key = QtGui.QKeySequence(event.keyCombination())  # type: ignore[attr-defined]  # a QKeyEvent
        for action in self._actions:
            if action.isEnabled() and action.shortcut().matches(key) == QtGui.QKeySequence.SequenceMatch.ExactMatch:
                action.trigger()
                return True
        return False


class _RecoveryBar(QtWidgets.QFrame):
    """'A recording was left incomplete by a crash' with Recover, Next and Later.

    Next moves on to the next incomplete session (round the list), so every one can be reached. A
    session whose recovery failed (the model's ``recovery_failed``) is not offered again in this run.
    """

    recover = QtCore.Signal(str)

    def __init__(self) -> None:
        super().__init__()
        self.setStyleSheet(_BANNER_STYLE["warn"])
        self.text = QtWidgets.QLabel(wordWrap=True)
        self.button = QtWidgets.QPushButton("Recover")
        self.next = QtWidgets.QPushButton("Next")
        self.next.setToolTip("Offer the next incomplete session instead")
        self.later = QtWidgets.QPushButton("Later")
        layout = QtWidgets.QHBoxLayout(self)
        layout.addWidget(self.text, 1)
        for button in (self.button, self.next, self.later):
            layout.addWidget(button)
        self.button.clicked.connect(lambda: self.recover.emit(self.current()))
        self.next.clicked.connect(self.show_next)
        self.later.clicked.connect(self.hide)
        self._sessions: list[Path] = []
        self._index = 0
        self._n_failed = 0  # failed sessions still incomplete
        self._enabled = True
        self.hide()

    def current(self) -> str:
        """The session on offer ('' when none)."""
        return str(self._sessions[self._index]) if self._sessions else ""

    def offer(self, sessions: list[Path], failed: set[Path] | None = None) -> None:
        """Offer ``sessions`` except those that failed; stay on the current one, else the next.

        Hides when none is left.
        """
        previous = self.current()
        failed = failed or set()
        self._sessions = [Path(s) for s in sessions if Path(s) not in failed]
        self._n_failed = len(sessions) - len(self._sessions)
        later = [i for i, s in enumerate(self._sessions) if str(s) >= previous]
        self._index = later[0] if later and previous else 0
        self._show_current()

    def show_next(self) -> None:
        """Offer the next session (after the last, the first again)."""
        if self._sessions:
            self._index = (self._index + 1) % len(self._sessions)
        self._show_current()

    def set_actions_enabled(self, enabled: bool) -> None:
        """Enable Recover and Next (disabled while recording, starting, stopping or recovering)."""
        self._enabled = enabled
        self.button.setEnabled(enabled and bool(self._sessions))
        self.next.setEnabled(enabled and len(self._sessions) > 1)

    def _show_current(self) -> None:
        """Show the offer for the current session, or hide when there is none."""
        self.set_actions_enabled(self._enabled)
        if not self._sessions:
            self.hide()
            return
        n = len(self._sessions)
        more = f" ({self._index + 1} of {n} incomplete)" if n > 1 else ""
        failed = f" {self._n_failed} could not be recovered (see the message above)." if self._n_failed else ""
        self.text.setText(f"A recording was left incomplete by a crash: <b>{self._sessions[self._index].name}</b>"
                          f"{more}. Recover it to finish its files and mark it complete.{failed}")
        self.show()


def _ask(parent: QtWidgets.QWidget, title: str, text: str) -> bool:
    """A yes/no question (default: no)."""
    answer = QtWidgets.QMessageBox.question(
        parent, title, text,
        QtWidgets.QMessageBox.StandardButton.Yes | QtWidgets.QMessageBox.StandardButton.No,
        QtWidgets.QMessageBox.StandardButton.No)
    return answer == QtWidgets.QMessageBox.StandardButton.Yes
