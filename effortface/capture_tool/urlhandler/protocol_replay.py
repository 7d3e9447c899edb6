"""``replay://<path>?speed=X&unplug_after=S``: a pyserial port that plays a recording in process.

The bytes of a ``.serlog`` (or raw capture with timing) become readable at their recorded times
divided by ``speed``, counted from :meth:`Serial.open`. After ``unplug_after`` seconds of the
recording, reads raise :class:`serial.SerialException` as a pulled USB stick does. Writes (poll
bytes, ANT configuration) are accepted and counted in ``bytes_sent``. For in-process tests; use
:mod:`effortface.capture_tool.replay` for a real pseudo-terminal that another process opens.
"""

from __future__ import annotations

import time
import urllib.parse as urlparse
from typing import TYPE_CHECKING, Any

from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from effortface.core.errors import UserError

if TYPE_CHECKING:
    from typing_extensions import Buffer  # typing only (collections.abc.Buffer from Python 3.12)


class Serial(SerialBase):
    """Serial port that replays a recording (see the module docstring for the URL form)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._data = b""
        self._due_s: list[tuple[float, int]] = []  # (time, end offset in _data)
        self._pos = 0
        self._t0 = 0.0
        self._speed = 1.0
        self._unplug_after_s: float | None = None
        self.bytes_sent = 0
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        """Load the recording named in the URL and start its clock."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self.port is None:
            raise SerialException("Port must be configured before it can be used.")
        path = self.from_url(self.port)
        from effortface.capture_tool.replay import load_timed_chunks

        try:
            chunks = load_timed_chunks(path)
        except UserError as exc:
            raise SerialException(2, str(exc)) from None
        end = 0
        for c in chunks:
            end += len(c.data)
            self._due_s.append((c.t_s, end))
        self._data = b"".join(c.data for c in chunks)
        self._pos = 0
        self._t0 = time.monotonic()
        self.is_open = True

    def from_url(self, url: str) -> str:
        """Parse ``replay://<path>?speed=X&unplug_after=S``; return the path."""
        parts = urlparse.urlsplit(url)
        if parts.scheme != "replay":
            raise SerialException(f"expected a URL replay://<path>[?speed=X&unplug_after=S], found {url!r}")
        try:
            for option, values in urlparse.parse_qs(parts.query, True).items():
                if option == "speed":
                    self._speed = float(values[0])
                    if not self._speed > 0:
                        raise ValueError(f"speed must be above 0, found {values[0]}")
                elif option == "unplug_after":
                    self._unplug_after_s = float(values[0])
                else:
                    raise ValueError(f"unknown option {option!r}")
        except ValueError as exc:
            raise SerialException(f"expected a URL replay://<path>[?speed=X&unplug_after=S]: {exc}") from None
        return urlparse.unquote(parts.netloc + parts.path)

    def _reconfigure_port(self) -> None:
        """Nothing to configure: settings are kept for get_settings() only."""

    def close(self) -> None:
        """Close the port."""
        self.is_open = False
        super().close()

    def _log_time_s(self) -> float:
        return (time.monotonic() - self._t0) * self._speed

    def _available_end(self) -> int:
        """Offset in the data up to which bytes are due now."""
        now = self._log_time_s()
        end = self._pos
        for t_s, stop in self._due_s:
            if t_s > now:
                break
            end = stop
        return max(end, self._pos)

    def _check_plugged(self) -> None:
        if self._unplug_after_s is not None and self._log_time_s() >= self._unplug_after_s:
            raise SerialException("device reports readiness to read but returned no data (replay unplugged)")

    @property
    def in_waiting(self) -> int:
        """Bytes due and not yet read."""
        if not self.is_open:
            raise PortNotOpenError()
        return self._available_end() - self._pos

    def read(self, size: int = 1) -> bytes:
        """Return up to ``size`` due bytes, waiting up to ``timeout`` for the first."""
        if not self.is_open:
            raise PortNotOpenError()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        while True:
            self._check_plugged()
            end = min(self._available_end(), self._pos + size)
            if end > self._pos:
                out, self._pos = self._data[self._pos:end], end
                return out
            if deadline is not None and time.monotonic() >= deadline:
                return b""
            time.sleep(0.002)

    def write(self, data: Buffer) -> int:
        """Accept and count bytes sent to the device."""
        if not self.is_open:
            raise PortNotOpenError()
        n_bytes = memoryview(data).nbytes
        self.bytes_sent += n_bytes
        return n_bytes

    def reset_input_buffer(self) -> None:
        """Skip nothing: the recording is the input."""

    def reset_output_buffer(self) -> None:
        """Nothing buffered."""
