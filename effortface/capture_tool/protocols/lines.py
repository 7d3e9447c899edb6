"""Text-line heart-rate protocols: PulseSensor ``B<bpm>`` / ``Q<ibi_ms>`` / ``S<raw>``, ``HR:<bpm>``
and CSV lines ``<bpm>[,<rr_ms>]``.

Lines end with ``\\n`` (a ``\\r`` before it is ignored). A line that matches no form is dropped and
counted; a line longer than :data:`MAX_LINE` bytes without a newline is implausible and dropped.

PulseSensor sends ``B`` then ``Q`` on each beat, so a ``B`` sample is held until the next line: a
``Q`` attaches its inter-beat interval to it, anything else releases it without RR (the stream's
``S`` lines, sent every 20 ms, keep that delay short). A ``Q`` with no pending ``B`` is emitted with
the last valid HR. :meth:`LinesDecoder.finish` releases a beat still held at the end.
"""

from __future__ import annotations

import re

from effortface.capture_tool.protocols import Decoder, HrSample
from effortface.core.physio_limits import hr_plausible

MAX_LINE = 80
_BEAT_RE = re.compile(rb"B(\d{1,3}(?:\.\d+)?)")
_HR_RE = re.compile(rb"HR:?\s*(\d{1,3}(?:\.\d+)?)", re.IGNORECASE)
_IBI_RE = re.compile(rb"Q(\d{2,5})")
_RAW_RE = re.compile(rb"S-?\d+")
_CSV_RE = re.compile(rb"(\d{1,3}(?:\.\d+)?)(?:[,;\s]+(\d{2,5}(?:\.\d+)?))?")


class LineDecoderBase(Decoder):
    """Shared line framing: split at end-of-line bytes, drop over-long lines (counted once each).

    Subclasses set :attr:`max_line` and implement :meth:`_parse_line`.
    """

    max_line: int = MAX_LINE

    def __init__(self) -> None:
        super().__init__()
        self._discarding = False  # inside a line already dropped as too long

    def _find_eol(self) -> int:
        """Index of the byte that ends the first line (``\\n``), or -1."""
        return self._buf.find(b"\n")

    def _consume(self) -> list[HrSample]:
        out: list[HrSample] = []
        while True:
            eol = self._find_eol()
            too_long = eol > self.max_line or (eol < 0 and len(self._buf) > self.max_line)
            if self._discarding or too_long:
                if not self._discard_long_line(eol):
                    return out
                continue
            if eol < 0:
                return out
            line = bytes(self._buf[:eol]).strip(b"\r\n\x00 \t")
            del self._buf[: eol + 1]
            out += self._parse_line(line, eol + 1)

    def _discard_long_line(self, eol: int) -> bool:
        """Drop a too-long line up to its end, counted once; True once its end is gone."""
        if not self._discarding:
            self.stats.frames_bad += 1
            self.stats.count("line_too_long")
        self._discarding = eol < 0
        n = len(self._buf) if eol < 0 else eol + 1
        del self._buf[:n]
        self.stats.bytes_dropped += n
        return eol >= 0

    def finish(self) -> list[HrSample]:
        """End of stream: count an unterminated last line; the next stream starts clean."""
        self._discarding = False
        return super().finish()

    def _unparsed(self, n_bytes: int) -> None:
        """Count a complete line that matches no form."""
        self.stats.frames_bad += 1
        self.stats.bytes_dropped += n_bytes
        self.stats.count("unparsed_line")

    def _parse_line(self, line: bytes, n_bytes: int) -> list[HrSample]:  # pragma: no cover
        raise NotImplementedError


class LinesDecoder(LineDecoderBase):
    """Decoder for newline-terminated ASCII heart-rate lines."""

    name = "lines"

    def __init__(self, device: str = "lines") -> None:
        super().__init__()
        self.device = device
        self._pending: HrSample | None = None  # a B beat waiting for its Q
        self._last_hr: float | None = None

    def finish(self) -> list[HrSample]:
        """End of stream: release a held beat and count an unterminated last line."""
        return self._born(self._release()) + super().finish()

    def _release(self) -> list[HrSample]:
        pending, self._pending = self._pending, None
        return [pending] if pending is not None else []

    def _parse_line(self, line: bytes, n_bytes: int) -> list[HrSample]:
        if not line:
            return []
        m = _IBI_RE.fullmatch(line)
        if m:
            self.stats.frames_ok += 1
            return self._ibi(float(m.group(1)))
        out = self._release()
        if _RAW_RE.fullmatch(line):
            return out  # PulseSensor raw signal: nothing to decode, nothing lost
        m = _BEAT_RE.fullmatch(line)
        if m:
            self.stats.frames_ok += 1
            self._pending = self._sample(float(m.group(1)), ())
            return out
        m = _HR_RE.fullmatch(line) or _CSV_RE.fullmatch(line)
        if m:
            self.stats.frames_ok += 1
            rr = (float(m.group(2)),) if m.lastindex == 2 and m.group(2) else ()
            return out + [self._sample(float(m.group(1)), rr)]
        self._unparsed(n_bytes)
        return out

    def _ibi(self, ibi_ms: float) -> list[HrSample]:
        """Attach a ``Q`` interval to the held beat, or emit it with the last valid HR."""
        self.stats.count("ibi_lines")
        if self._pending is not None:
            beat, self._pending = self._pending, None
            return [HrSample(beat.t_s, beat.hr_bpm, (ibi_ms,), None, self.device, beat.valid)]
        if self._last_hr is None:
            self.stats.count("orphan_ibi")
            return []
        return [HrSample(self._t_s, self._last_hr, (ibi_ms,), None, self.device, True)]

    def _sample(self, hr: float, rr: tuple[float, ...]) -> HrSample:
        valid = hr_plausible(hr)
        self._last_hr = hr if valid else None
        return HrSample(self._t_s, hr if valid else None, rr, None, self.device, valid)


DECODER = LinesDecoder
