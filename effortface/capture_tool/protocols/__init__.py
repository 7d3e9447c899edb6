"""Sans-I/O heart-rate strap decoders: fed bytes in any chunking, they return samples and counters.

Every decoder knows nothing of ports or threads (the pyserial ``threaded`` pattern): the serial
link, replay and the ``decode`` command all call :meth:`Decoder.feed` with whatever bytes arrived and
the host time of their arrival. A decoder resyncs after garbage, bad checksums, padding, implausible
lengths and a truncated last frame, and counts what it dropped in :attr:`Decoder.stats`.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
from collections.abc import Iterable, Mapping
from typing import ClassVar

from effortface.core.errors import SessionFormatError, UserError
from effortface.core.hr_sample import HrSample  # noqa: F401  (defined below the stages: the session format uses it)
from effortface.core.physio_limits import hr_plausible, rr_plausible

#: protocol name -> module in this package that defines ``DECODER`` (a Decoder subclass)
PROTOCOLS: dict[str, str] = {
    "ant": "effortface.capture_tool.protocols.ant",
    "hxm": "effortface.capture_tool.protocols.hxm",
    "hrmi": "effortface.capture_tool.protocols.hrmi",
    "lines": "effortface.capture_tool.protocols.lines",
    "ble_hrm": "effortface.capture_tool.protocols.ble_hrm",
}


@dataclasses.dataclass(frozen=True)
class DeviceEvent:
    """A change in the link to the strap (searching, tracking, lost, closed...), for ``events.csv``."""

    t_s: float
    kind: str
    label: str
    value: str = ""


@dataclasses.dataclass
class DecoderStats:
    """Counters a decoder keeps; ``frames_bad`` + ``bytes_dropped`` say what resync threw away."""

    bytes_in: int = 0
    frames_ok: int = 0
    frames_bad: int = 0
    bytes_dropped: int = 0
    samples: int = 0
    invalid_samples: int = 0
    detail: dict[str, int] = dataclasses.field(default_factory=dict)

    def count(self, key: str, n: int = 1) -> None:
        """Add ``n`` to a named detail counter (e.g. ``"bad_checksum"``)."""
        self.detail[key] = self.detail.get(key, 0) + n

    def as_dict(self) -> dict[str, int]:
        """Flat dict of every counter, for logs and ``session.json``."""
        out = dataclasses.asdict(self)
        out.pop("detail")
        out.update(self.detail)
        return out


class Decoder:
    """Base class of the sans-I/O decoders.

    Subclasses implement :meth:`_consume`, which takes bytes from ``self._buf`` and returns the
    samples completed; they never block and never do I/O.
    """

    name: ClassVar[str] = ""
    #: bytes the link writes to the device once after opening (e.g. an HRMI poll, nothing for HxM)
    startup_bytes: ClassVar[bytes] = b""
    #: bytes the link writes every ``poll_interval_s`` (polled protocols only)
    poll_bytes: ClassVar[bytes] = b""
    poll_interval_s: ClassVar[float] = 0.0

    def __init__(self) -> None:
        self._buf = bytearray()
        self._t_s = 0.0
        self.stats = DecoderStats()
        self._events: list[DeviceEvent] = []

    def feed(self, data: bytes, t_s: float = 0.0) -> list[HrSample]:
        """Decode ``data`` that arrived at host time ``t_s``; return the samples it completed."""
        self._t_s = t_s
        self.stats.bytes_in += len(data)
        self._buf += data
        return self._born(self._consume())

    def _born(self, samples: list[HrSample]) -> list[HrSample]:
        """Samples leaving the decoder: physiological limits applied (counted), then counted.

        A heart rate outside :data:`effortface.core.physio_limits.HR_BPM` makes the sample invalid
        (``implausible_hr``); an R-R interval outside ``RR_MS`` is dropped (``implausible_rr``).
        """
        out = [self._within_limits(s) for s in samples]
        self.stats.samples += len(out)
        self.stats.invalid_samples += sum(not s.valid for s in out)
        return out

    def _within_limits(self, s: HrSample) -> HrSample:
        """``s`` with an implausible heart rate marked invalid and implausible RR dropped."""
        rr = tuple(r for r in s.rr_ms if rr_plausible(r))
        if len(rr) != len(s.rr_ms):
            self.stats.count("implausible_rr", len(s.rr_ms) - len(rr))
        bad_hr = s.hr_bpm is not None and not hr_plausible(s.hr_bpm)
        if bad_hr:
            self.stats.count("implausible_hr")
        if not bad_hr and len(rr) == len(s.rr_ms):
            return s
        valid = s.valid and not bad_hr
        return dataclasses.replace(s, hr_bpm=s.hr_bpm if valid else None, rr_ms=rr, valid=valid)

    def finish(self) -> list[HrSample]:
        """End of stream: count a truncated trailing frame as dropped and return any last samples."""
        if self._buf:
            self.stats.count("truncated_tail")
            self.stats.bytes_dropped += len(self._buf)
            self._buf.clear()
        return []

    def pop_events(self) -> list[DeviceEvent]:
        """Return and clear the link events (state changes) seen since the last call."""
        events, self._events = self._events, []
        return events

    def _emit_event(self, kind: str, label: str, value: str = "") -> None:
        self._events.append(DeviceEvent(self._t_s, kind, label, value))

    def _drop(self, n: int, reason: str) -> None:
        """Discard ``n`` bytes from the front of the buffer and count why."""
        del self._buf[:n]
        self.stats.bytes_dropped += n
        self.stats.count(reason, 1)

    def _consume(self) -> list[HrSample]:  # pragma: no cover - abstract
        raise NotImplementedError


def decode_chunks(decoder: Decoder, chunks: Iterable[tuple[float, bytes]]) -> list[HrSample]:
    """Feed ``(t_s, bytes)`` chunks to ``decoder`` and finish it; return every sample.

    Parameters
    ----------
    decoder : Decoder
        A fresh decoder.
    chunks : iterable of (float, bytes)
        Arrival time and bytes of each read.

    Returns
    -------
    list of HrSample
    """
    out: list[HrSample] = []
    for t_s, data in chunks:
        out += decoder.feed(data, t_s)
    return out + decoder.finish()

def check_protocol(protocol: str) -> str:
    """``protocol`` if it is one of :data:`PROTOCOLS`, else a UserError naming ``--protocol``."""
    if protocol not in PROTOCOLS:
        raise UserError(f"--protocol: expected one of {', '.join(sorted(PROTOCOLS))}, found {protocol!r}")
    return protocol


def get_decoder(protocol: str, **options: object) -> Decoder:
    """Return a fresh decoder for ``protocol``.

    Parameters
    ----------
    protocol : str
        One of :data:`PROTOCOLS`.
    **options
        Passed to the decoder class (e.g. ``device_type`` for ANT).

    Raises
    ------
    UserError
        If the protocol is unknown.
    """
    module = importlib.import_module(PROTOCOLS[check_protocol(protocol)])
    return module.DECODER(**options)


def header_protocol(header: Mapping[str, object], path: str | os.PathLike) -> str:
    """The protocol a ``.serlog`` header names.

    Parameters
    ----------
    header : mapping
        The parsed header line.
    path : path-like
        The serial log, named in the message.

    Raises
    ------
    SessionFormatError
        If the header's ``protocol`` is missing or not one of :data:`PROTOCOLS`.
    """
    protocol = header.get("protocol")
    if not isinstance(protocol, str) or protocol not in PROTOCOLS:
        raise SessionFormatError(f"{path}: header field 'protocol': expected one of "
                                 f"{', '.join(sorted(PROTOCOLS))}, found {protocol!r}")
    return protocol
