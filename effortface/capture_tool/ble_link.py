"""The Bluetooth Low Energy link: a heart-rate strap's 0x2A37 notifications as a pyserial port.

``ble://ADDRESS`` or ``ble://NAME`` (``serial.serial_for_url``, registered by
:mod:`effortface.capture_tool.urlhandler`) opens :class:`BlePort`: a thread runs ``bleak`` (scan for
the address or a name that contains NAME, connect, subscribe to the Heart Rate Measurement
characteristic 0x2A37) and each notification becomes readable as one frame
(:func:`effortface.capture_tool.protocols.ble_hrm.frame`). So a BLE strap records through the same
:class:`~effortface.capture_tool.serial_link.SerialLink` and recorder as a serial one: every
notification logged raw with its arrival time in ``serial/<device>.serlog`` (crash-safe), decoded
by ``ble_hrm``, a lost connection a gap and a reconnect (the port's reads raise as a pulled USB
stick's do, and the link re-opens it with back-off), and the log replayed by ``replay://`` and
``effortface decode``. :func:`scan_heart_rate_devices` lists the straps in range for
``effortface ports``.
"""

from __future__ import annotations

import asyncio
import re
import threading
import time
from typing import TYPE_CHECKING, Any

from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from effortface.capture_tool.protocols.ble_hrm import frame

if TYPE_CHECKING:
    from typing_extensions import Buffer

HR_SERVICE_UUID = "0000180d-0000-1000-8000-00805f9b34fb"
HR_MEASUREMENT_UUID = "00002a37-0000-1000-8000-00805f9b34fb"
#: how long to look for the strap, and to wait for its connection, seconds
SCAN_TIMEOUT_S = 10.0
CONNECT_TIMEOUT_S = 20.0
#: a device address: a MAC (Linux, Windows) or the UUID macOS gives a device
ADDRESS_RE = re.compile(r"([0-9A-Fa-f]{2}:){5}[0-9A-Fa-f]{2}|[0-9A-Fa-f]{8}(-[0-9A-Fa-f]{4}){3}-[0-9A-Fa-f]{12}")


class BleUnavailable(Exception):
    """No BLE stack or adapter on this machine (the message says which, in one line)."""


def _reason(exc: BaseException) -> str:
    if isinstance(exc, FileNotFoundError):  # bleak on Linux: the system D-Bus socket of BlueZ is absent
        return "no Bluetooth adapter (BlueZ's D-Bus service is not running)"
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return f"{type(exc).__name__}: {text[:160]}"


def scan_heart_rate_devices(timeout_s: float = 5.0) -> list[dict[str, Any]]:
    """BLE devices advertising the Heart Rate service: ``name``, ``address``, ``rssi`` (dBm), sorted by name.

    Raises
    ------
    BleUnavailable
        ``bleak`` is not installed, or no adapter answers (no BlueZ / D-Bus, adapter off).
    """
    try:
        from bleak import BleakScanner
    except ImportError as exc:
        raise BleUnavailable(f"bleak is not installed ({exc})") from None

    async def scan() -> list[dict[str, Any]]:
        found = await BleakScanner.discover(timeout=timeout_s, return_adv=True, service_uuids=[HR_SERVICE_UUID])
        return [{"name": dev.name or adv.local_name or "", "address": dev.address, "rssi": adv.rssi}
                for dev, adv in found.values()]

    try:
        devices = asyncio.run(scan())
    except Exception as exc:  # bleak raises BleakError, D-Bus errors, FileNotFoundError (no bus), OSError
        raise BleUnavailable(_reason(exc)) from None
    return sorted(devices, key=lambda d: (d["name"], d["address"]))


class BlePort(SerialBase):
    """pyserial port over a BLE heart-rate strap: reads return framed 0x2A37 notifications."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._buf = bytearray()
        self._cond = threading.Condition()
        self._lost: str | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self.target = ""
        self.notifications = 0
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        """Find, connect and subscribe (in a thread with its own event loop); raise if that fails."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self.port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.target = str(self.port).split("://", 1)[-1].strip("/")
        if not self.target:
            raise SerialException(2, "ble://: expected a device address or name, found none")
        ready = threading.Event()
        failure: list[str] = []
        self._lost = None
        self._thread = threading.Thread(target=self._run, args=(ready, failure), name=f"ble-{self.target}",
                                        daemon=True)
        self._thread.start()
        if not ready.wait(SCAN_TIMEOUT_S + CONNECT_TIMEOUT_S) or failure:
            self._shutdown()
            raise SerialException(2, f"ble://{self.target}: {failure[0] if failure else 'no connection in time'}")
        self.is_open = True

    def _run(self, ready: threading.Event, failure: list[str]) -> None:
        try:
            asyncio.run(self._session(ready, failure))
        except Exception as exc:  # noqa: BLE001 - any bleak/D-Bus failure is a connection failure
            failure.append(_reason(exc))
        finally:
            ready.set()
            self._set_lost("BLE connection closed")

    async def _session(self, ready: threading.Event, failure: list[str]) -> None:
        from bleak import BleakClient, BleakScanner

        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        target = self.target
        if ADDRESS_RE.fullmatch(target):
            device = await BleakScanner.find_device_by_address(target, timeout=SCAN_TIMEOUT_S)
        else:  # a part of the advertised name, any case
            device = await BleakScanner.find_device_by_filter(
                lambda d, adv: target.lower() in (d.name or adv.local_name or "").lower(), timeout=SCAN_TIMEOUT_S)
        if device is None:
            failure.append(f"expected a BLE device {target!r} in range, found none")
            return
        async with BleakClient(device, disconnected_callback=lambda _c: self._set_lost("BLE link lost"),
                               timeout=CONNECT_TIMEOUT_S) as client:
            await client.start_notify(HR_MEASUREMENT_UUID, lambda _h, data: self._notified(bytes(data)))
            ready.set()
            await self._stop.wait()

    def _notified(self, data: bytes) -> None:
        with self._cond:
            self.notifications += 1
            try:
                self._buf += frame(data)
            except ValueError:
                return
            self._cond.notify_all()

    def _set_lost(self, why: str) -> None:
        with self._cond:
            self._lost = self._lost or why
            self._cond.notify_all()

    @property
    def in_waiting(self) -> int:
        """Bytes ready to read."""
        with self._cond:
            return len(self._buf)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes, waiting at most ``timeout``; raise once the link is lost and drained."""
        if not self.is_open:
            raise PortNotOpenError()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        with self._cond:
            while not self._buf and self._lost is None:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return b""
                self._cond.wait(left)
            if not self._buf:
                raise SerialException(f"ble://{self.target}: {self._lost}")
            out = bytes(self._buf[:size])
            del self._buf[:size]
            return out

    def write(self, data: Buffer) -> int:
        """A strap takes no commands: accepted and dropped."""
        return len(memoryview(data))

    def _shutdown(self) -> None:
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and loop.is_running():
            loop.call_soon_threadsafe(stop.set)
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def close(self) -> None:
        """Unsubscribe and disconnect."""
        self._shutdown()
        self.is_open = False

    def _reconfigure_port(self) -> None:
        """Nothing to configure on a BLE link."""

    def reset_input_buffer(self) -> None:
        """Drop bytes not read yet."""
        with self._cond:
            self._buf.clear()

    def reset_output_buffer(self) -> None:
        """Nothing is buffered for output."""
