"""Pre-flight: which strap port, protocol and camera; each device shown ready or missing.

Opening ports and cameras can block for a second or more, so every check runs in
:class:`~effortface.core.jobs.Jobs` with its own ``done`` callback, delivered on a QTimer.
"""

from __future__ import annotations

import os
from pathlib import Path
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore, QtWidgets

from effortface.capture_tool.capture_session import DeviceChoice
from effortface.core.errors import UserError
from effortface.core.framing import Framing
from effortface.capture_tool.gui.detect import detect_protocol, read_first_bytes
from effortface.core.jobs import JobResult, Jobs
from effortface.capture_tool.protocols import PROTOCOLS
from effortface.capture_tool.strap_status import StrapStatus, StrapView

__all__ = ["DeviceChoice", "QtPreflight"]

NO_VIDEO = "No video"
VIDEO_FILE = "Video file..."
READY, MISSING, CHECKING, OFF = "ready", "missing", "checking...", "off"


def check_strap(port: str) -> str:
    """Open and close ``port`` (blocking); return a one-line 'ready' note or raise DeviceError."""
    from effortface.capture_tool.serial_link import open_port

    open_port(port).close()
    return f"{port} opens"


def check_camera(camera: int | str) -> tuple[str, Any, Framing | None]:
    """Open a camera or video file, grab one frame, release it, and check the face's framing (blocking).

    Returns
    -------
    (str, ndarray or None, Framing or None)
        A 'WIDTHxHEIGHT' note (with the framing's line), the first frame (BGR) for the preview, and
        its framing for the machine rater (None without a frame, or where the face detector cannot run).

    Raises
    ------
    UserError, DeviceError
        If it cannot be opened.
    """
    from effortface.capture_tool.camera import open_capture
    from effortface.capture_tool.framing_sampler import check_camera_framing

    cap = open_capture(camera)
    try:
        ok, frame = cap.read()
    finally:
        cap.release()
    if not ok:
        return "0x0", None, None
    h, w = frame.shape[:2]
    try:
        framing: Framing | None = check_camera_framing(frame)
    except UserError:  # no ai-edge-litert here: the camera is fine, its framing unknown
        framing = None
    return (f"{w}x{h}" + (f"; {framing.line()}" if framing is not None else "")), frame, framing


def found_ports() -> list[str]:
    """Serial port paths on this machine."""
    from effortface.capture_tool.serial_link import list_ports

    return [p["device"] for p in list_ports()]


def found_ble_straps(scan_s: float = 3.0) -> tuple[list[str], str]:
    """BLE heart-rate straps in range as ``ble://ADDRESS`` ports, and a one-line note for the form.

    No adapter (or no ``bleak``) is not an error: no ports, and the note says why.
    """
    from effortface.capture_tool.ble_link import BleUnavailable, scan_heart_rate_devices

    try:
        devices = scan_heart_rate_devices(scan_s)
    except BleUnavailable as exc:
        return [], f"no straps listed: {exc}"
    names = ", ".join(f"{d['name'] or '?'} ({d['address']}, {d['rssi']} dBm)" for d in devices)
    return [f"ble://{d['address']}" for d in devices], (f"{len(devices)} heart-rate strap(s): {names}" if devices
                                                         else "no heart-rate strap in range")


def found_cameras() -> list[int]:
    """Camera indices from ``/dev/video*``."""
    from effortface.capture_tool.camera import list_cameras

    out = []
    for dev in list_cameras():
        digits = "".join(c for c in Path(dev).name if c.isdigit())
        if digits:
            out.append(int(digits))
    return out


