"""A minimal valid XDF 1.0 writer for the tests (the format: github.com/sccn/xdf/wiki/Specifications).

Chunks: ``NumLengthBytes, Length, Tag (uint16), content``; tags 1 FileHeader, 2 StreamHeader,
3 Samples, 4 ClockOffset, 6 StreamFooter; every timestamp written in full (8 bytes)."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape


def _varlen(n: int) -> bytes:
    if n < 256:
        return b"\x01" + bytes([n])
    if n < 2 ** 32:
        return b"\x04" + struct.pack("<I", n)
    return b"\x08" + struct.pack("<Q", n)


def _chunk(tag: int, content: bytes) -> bytes:
    body = struct.pack("<H", tag) + content
    return _varlen(len(body)) + body


@dataclass
class XdfStream:
    """One stream: header fields, channel labels/units, samples and their LSL time stamps."""

    name: str
    type: str
    channels: list[tuple[str, str]]
    stamps: list[float]
    samples: list[list]
    fmt: str = "float32"          # or "string"
    srate_hz: float = 0.0
    clock_offsets: list[tuple[float, float]] = field(default_factory=lambda: [(0.0, 0.0), (60.0, 0.0)])

    def header_xml(self) -> bytes:
        chans = "".join(f"<channel><label>{escape(lab)}</label><unit>{escape(u)}</unit></channel>"
                        for lab, u in self.channels)
        return (f'<?xml version="1.0"?><info><name>{escape(self.name)}</name><type>{escape(self.type)}</type>'
                f"<channel_count>{len(self.channels)}</channel_count><nominal_srate>{self.srate_hz}</nominal_srate>"
                f"<channel_format>{self.fmt}</channel_format><source_id>{escape(self.name)}</source_id>"
                f"<created_at>0</created_at><desc><channels>{chans}</channels></desc></info>").encode()

    def samples_bytes(self) -> bytes:
        out = _varlen(len(self.samples))
        for stamp, sample in zip(self.stamps, self.samples):
            out += b"\x08" + struct.pack("<d", stamp)
            if self.fmt == "string":
                for value in sample:
                    raw = str(value).encode()
                    out += _varlen(len(raw)) + raw
            else:
                out += struct.pack(f"<{len(sample)}f", *sample)
        return out


def write_xdf(path: Path, streams: list[XdfStream]) -> Path:
    """Write the streams as an XDF file."""
    data = b"XDF:" + _chunk(1, b'<?xml version="1.0"?><info><version>1.0</version></info>')
    for sid, s in enumerate(streams, start=1):
        data += _chunk(2, struct.pack("<I", sid) + s.header_xml())
    for sid, s in enumerate(streams, start=1):
        for i in range(0, len(s.samples), 100):   # several sample chunks, as LabRecorder writes
            part = XdfStream(s.name, s.type, s.channels, s.stamps[i:i + 100], s.samples[i:i + 100], s.fmt)
            data += _chunk(3, struct.pack("<I", sid) + part.samples_bytes())
        for collected, offset in s.clock_offsets:
            data += _chunk(4, struct.pack("<Idd", sid, collected, offset))
    for sid, s in enumerate(streams, start=1):
        footer = (f'<?xml version="1.0"?><info><first_timestamp>{s.stamps[0] if s.stamps else 0}</first_timestamp>'
                  f"<last_timestamp>{s.stamps[-1] if s.stamps else 0}</last_timestamp>"
                  f"<sample_count>{len(s.samples)}</sample_count><clock_offsets></clock_offsets></info>").encode()
        data += _chunk(6, struct.pack("<I", sid) + footer)
    path.write_bytes(data)
    return path
