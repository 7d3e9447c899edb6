"""The serial link: a reader thread between a strap's port, its raw log, its decoder and the recorder.

Each read is stamped with the session clock, appended to ``serial/<device>.serlog`` at once (the
OS has it even if the process is killed; ``fsync`` about once a second), fed to the sans-I/O
decoder, and the samples and link events go to a :class:`queue.Queue` as ``("hr", HrSample)`` or
``("event", DeviceEvent)`` items. A vanished port is a gap: the link records it, re-opens the
same path with back-off (0.1 s doubling to 2 s), records the reconnect and carries on.

A log that cannot be written (disk full, file-size limit) is not a gap: the link stops, keeps what
was written, sets :attr:`SerialLink.fault` (one line naming the log) and puts an ``error`` event
on the queue; its state is ``"failed"``, never a ``"reconnecting"`` that would never end.
"""

from __future__ import annotations

import errno
import os
import queue
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import serial
import serial.tools.list_ports

from effortface.core.errors import DeviceError, DeviceErrorReason
from effortface.capture_tool.protocols import Decoder, DeviceEvent
from effortface.capture_tool.serlog import SerlogWriter
from effortface.capture_tool.urlhandler import register as _register_urls

_register_urls()

BACKOFF_START_S = 0.1
BACKOFF_MAX_S = 2.0
FSYNC_INTERVAL_S = 1.0
READ_TIMEOUT_S = 0.05


def open_port(port: str, baudrate: int = 115200, **settings: Any) -> serial.SerialBase:
    """Open ``port`` (a device path or a pyserial URL) exclusively.

    Parameters
    ----------
    port : str
        ``/dev/ttyUSB0``, ``COM3``, ``/dev/pts/5``, ``loop://``, ``replay://file.serlog?speed=10``.
    baudrate : int
        Line speed (ignored by pseudo-terminals and URL ports).
    **settings
        Other :func:`serial.serial_for_url` settings.

    Raises
    ------
    DeviceError
        With reason NOT_FOUND, BUSY (another program has it open) or PERMISSION.
    """
    kwargs = {"baudrate": baudrate, "timeout": READ_TIMEOUT_S, **settings}
    if "://" not in port:
        kwargs["exclusive"] = True  # a port in use is then BUSY, not two readers sharing bytes
    try:
        return serial.serial_for_url(port, **kwargs)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise _device_error(port, exc) from None


def _device_error(port: str, exc: BaseException) -> DeviceError:
    """Map an open failure to a DeviceError with a reason and a one-line message."""
    code = getattr(exc, "errno", None)
    text = str(exc)
    if port.startswith("ble://"):
        return DeviceError(f"--ble {port[6:]}: expected a BLE heart-rate strap in range, found "
                           f"{text.splitlines()[0] if text else type(exc).__name__}", DeviceErrorReason.NOT_FOUND)
    if code == errno.ENOENT or "[Errno 2]" in text or "No such file" in text:
        return DeviceError(f"--port {port}: expected a serial port, found no such device", DeviceErrorReason.NOT_FOUND)
    if code in (errno.EACCES, errno.EPERM) or "[Errno 13]" in text:
        return DeviceError(
            f"--port {port}: expected read/write access, found permission denied (join the 'dialout' group)",
            DeviceErrorReason.PERMISSION,
        )
    if code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text or "[Errno 16]" in text:
        return DeviceError(f"--port {port}: expected a free port, found it in use by another program", DeviceErrorReason.BUSY)
    return DeviceError(f"--port {port}: could not open ({text.splitlines()[0] if text else type(exc).__name__})")


def check_port_exists(port: str) -> None:
    """Raise DeviceError NOT_FOUND if ``port`` is a POSIX device path that does not exist.

    URLs (``loop://``, ``replay://...``) and Windows names (``COM3``) are not checked: opening
    them reports any problem.

    Raises
    ------
    DeviceError
        With reason NOT_FOUND, the message of a failed open.
    """
    if "://" in port or os.name != "posix" or os.path.exists(port):
        return
    raise _device_error(port, FileNotFoundError(errno.ENOENT, "No such file or directory", port))