class QtPreflight(QtWidgets.QGroupBox):
    """Port, protocol (with detection) and camera choice, each device shown ready or missing.

    Parameters
    ----------
    settings : QSettings
        Remembers the last port, protocol and video file.
    parent : QWidget, optional
        Parent widget.
    """

    #: the first frame of the chosen camera, for a preview before recording
    camera_frame = QtCore.Signal(object)
    #: the camera check's framing for the machine rater (:class:`~effortface.core.framing.Framing`, or None)
    camera_framing = QtCore.Signal(object)
    #: the chosen strap port opens: (port, protocol), to watch its live heart rate ('' : none opens)
    strap_ready = QtCore.Signal(str, str)
    #: the strap's one status changed (:class:`~effortface.capture_tool.strap_status.StrapView`)
    strap_changed = QtCore.Signal(object)

    def __init__(self, settings: QtCore.QSettings, parent: QtWidgets.QWidget | None = None,
                 strap_in_use: Callable[[str], bool] | None = None,
                 release_strap: Callable[[], Callable[[], None]] | None = None) -> None:
        super().__init__("Devices", parent)
        self.settings = settings
        #: True for a port this application already holds open (the live monitor): not opened again
        self.strap_in_use = strap_in_use or (lambda port: False)
        #: lets go of the port held by the live monitor: returns its blocking close, run in the job
        self.release_strap = release_strap or (lambda: (lambda: None))
        self.jobs = Jobs(name="preflight")
        self.state = {"strap": MISSING, "camera": MISSING}
        self.ble_ports: list[str] = []  # BLE straps found by the last scan (``ble://ADDRESS``)
        self.ble_scan_s = 3.0
        #: the strap's one state: the Strap line, the stage's banner and HR readout all draw it
        self.strap = StrapStatus()
        self.detect_seconds = 2.5  # how long Detect listens to the port
        self._build()
        self._timer = QtCore.QTimer(self, interval=100)
        self._timer.timeout.connect(self.jobs.drain)
        self._timer.start()
        self._restore()
        self.refresh()

    def _build(self) -> None:
        self.port = QtWidgets.QComboBox(editable=True)
        self.port.lineEdit().setPlaceholderText(  # type: ignore[union-attr]  # editable: it has one
            "/dev/ttyUSB0, ble://ADDRESS or replay://file.serlog")
        self.port.setMinimumContentsLength(22)
        self.protocol = QtWidgets.QComboBox()
        self.protocol.addItems(sorted(PROTOCOLS))
        self.detect_button = QtWidgets.QPushButton("Detect")
        self.detect_button.setToolTip("Listen to the port for 2.5 s and guess the protocol")
        self.camera = QtWidgets.QComboBox()
        self.camera.addItems([VIDEO_FILE, NO_VIDEO])
        self.video_path = QtWidgets.QLineEdit(placeholderText="video file played as the camera")
        self.browse = QtWidgets.QPushButton("Browse...")
        self.refresh_button = QtWidgets.QPushButton("Refresh devices")
        self.strap_status = QtWidgets.QLabel()
        self.camera_status = QtWidgets.QLabel()
        self.ble_status = QtWidgets.QLabel("scanning...")
        self.ble_status.setToolTip("Bluetooth Low Energy heart-rate straps (Heart Rate Service 0x180D) in range: "
                                   "choose one as ble://ADDRESS in Strap port")
        for label in (self.strap_status, self.camera_status, self.ble_status):
            label.setWordWrap(True)
        form = QtWidgets.QFormLayout(self)
        form.addRow("Strap port", self.port)
        form.addRow("Protocol", _row(self.protocol, self.detect_button))
        form.addRow("Strap", self.strap_status)
        form.addRow("Bluetooth", self.ble_status)
        form.addRow("Camera", self.camera)
        form.addRow("", _row(self.video_path, self.browse))
        form.addRow("Camera state", self.camera_status)
        form.addRow(self.refresh_button)
        self.refresh_button.clicked.connect(self.refresh)
        self.detect_button.clicked.connect(self.detect)
        self.browse.clicked.connect(self._browse)
        self._debounce = QtCore.QTimer(self, singleShot=True, interval=400)
        self._debounce.timeout.connect(self.check)
        self.port.currentTextChanged.connect(self._on_port_changed)
        self.camera.currentIndexChanged.connect(lambda _: self._on_camera_changed())
        self.video_path.editingFinished.connect(self.check)
        self.video_path.textChanged.connect(self.video_path.setToolTip)
        self.protocol.currentTextChanged.connect(self._on_protocol_changed)

    def _on_port_changed(self, port: str) -> None:
        """A BLE strap speaks ble_hrm: chosen with it; then the check after a pause in typing."""
        if port.strip().startswith("ble://") and self.protocol.currentText() != "ble_hrm":
            self.protocol.blockSignals(True)
            self.protocol.setCurrentText("ble_hrm")
            self.protocol.blockSignals(False)
        self._debounce.start()

    def _on_protocol_changed(self, protocol: str) -> None:
        self.settings.setValue("capture/protocol", protocol)
        self._debounce.start()

    def _restore(self) -> None:
        protocol = self.settings.value("capture/protocol", "")
        if protocol in PROTOCOLS:
            self.protocol.setCurrentText(str(protocol))
        self.video_path.setText(str(self.settings.value("capture/video_file", "")))

    def refresh(self) -> None:
        """List the ports and cameras found (in the background), then check the chosen ones."""
        self.jobs.submit("ports", found_ports, done=self._ports_found)
        self.jobs.submit("ble", found_ble_straps, self.ble_scan_s, done=self._ble_found)
        self.jobs.submit("cameras", found_cameras, done=self._cameras_found)

    def choice(self) -> DeviceChoice:
        """The devices chosen now."""
        text = self.camera.currentText()
        camera: int | str | None
        if text in (NO_VIDEO, ""):
            camera = None
        elif text == VIDEO_FILE:
            camera = self.video_path.text().strip() or None
        else:
            camera = int(text.split()[-1])
        return DeviceChoice(self.port.currentText().strip(), self.protocol.currentText(), camera)

    def set_choice(self, port: str | None = None, protocol: str | None = None,
                   video_file: str | os.PathLike | None = None) -> None:
        """Choose devices programmatically (tests, scripts): a port, a protocol, a video file."""
        if protocol is not None:
            self.protocol.setCurrentText(protocol)
        if video_file is not None:
            self.video_path.setText(os.fspath(video_file))
            self.camera.setCurrentText(VIDEO_FILE)
        if port is not None:
            self.port.setCurrentText(port)
        self.check()

    def missing(self) -> list[str]:
        """Devices chosen but not ready, and a strap not chosen ('strap', 'camera').

        "No video" chosen on purpose is not missing: it is the operator's choice.
        """
        return [name for name, state in self.state.items() if state not in (READY, OFF)]

    def remember(self) -> None:
        """Store the chosen port and video file as the next defaults (on Record)."""
        choice = self.choice()
        self.settings.setValue("capture/port", choice.port)
        if isinstance(choice.camera, str):
            self.settings.setValue("capture/video_file", choice.camera)

    def check(self) -> None:
        """Check the chosen strap and camera in the background."""
        choice = self.choice()
        if choice.port and self.strap_in_use(choice.port):
            self._show("strap", READY, f"{choice.port}: live heart rate shown")
            self.strap_ready.emit(choice.port, choice.protocol)
        elif self._check_one("strap", choice.port, "no port chosen"):
            self.jobs.submit("strap", check_strap, choice.port, done=self._strap_checked)
        else:
            self.strap_ready.emit("", choice.protocol)  # no port: stop watching the previous one
        if self.camera.currentText() == NO_VIDEO:
            self._show("camera", OFF, "no video: chosen (heart rate and events only)")
            self.camera_frame.emit(None)
            self.camera_framing.emit(None)
        elif self._check_one("camera", choice.camera, "no video file chosen"):
            self.jobs.submit("camera", check_camera, choice.camera, done=self._camera_checked)

    def _check_one(self, name: str, target: object, none_text: str) -> bool:
        """Show ``name`` as checking and return True, or as missing (nothing chosen) and return False."""
        if target in (None, ""):
            self._show(name, MISSING, none_text)
            if name == "camera":
                self.camera_frame.emit(None)
                self.camera_framing.emit(None)
            return False
        self._show(name, CHECKING, str(target))
        return True

    def detect(self) -> None:
        """Listen to the chosen port and pick the protocol its bytes fit (background)."""
        port = self.choice().port
        if not port:
            self._show("strap", MISSING, "choose a port before detecting its protocol")
            return
        self.detect_button.setEnabled(False)
        self.detect_button.setText("Listening...")
        seconds = self.detect_seconds
        close_monitor = self.release_strap()
        self.jobs.submit("detect", _detect_after, close_monitor, port, seconds, done=self._protocol_detected)

    def _ports_found(self, result: JobResult) -> None:
        current = self.port.currentText() or str(self.settings.value("capture/port", ""))
        ports = list(result.value or []) + [p for p in self.ble_ports if p not in (result.value or [])]
        if current and current not in ports:
            ports.insert(0, current)
        self.port.blockSignals(True)
        self.port.clear()
        self.port.addItems(ports)
        self.port.setCurrentText(current)
        self.port.blockSignals(False)
        self.check()

    def _ble_found(self, result: JobResult) -> None:
        if result.error is not None:
            self.ble_status.setText(f"no straps listed: {str(result.error).splitlines()[0]}")
            return
        self.ble_ports, note = result.value
        self.ble_status.setText(note)
        for port in self.ble_ports:
            if self.port.findText(port) < 0:
                self.port.blockSignals(True)
                current = self.port.currentText()
                self.port.addItem(port)
                self.port.setCurrentText(current)
                self.port.blockSignals(False)

    def _cameras_found(self, result: JobResult) -> None:
        current = self.camera.currentText()
        self.camera.blockSignals(True)
        self.camera.clear()
        self.camera.addItems([f"Camera {i}" for i in result.value or []] + [VIDEO_FILE, NO_VIDEO])
        default = current or (VIDEO_FILE if self.video_path.text() else self.camera.itemText(0))
        self.camera.setCurrentText(default)
        self.camera.blockSignals(False)
        self._on_camera_changed()

    def _on_camera_changed(self) -> None:
        is_file = self.camera.currentText() == VIDEO_FILE
        self.video_path.setVisible(is_file)
        self.browse.setVisible(is_file)
        self.check()

    def _strap_checked(self, result: JobResult) -> None:
        self._show_result("strap", result)
        choice = self.choice()
        if result.error is None and result.value == f"{choice.port} opens":
            self.strap_ready.emit(choice.port, choice.protocol)
        elif result.error is not None:
            self.strap_ready.emit("", choice.protocol)

    def _camera_checked(self, result: JobResult) -> None:
        if result.error is not None:
            self._show_result("camera", result)
            self.camera_frame.emit(None)
            self.camera_framing.emit(None)
            return
        note, frame, framing = result.value
        self._show("camera", READY, note)
        self.camera_frame.emit(frame)
        self.camera_framing.emit(framing)

    def _protocol_detected(self, result: JobResult) -> None:
        self.detect_button.setEnabled(True)
        self.detect_button.setText("Detect")
        if result.error is not None:
            self._show("strap", MISSING, f"detection failed: {result.error}")
        else:
            if result.value is not None:
                self.protocol.blockSignals(True)  # no re-check: it would replace the message
                self.protocol.setCurrentText(result.value)
                self.protocol.blockSignals(False)
                self.settings.setValue("capture/protocol", result.value)
            self.strap.detected(result.value)
            self.render_strap()
        if self.state["strap"] == READY:  # watch the live heart rate again, with the protocol found
            choice = self.choice()
            self.strap_ready.emit(choice.port, choice.protocol)

    def _show_result(self, name: str, result: JobResult) -> None:
        if result.error is None:
            self._show(name, READY, str(result.value))
        else:
            self._show(name, MISSING, str(result.error).splitlines()[0])

    def _show(self, name: str, state: str, note: str) -> None:
        if name == "strap":
            self._feed_strap(state, note)
            return
        self.state[name] = state
        label = self.strap_status if name == "strap" else self.camera_status
        colour = {READY: "#1b7f3b", MISSING: "#b00020", OFF: "#505050"}.get(state, "#806000")
        mark = {READY: "\u2714", MISSING: "\u2716", OFF: "\u25CB"}.get(state, "\u2026")
        label.setText(f"<span style='color:{colour}'><b>{mark} {state}</b></span> {note}")

    def _feed_strap(self, state: str, note: str) -> None:
        """A check's result goes into the strap's one state, which is then drawn."""
        choice = self.choice()
        self.strap.choose(choice.port, choice.protocol)
        if state == CHECKING:
            self.strap.checking()
        elif state == READY:
            self.strap.opened()
        elif choice.port:
            self.strap.failed(note)
        self.render_strap()

    def render_strap(self) -> StrapView:
        """Draw the Strap line from :attr:`strap` and say it (``strap_changed``); return the view."""
        view = self.strap.view()
        self.state["strap"] = (READY if view.state in ("opens", "live", "no_contact") else
                               CHECKING if view.state == "checking" else MISSING)
        colour = "#806000" if view.ok is None else ("#1b7f3b" if view.ok else "#b00020")
        mark = "\u2026" if view.ok is None else ("\u2714" if view.ok else "\u2716")
        head, _, rest = view.line.partition(": ")
        self.strap_status.setText(f"<span style='color:{colour}'><b>{mark} {head}</b></span> {rest}")
        self.strap_changed.emit(view)
        return view

    def _browse(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Video file played as the camera",
                                                        self.video_path.text(), "Videos (*.avi *.mp4 *.mkv)")
        if path:
            self.video_path.setText(path)
            self.check()

    def shutdown(self) -> None:
        """Stop the timer and the background pool."""
        self._timer.stop()
        self._debounce.stop()
        self.jobs.shutdown()


def _detect_after(close_monitor: Callable[[], None], port: str, seconds: float) -> str | None:
    """Runs in a job: close the live monitor's port, then listen to it and guess the protocol."""
    close_monitor()
    return detect_protocol(read_first_bytes(port, seconds))


def _row(*widgets: QtWidgets.QWidget) -> QtWidgets.QWidget:
    box = QtWidgets.QWidget()
    layout = QtWidgets.QHBoxLayout(box)
    layout.setContentsMargins(0, 0, 0, 0)
    for i, widget in enumerate(widgets):
        layout.addWidget(widget, 1 if i == 0 else 0)
    return box
