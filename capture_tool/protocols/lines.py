"""Text-line heart-rate protocols: PulseSensor ``B<bpm>`` / ``Q<ibi_ms>`` / ``S<raw>``, ``HR:<bpm>``
and CSV lines ``<bpm>[,<rr_ms>]``.

Lines end with ``\\n`` (a ``\\r`` before it is ignored). A line that matches no form is dropped and
counted; a line longer than :data:`MAX_LINE` bytes without a newline is implausible and dropped.
A ``Q`` (inter-beat interval) line attaches its RR to the next ``B`` line, as PulseSensor sends
``B`` then ``Q`` on each beat: a ``Q`` with no pending ``B`` is emitted on its own with the last HR.
"""

from __future__ import annotations

import re

from capture_tool.protocols import Decoder, HrSample

MAX_LINE = 80
_HR_RE = re.compile(rb"^(?:B|HR:?\s*)(\d{1,3}(?:\.\d+)?)$", re.IGNORECASE)
_IBI_RE = re.compile(rb"^Q(\d{2,5})$")
_RAW_RE = re.compile(rb"^S-?\d+$")
_CSV_RE = re.compile(rb"^(\d{1,3}(?:\.\d+)?)(?:[,;\s]+(\d{2,5}(?:\.\d+)?))?$")


class LinesDecoder(Decoder):
    """Decoder for newline-terminated ASCII heart-rate lines."""

    name = "lines"

    def __init__(self, device: str = "lines") -> None:
        super().__init__()
        self.device = device

    def _consume(self) -> list[HrSample]:
        out: list[HrSample] = []
        while True:
            nl = self._buf.find(b"\n")
            if nl < 0:
                if len(self._buf) > MAX_LINE:
                    self._drop(len(self._buf), "line_too_long")
                return out
            line = bytes(self._buf[:nl]).strip(b"\r\x00 \t")
            del self._buf[: nl + 1]
            sample = self._parse(line, nl + 1)
            if sample is not None:
                out.append(sample)

    def _parse(self, line: bytes, n_bytes: int) -> HrSample | None:
        if not line or _RAW_RE.match(line):
            return None  # blank line or PulseSensor raw signal: nothing to decode, nothing lost
        m = _HR_RE.match(line) or _CSV_RE.match(line)
        if m:
            self.stats.frames_ok += 1
            hr = float(m.group(1))
            rr = (float(m.group(2)),) if m.lastindex and m.lastindex >= 2 and m.group(2) else ()
            return self._sample(hr, rr)
        m = _IBI_RE.match(line)
        if m:
            self.stats.frames_ok += 1
            self.stats.count("ibi_lines")
            return self._sample(None, (float(m.group(1)),), rr_only=True)
        self.stats.frames_bad += 1
        self.stats.bytes_dropped += n_bytes
        self.stats.count("unparsed_line")
        return None

    def _sample(self, hr: float | None, rr: tuple[float, ...], rr_only: bool = False) -> HrSample | None:
        if rr_only:
            # PulseSensor sends Q just after B: the IBI belongs to the beat already emitted.
            hr = getattr(self, "_last_hr", None)
            if hr is None:
                return None
        valid = hr is not None and 20 <= hr <= 250
        if not rr_only:
            self._last_hr = hr if valid else None
        return HrSample(self._t_s, hr if valid else None, rr, None, self.device, valid)


DECODER = LinesDecoder
