"""The Capture stage: pre-flight, participant, live view, phases and markers, Record/Stop, sync test.

:class:`QtCaptureStage` views a :class:`~effortface.capture_tool.capture_session.CaptureSession`
(the stage-model convention of :mod:`effortface.core`): it calls the session's methods, connects to
its ``<thing>_changed`` emitters in ``__init__``, and its QTimer calls
:meth:`~effortface.capture_tool.capture_session.CaptureSession.poll`, which delivers the background
start, stop and recovery jobs and the live rows; the GUI thread never waits (STYLE.md L3, L5).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.core.errors import UserError
from effortface.capture_tool.capture_session import (BUSY_STATES, CaptureSession, DeviceChoice, HrRow,
                                                      LiveUpdate, format_elapsed)
from effortface.capture_tool.gui.live_view import QtLiveView, format_bytes
from effortface.capture_tool.gui.participant_form import QtParticipantForm
from effortface.capture_tool.gui.phases import PHASE_TITLES, QtPhasePanel
from effortface.capture_tool.gui.preflight import QtPreflight
from effortface.capture_tool.session import Event

__all__ = ["CaptureSession", "QtCaptureStage"]

POLL_MS = 100
FLASH_MS = 250
DEFAULT_REST_BPM = 60.0
#: event kinds drawn as lines on the HR plot: (text, colour)
_PLOTTED = {"phase_start": ("{title}", "#303030"), "marker": ("\u2691 {label}", "#6a3d9a"),
            "device_gap": ("strap lost", "#b00020"), "reconnect": ("strap back", "#1b7f3b"),
            "sync": ("sync flash", "#806000")}
#: what the Record button says in each state, and its colour (red unless listed)
_STATE_TEXT = {"idle": "\u25CF  Record", "starting": "Starting...", "recording": "\u25A0  Stop",
               "stopping": "Stopping...", "recovering": "Recovering..."}
_STATE_COLOUR = {"idle": "#1b7f3b", "recovering": "#6c757d"}
_BANNER_STYLE = {"warn": "background:#fff3cd; color:#664d03; border:1px solid #e0c060;",
                 "info": "background:#e7f1ff; color:#084298; border:1px solid #9ec5fe;",
                 "error": "background:#f8d7da; color:#842029; border:1px solid #e0a0a8;"}


def tanaka_hr_max(age: float) -> float:
    """Age-predicted maximal HR, Tanaka 2001: ``208 - 0.7 age`` (SCIENCE.md section 3)."""
    return 208.0 - 0.7 * age


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
        self._contact_lost = 0
        self._contact_ok = True
        self._build(settings)
        self._connect()
        self._timer = QtCore.QTimer(self, interval=POLL_MS)
        self._timer.timeout.connect(session.poll)
        self._timer.start()
        self._update_zones()
        self._show_state(session.state)
        self.check_incomplete()

    # ------------------------------------------------------------------------------- layout
    def _build(self, settings: QtCore.QSettings) -> None:
        self.preflight = QtPreflight(settings)
        self.form = QtParticipantForm()
        self.lsl_box = QtWidgets.QCheckBox("Publish to LSL (HeartRate and Markers streams, for LabRecorder)")
        self.lsl_box.setChecked(bool(settings.value("capture/lsl", False, type=bool)))
        self.lsl_box.toggled.connect(lambda on: settings.setValue("capture/lsl", on))
        self.record_button = QtWidgets.QPushButton()
        self.record_button.setMinimumHeight(52)
        font = self.record_button.font()
        font.setPointSize(font.pointSize() + 5)
        font.setBold(True)
        self.record_button.setFont(font)
        self.session_label = QtWidgets.QLabel(wordWrap=True)
        self.session_label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        self.banner = QtWidgets.QLabel(wordWrap=True)
        self.banner.setMargin(6)
        self.banner.hide()
        self.recovery_bar = _RecoveryBar()
        self.live = QtLiveView()
        self.phases = QtPhasePanel()
        self.flash = QtWidgets.QWidget(self)
        self.flash.setStyleSheet("background: white;")
        self.flash.setAttribute(QtCore.Qt.WidgetAttribute.WA_StyledBackground, True)
        self.flash.hide()
        left = QtWidgets.QVBoxLayout()
        for widget in (self.preflight, self.form, self.lsl_box, self.record_button, self.session_label):
            left.addWidget(widget)
        left.addStretch(1)
        left_box = QtWidgets.QWidget()
        left_box.setLayout(left)
        scroll = QtWidgets.QScrollArea(widgetResizable=True)
        scroll.setWidget(left_box)
        scroll.setFixedWidth(420)
        scroll.setFrameShape(QtWidgets.QFrame.Shape.NoFrame)
        right = QtWidgets.QVBoxLayout()
        right.addWidget(self.banner)
        right.addWidget(self.recovery_bar)
        right.addWidget(self.live, 1)
        right.addWidget(self.phases)
        layout = QtWidgets.QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(scroll)
        layout.addLayout(right, 1)

    def _connect(self) -> None:
        self.record_button.clicked.connect(self.toggle_recording)
        self.phases.phase_requested.connect(self._on_phase)
        self.phases.load_changed.connect(lambda value: self._guarded(self.session.change_load, value))
        self.phases.marker_requested.connect(lambda text: self._guarded(self.session.mark, "marker", text))
        self.phases.sync_requested.connect(self.sync_test)
        self.form.changed.connect(self._update_zones)
        self.recovery_bar.recover.connect(self.session.recover_in_background)
        self.preflight.camera_frame.connect(self._show_camera_check)
        s = self.session
        s.state_changed.connect(self._show_state)
        s.recording_changed.connect(self._show_recording)
        s.live_changed.connect(self._show_update)
        s.status_changed.connect(lambda text, is_error: self.show_banner(text, "error" if is_error else "info"))
        s.incomplete_changed.connect(lambda sessions: self.recovery_bar.offer(sessions, s.recovery_failed))

    def _show_camera_check(self, frame: np.ndarray | None) -> None:
        """Before recording, show the chosen camera's first frame (to check the framing)."""
        if not self.session.recording:
            caption = "camera check: first frame (live video starts with Record)" if frame is not None else ""
            self.live.set_frame(frame, caption)

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
        """Validate the form and devices (asking about a missing one), then start in the background.

        Returns
        -------
        bool
            True if a start was requested.
        """
        if self.form.validate():
            self.show_banner("Check the participant form: " + self.form.message.text(), "error")
            return False
        choice = self._confirm_devices(self.preflight.choice())
        if choice is None:
            return False
        participant, label = self.form.participant(), self.form.session_label()
        self.preflight.remember()
        self.session.start_in_background(participant, choice, label, self.lsl_box.isChecked())
        return True

    def _confirm_devices(self, choice: DeviceChoice) -> DeviceChoice | None:
        """Ask before recording without a ready strap or camera; None if the user declines."""
        missing = self.preflight.missing()
        if "strap" in missing:
            text = ("The heart-rate strap is not shown ready. Record anyway? "
                    "If its port cannot be opened the recording will not start.")
            if not _ask(self, "Strap not ready", text):
                return None
        if "camera" in missing:
            if not _ask(self, "No camera", "No camera is ready. Record heart rate without video?"):
                return None
            choice = DeviceChoice(choice.port, choice.protocol, None)
        return choice

    def stop_recording(self) -> None:
        """Stop in the background: the session is closed and marked complete."""
        self.session.stop_in_background()

    def stop_now(self) -> Path:
        """Stop and wait (used when the application closes)."""
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
        self._timer.stop()
        self.preflight.shutdown()
        self.session.shutdown()

    # ----------------------------------------------------------------------- phases, markers
    def _on_phase(self, phase: str, value: str) -> None:
        t_s = self._guarded(self.session.start_phase, phase, value)
        if t_s is not None:
            self.phases.set_current(phase, format_elapsed(float(t_s)))

    def _guarded(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Call a controller method; show an expected error in the banner instead of raising."""
        try:
            return fn(*args)
        except UserError as exc:
            self.show_banner(str(exc), "error")
            return None

    def sync_test(self) -> None:
        """Flash the stage white and record the flash time as a ``sync`` event."""
        self.flash.setGeometry(self.rect())
        self.flash.raise_()
        self.flash.show()
        self.flash.repaint()
        if self._guarded(self.session.sync_flash) is None:
            self.flash.hide()
            return
        QtCore.QTimer.singleShot(FLASH_MS, self.flash.hide)

    # ------------------------------------------------------------------------ model changes
    def _show_update(self, update: LiveUpdate) -> None:
        self._plot_rows(update.hr_rows)
        self._plot_events(update.events)
        if update.frame is not None:
            self.live.set_frame(update.frame, f"live camera: {update.status.frames} frames recorded")
        status = update.status
        live = status.link_state == "connected"  # never show a stale HR while the strap is gone
        self.live.set_current(status.hr_bpm if live else None, status.rr_ms if live else None)
        self.live.set_counters({
            "elapsed": format_elapsed(status.elapsed_s), "link": status.link_state,
            "samples": status.samples, "contact_loss": self._contact_lost,
            "bad": f"{update.frames_bad} / {status.bad_bytes} B", "frames": status.frames,
            "dropped": status.dropped_frames, "size": format_bytes(status.bytes_on_disk)})
        self._update_banner(status.link_state, update.camera_ended, self._contact_ok, status.fault)

    def _plot_rows(self, hr_rows: list[HrRow]) -> None:
        """Plot the valid rows; count contact losses and remember whether contact is on now."""
        rows = [r for r in hr_rows if r.valid and r.hr_bpm is not None]
        if rows:
            self.live.add_samples(np.array([r.t_s for r in rows]), np.array([r.hr_bpm for r in rows]))
        self._contact_lost += sum(not r.valid for r in hr_rows)
        if hr_rows:
            self._contact_ok = hr_rows[-1].valid

    def _plot_events(self, events: list[Event]) -> None:
        """Draw phases, markers, gaps, reconnects and sync flashes as lines on the HR plot."""
        for event in events:
            if event.kind in _PLOTTED and event.label not in ("session_start", "session_stop"):
                text, colour = _PLOTTED[event.kind]
                title = PHASE_TITLES.get(event.label, event.label)
                self.live.add_marker(event.t_s, text.format(label=event.label, title=title), colour)

    def _update_banner(self, link_state: str, camera_ended: bool, contact_ok: bool,
                       fault: str | None = None) -> None:
        """Show the most urgent problem (a fault: a file that cannot be written; strap lost, camera
        stopped, no contact) or hide."""
        if fault:
            reason = f"{fault}. Stop the recording and free some disk space."
        elif link_state == "reconnecting":
            reason = "Strap lost: reconnecting by itself. The recording goes on."
        elif camera_ended:
            reason = "The camera stopped delivering frames. The heart-rate recording goes on."
        elif not contact_ok:
            reason = "No skin contact: the strap reports no heart rate (check the strap is moist and tight)."
        else:
            reason = ""
        if reason != self._banner_reason:
            self._banner_reason = reason
            if reason:
                self.show_banner(reason, "error" if fault else "warn")
            else:
                self.banner.hide()

    def show_banner(self, text: str, kind: str = "info") -> None:
        """Show a one-line message above the live view (``info``, ``warn`` or ``error``)."""
        self.banner.setStyleSheet(_BANNER_STYLE[kind])
        self.banner.setText(text)
        self.banner.show()

    def _show_recording(self, path: Path | None) -> None:
        """A recording started into ``path`` (clear the live view), or stopped (None)."""
        if path is not None:
            self._contact_lost = 0
            self._contact_ok = True
            self.live.clear()
            self.banner.hide()
            self.form.show_session_name(path.name)
            self.session_label.setText(f"Recording into<br><b>{path}</b>")
            return
        self._banner_reason = ""
        self.live.set_current(None, None)
        self.live.set_counters({"link": "stopped"})
        self.live.preview_caption.setText("last frame recorded (stopped)")
        self.session_label.setText(f"Saved, complete:<br><b>{self.session.last_session}</b>")

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
        self.phases.setEnabled(recording)
        self.recovery_bar.set_actions_enabled(state == "idle")
        if state == "idle":
            self.phases.set_current(None)
        self.recording_changed.emit(recording)

    def _update_zones(self) -> None:
        values = self.form.values()
        rest = values["hr_rest_bpm"] or DEFAULT_REST_BPM
        hr_max = values["hr_max_bpm"] or tanaka_hr_max(values["age"])
        if hr_max > rest:
            self.live.set_zones(rest, hr_max)

    def resizeEvent(self, event: QtGui.QResizeEvent) -> None:  # noqa: N802 - Qt override
        """Keep the flash overlay covering the stage."""
        super().resizeEvent(event)
        self.flash.setGeometry(self.rect())


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
