"""Polar / SparkFun Heart Rate Monitor Interface (HRMI, danjuliodesigns), serial mode, polled.

The host sends ``G<n>\\r`` ("get heart rate data", n = 1..32 history entries) and the HRMI replies
with one line of space-separated decimal numbers::

    <status> <count> <hr1> ... <hrn>\\r       hr1 is the most recent value

``count`` is an 8-bit counter of the heart-rate values the HRMI has computed so far (it wraps at 255):
a reply whose count equals the previous reply's holds nothing new and yields no sample, so polling
faster than the strap beats never repeats a value. ``hr1`` is the value emitted.

Invalid readings (no transmitter in range, no contact): an HR of 0 (the HRMI reports 0 before it
has data), or a status byte with a bit of :attr:`HrmiDecoder.invalid_status_mask` set. **Our
reading, not verified on a unit:** bit 0 of the status byte is the averaging mode (the published
examples show status 1 in averaging mode and 0 in raw mode with good data), so the default mask is
bit 1 (0x02); pass ``invalid_status_mask=0`` to rely on HR 0 alone.
"""

from __future__ import annotations

import re

from effortface.capture_tool.protocols import HrSample
from effortface.capture_tool.protocols.lines import LineDecoderBase
from effortface.core.physio_limits import hr_plausible

MAX_LINE = 200  # "255 255" + 32 values of 3 digits: a longer line is garbage
_REPLY_RE = re.compile(rb"(\d{1,3})((?: \d{1,3})+)")


class HrmiDecoder(LineDecoderBase):
    """Decoder for HRMI replies to ``G1``; one sample per reply with a new count.

    Parameters
    ----------
    invalid_status_mask : int
        Status bits that mark the reading invalid (see the module docstring).
    device : str
        Device identifier written in the samples.
    """

    name = "hrmi"
    startup_bytes = b"G1\r"
    poll_bytes = b"G1\r"
    poll_interval_s = 1.0
    max_line = MAX_LINE

    def __init__(self, invalid_status_mask: int = 0x02, device: str = "hrmi") -> None:
        super().__init__()
        self.invalid_status_mask = int(invalid_status_mask)
        self.device = device
        self._last_count: int | None = None

    def _find_eol(self) -> int:
        """The HRMI ends replies with ``\\r`` (some adapters add ``\\n``): either ends a line."""
        cr = self._buf.find(b"\r")
        lf = self._buf.find(b"\n", 0, len(self._buf) if cr < 0 else cr)  # only a \n before the \r
        return cr if lf < 0 else lf

    def _parse_line(self, line: bytes, n_bytes: int) -> list[HrSample]:
        if not line:
            return []  # the \n of a \r\n pair, or an empty reply
        m = _REPLY_RE.fullmatch(line)
        values = [int(v) for v in m.group(2).split()] if m else []
        if not m or len(values) < 2 or max(values[:1] + [int(m.group(1))]) > 255:
            self._unparsed(n_bytes)
            return []
        self.stats.frames_ok += 1
        return self._sample(int(m.group(1)), values[0], values[1])

    def _sample(self, status: int, count: int, hr: int) -> list[HrSample]:
        if count == self._last_count:
            self.stats.count("no_new_value")
            return []
        self._last_count = count
        valid = not status & self.invalid_status_mask and hr_plausible(hr)
        return [HrSample(self._t_s, float(hr) if valid else None, (), count, self.device, valid)]


def poll_command(n_values: int = 1) -> bytes:
    """The ``G<n>\\r`` request for the ``n_values`` most recent heart-rate values (1..32)."""
    if not 1 <= n_values <= 32:
        raise ValueError(f"n_values: expected 1..32, found {n_values}")
    return b"G%d\r" % n_values


DECODER = HrmiDecoder
