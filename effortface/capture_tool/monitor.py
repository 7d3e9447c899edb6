"""Live heart rate before Record: a strap watched as soon as it is chosen (Qt-free).

:class:`StrapMonitor` reads the chosen port with the recorder's own :class:`SerialLink` and decoder
(its raw log goes to a temporary folder, deleted at :meth:`StrapMonitor.stop`), so what the
operator sees before Record is what the recording will get: heart rate, last R-R interval, the
effective sample rate, the time since the last sample and the share of samples with skin contact.
Record stops the monitor first (a real port is opened exclusively).
"""

from __future__ import annotations

import collections
import dataclasses
import queue
import tempfile
import threading
import time
from pathlib import Path

from effortface.capture_tool.protocols import HrSample, get_decoder
from effortface.capture_tool.recorder import device_startup_frames
from effortface.capture_tool.serial_link import SerialLink

#: seconds of samples the rate and contact figures are computed over
WINDOW_S = 10.0


@dataclasses.dataclass(frozen=True)
class MonitorStats:
    """What the strap sends now.

    Attributes
    ----------
    port, link_state : str
        The port watched and its link state (``connected``, ``reconnecting``...).
    hr_bpm, rr_ms : float or None
        Last valid heart rate and last R-R interval (None: none yet, or no contact now).
    rate_hz : float or None
        Samples per second over the last :data:`WINDOW_S` (None: fewer than two samples).
    since_last_s : float or None
        Seconds since the last sample (None: none yet).
    contact_fraction : float or None
        Share of the last :data:`WINDOW_S` samples with skin contact (the protocol's validity).
    contact_now : bool or None
        Whether the last sample had contact.
    frames_bad : int
        Frames the decoder rejected (checksum, length) since the monitor started.
    bytes_in, samples_total : int
        Bytes received and heart-rate samples decoded since the monitor started (bytes without a
        sample: the protocol is likely wrong).
    new : tuple of (t_s, hr_bpm or None)
        The samples arrived since the previous poll (monitor seconds; None: no contact), for the
        live plot before Record.
    """

    port: str
    link_state: str
    hr_bpm: float | None
    rr_ms: float | None
    rate_hz: float | None
    since_last_s: float | None
    contact_fraction: float | None
    contact_now: bool | None
    frames_bad: int
    bytes_in: int = 0
    samples_total: int = 0
    new: tuple[tuple[float, float | None], ...] = ()


class StrapMonitor:
    """Watch one strap port without recording it.

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    protocol : str
        Decoder name (``hxm``, ``ant``...).
    """

    def __init__(self, port: str, protocol: str) -> None:
        self.port, self.protocol = port, protocol
        self._queue: queue.Queue = queue.Queue()
        self._t0 = time.monotonic()
        self._dir: tempfile.TemporaryDirectory[str] | None = None
        self._recent: collections.deque[HrSample] = collections.deque()
        self._last_valid: HrSample | None = None
        self._samples_total = 0
        self.link = SerialLink(port, get_decoder(protocol), self._queue, self.clock, protocol,
                               startup_frames=device_startup_frames(protocol, port))

    def clock(self) -> float:
        """Seconds since the monitor was made."""
        return time.monotonic() - self._t0

    def start(self) -> None:
        """Open the port and start reading (blocking for the open; DeviceError if it fails)."""
        self._dir = tempfile.TemporaryDirectory(prefix="effortface-monitor-")
        try:
            self.link.start(Path(self._dir.name) / "monitor.serlog")
        except BaseException:
            self._dir.cleanup()
            raise

    def stop(self) -> None:
        """Close the port and delete the temporary log (idempotent)."""
        if self._dir is None:
            return
        self.link.stop(timeout_s=2.0)
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None

    def poll(self) -> MonitorStats:
        """Take what arrived since the last call and summarise it (never blocks)."""
        now = self.clock()
        new: list[tuple[float, float | None]] = []
        while True:
            try:
                kind, item = self._queue.get_nowait()
            except queue.Empty:
                break
            if kind == "hr":
                self._samples_total += 1
                self._recent.append(item)
                new.append((item.t_s, item.hr_bpm if item.valid else None))
                if item.valid and item.hr_bpm is not None:
                    self._last_valid = item
        while self._recent and self._recent[0].t_s < now - WINDOW_S:
            self._recent.popleft()
        return dataclasses.replace(self._stats(now), new=tuple(new))

    def _stats(self, now: float) -> MonitorStats:
        recent = list(self._recent)
        last = recent[-1] if recent else None
        contact_now = None if last is None else last.valid
        live = self._last_valid if contact_now else None
        rate = ((len(recent) - 1) / (recent[-1].t_s - recent[0].t_s)
                if len(recent) > 1 and recent[-1].t_s > recent[0].t_s else None)
        return MonitorStats(
            port=self.port, link_state=self.link.state,
            hr_bpm=None if live is None else live.hr_bpm,
            rr_ms=live.rr_ms[-1] if live is not None and live.rr_ms else None,
            rate_hz=rate, since_last_s=None if last is None else max(0.0, now - last.t_s),
            contact_fraction=sum(s.valid for s in recent) / len(recent) if recent else None,
            contact_now=contact_now, frames_bad=self.link.decoder.stats.frames_bad,
            bytes_in=self.link.decoder.stats.bytes_in, samples_total=self._samples_total)


class MonitorPool:
    """The monitors a stage opened (in jobs), so that closing the stage closes every port, even one a
    job opened whose result was never delivered. Thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._opened: list[StrapMonitor] = []
        self._closing = False

    def open(self, port: str, protocol: str) -> StrapMonitor:
        """Open a monitor (blocking) and keep it; UserError once :meth:`close_all` was called."""
        from effortface.core.errors import UserError

        with self._lock:
            if self._closing:
                raise UserError(f"{port}: not watched (the stage is closing)")
            monitor = StrapMonitor(port, protocol)
            monitor.start()
            self._opened = [m for m in self._opened if m._dir is not None] + [monitor]
            return monitor

    def close_all(self) -> None:
        """Close every monitor opened, and open no more."""
        with self._lock:
            self._closing = True
            opened, self._opened = self._opened, []
        for monitor in opened:
            monitor.stop()