def is_simulated_port(port: str) -> bool:
    """True for pyserial URLs and pseudo-terminals (replays), which need no device configuration."""
    if "://" in port:
        return True
    try:
        real = os.path.realpath(port)
    except OSError:
        return False
    return real.startswith("/dev/pts/") or real == "/dev/ptmx"


def list_ports() -> list[dict[str, str]]:
    """Serial ports found on this machine (``device``, ``description``, ``hwid``), sorted by device."""
    ports = [
        {"device": p.device, "description": p.description or "", "hwid": p.hwid or ""}
        for p in serial.tools.list_ports.comports()
    ]
    return sorted(ports, key=lambda p: p["device"])


class _LogFailed(Exception):
    """The serial log could not be written (wraps the OSError): not a device gap."""

    def __init__(self, exc: OSError) -> None:
        super().__init__(str(exc))
        self.exc = exc


class SerialLink:
    """Reader thread of one strap.

    Parameters
    ----------
    port : str
        Device path or pyserial URL; re-opened by the same path after a gap.
    decoder : Decoder
        Fresh decoder for the strap's protocol.
    out : queue.Queue
        Receives ``("hr", HrSample)`` and ``("event", DeviceEvent)`` items.
    clock : callable
        Session clock in seconds (``time.monotonic() - t0``).
    device : str
        Device name (the serlog file stem).
    baudrate : int
        Line speed.
    startup_frames : sequence of bytes
        Written after each (re)open, 20 ms apart, before the decoder's ``startup_bytes`` (e.g. the
        ANT stick's reset / key / channel configuration).

    Attributes
    ----------
    state : str
        ``"closed"``, ``"connected"``, ``"reconnecting"``, ``"failed"`` or ``"stopped"``.
    fault : str or None
        Why the link stopped on its own (its log could not be written...): one line naming the file.
    bytes_in, gaps, reconnects : int
        Counters for the status display.
    """

    def __init__(
        self,
        port: str,
        decoder: Decoder,
        out: queue.Queue,
        clock: Callable[[], float],
        device: str = "strap",
        baudrate: int = 115200,
        startup_frames: Sequence[bytes] = (),
    ) -> None:
        self.port = port
        self.decoder = decoder
        self.out = out
        self.clock = clock
        self.device = device
        self.baudrate = baudrate
        self.startup_frames = tuple(startup_frames)
        self.state = "closed"
        self.bytes_in = 0
        self.gaps = 0
        self.reconnects = 0
        self.fault: str | None = None
        self._ser: serial.SerialBase | None = None
        self._log: SerlogWriter | None = None
        self._stop = threading.Event()
        self._stopping = threading.Lock()  # stop() from two threads runs once at a time
        self._thread: threading.Thread | None = None
        self._last_sync = 0.0
        self._last_poll = 0.0

    def open(self) -> None:
        """Open the port now (so a missing or busy port fails before a session is created).

        Raises
        ------
        DeviceError
            If the port cannot be opened.
        """
        self._ser = open_port(self.port, self.baudrate)
        self.state = "connected"

    def settings(self) -> dict[str, Any]:
        """Port, protocol and pyserial settings, for ``session.json`` and the serlog header."""
        out: dict[str, Any] = {"protocol": self.decoder.name, "port": self.port, "device": self.device}
        if self._ser is not None:
            out["settings"] = self._ser.get_settings()
        return out

    def start(self, serlog_path: str | Path) -> None:
        """Start logging to ``serlog_path`` and reading in a thread (opens the port if needed)."""
        if self._ser is None:
            self.open()
        self._log = SerlogWriter(serlog_path, self.settings())
        self._send_startup()
        self._thread = threading.Thread(target=self._run, name=f"serial-{self.device}", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the thread, flush the decoder's last samples, close port and log."""
        with self._stopping:
            self._stop.set()
            if self._thread is not None:
                self._thread.join(timeout_s)
            self._close_port()
            self._emit_samples(self.decoder.finish())
            if self._log is not None and not self._log.closed:
                try:
                    self._log.sync()
                    self._log.close()
                except OSError as exc:
                    self._fail(_LogFailed(exc))
            if self.state != "failed":
                self.state = "stopped"

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                if self._ser is None:
                    self._reconnect()
                    continue
                try:
                    self._read_once()
                except (serial.SerialException, OSError) as exc:
                    self._gap(exc)
        except _LogFailed as exc:
            self._fail(exc)
        except Exception as exc:  # anything else: said plainly, never a dead thread
            self._fail(exc)

    def _fail(self, exc: Exception) -> None:
        """Stop the link for good: close the port, keep the log as written, say why once."""
        if self.fault is not None:
            return
        now = self.clock()
        self._close_port()
        if isinstance(exc, _LogFailed):
            err = exc.exc
            self.fault = (f"{self._log.path if self._log else 'serial log'}: could not write the serial log "
                          f"({err.strerror or err}); heart-rate recording stopped at {now:.1f} s, what was "
                          "written is kept")
        else:
            self.fault = f"{self.port}: the serial link stopped on an unexpected error ({type(exc).__name__}: {exc})"
        self.state = "failed"
        self.out.put(("event", DeviceEvent(now, "error", self.device, self.fault)))

    def _log_call(self, method: Callable[..., None], *args: Any) -> None:
        """Call a method of the serial log; its OSError becomes _LogFailed (a disk, not a device)."""
        try:
            method(*args)
        except OSError as exc:
            raise _LogFailed(exc) from exc

    def _read_once(self) -> None:
        ser = self._ser
        assert ser is not None
        # every concrete port (posix, URL handlers, replay://) has in_waiting; SerialBase does not
        data = ser.read(max(1, min(ser.in_waiting, 65536)))  # type: ignore[attr-defined]  # see above
        now = self.clock()
        if data:
            assert self._log is not None
            self._log_call(self._log.write, now, data)
            self.bytes_in += len(data)
            self._emit_samples(self.decoder.feed(data, now))
            self._emit_events(self.decoder.pop_events())
        self._housekeeping(now)

    def _housekeeping(self, now: float) -> None:
        """fsync the log about once a second and send poll bytes when due."""
        if now - self._last_sync >= FSYNC_INTERVAL_S and self._log is not None:
            self._log_call(self._log.sync)
            self._last_sync = now
        interval = self.decoder.poll_interval_s
        if self.decoder.poll_bytes and interval > 0 and now - self._last_poll >= interval:
            self._send(self.decoder.poll_bytes)
            self._last_poll = now

    def _send_startup(self) -> None:
        """Configure the device after an open: startup frames (paced), then the decoder's bytes."""
        for frame in self.startup_frames:
            self._send(frame)
            time.sleep(0.02)
        self._send(self.decoder.startup_bytes)

    def _send(self, data: bytes) -> None:
        if data and self._ser is not None:
            self._ser.write(data)

    def _emit_samples(self, samples: list) -> None:
        for s in samples:
            self.out.put(("hr", s))

    def _emit_events(self, events: list[DeviceEvent]) -> None:
        for e in events:
            self.out.put(("event", e))

    def _gap(self, exc: BaseException) -> None:
        """The port vanished: log a gap, drop the partial frame, start reconnecting."""
        now = self.clock()
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        self._close_port()
        self._emit_samples(self.decoder.finish())  # a frame cut by the unplug is incomplete
        self.gaps += 1
        self.state = "reconnecting"
        self._log_event(DeviceEvent(now, "device_gap", self.device, reason))

    def _reconnect(self) -> None:
        """Re-open the same port path with back-off until it works or the link is stopped."""
        delay = BACKOFF_START_S
        while not self._stop.wait(delay):
            try:
                self._ser = open_port(self.port, self.baudrate)
            except DeviceError:
                delay = min(delay * 2, BACKOFF_MAX_S)
                continue
            self.reconnects += 1
            self.state = "connected"
            self._log_event(DeviceEvent(self.clock(), "reconnect", self.device, self.port))
            try:
                self._send_startup()
            except (serial.SerialException, OSError) as exc:  # vanished again at once: another gap
                self._gap(exc)
            return

    def _log_event(self, event: DeviceEvent) -> None:
        """Record a link event both in the serlog (for replay/recover) and for events.csv."""
        self.out.put(("event", event))
        if self._log is not None:
            self._log_call(self._log.write_event, event.t_s, event.kind, event.label, event.value)

    def _close_port(self) -> None:
        if self._ser is not None:
            try:
                self._ser.close()
            except (serial.SerialException, OSError):
                pass
            self._ser = None
