"""Readers for recorded strap byte streams with their arrival times: ``read_timed_capture(path)``.

Formats, chosen by magic number first, then by suffix:

- ``.serlog`` (our own format, :mod:`effortface.capture_tool.serlog`): every read with its host time.
- libpcap (``.pcap``, magic ``a1b2c3d4`` or ``a1b23c4d`` in either byte order): each record's payload
  is one raw read from the device (libant's ``PcapLogger`` writes them with link type 1), stamped
  with the record time.
- raw bytes (``.dat``, ``.bin``, ``.raw``, ``.txt`` or no suffix) with a sibling timing CSV:

  * ``<stem>-timing.csv`` or ``<stem>_timing.csv`` without a header, rows
    ``host_time_before_chunk,cumulative_end_offset`` (zephyr-bt's ``MessageDataLogger``): chunk i
    is the bytes up to that END offset;
  * a ``*timing.csv`` whose name (before ``timing``) starts the stem, with header
    ``host_time_s,byte_offset_<a>,byte_offset_<b>...``: START offsets of each frame; the column
    whose name ends the stem (``..._ext.bin`` -> ``byte_offset_ext``) is used, else the first;
  * no timing file: the whole file is one chunk at t = 0.

Times are returned relative to the first chunk. Bytes after the last timed offset form a last chunk
at the last time, so no byte is ever lost.
"""

from __future__ import annotations

import csv
import math
import os
import struct
from pathlib import Path

from effortface.core.bounds import is_number
from effortface.core.errors import SessionFormatError, UserError, not_text_error
from effortface.core.fileio import not_a_file
from effortface.capture_tool.serlog import MAGIC as SERLOG_MAGIC
from effortface.capture_tool.serlog import read_serlog

Chunk = tuple[float, bytes]
RAW_SUFFIXES = (".dat", ".bin", ".raw", ".txt", "")
_PCAP_MAGICS = {
    b"\xd4\xc3\xb2\xa1": ("<", 1e-6),
    b"\xa1\xb2\xc3\xd4": (">", 1e-6),
    b"\x4d\x3c\xb2\xa1": ("<", 1e-9),
    b"\xa1\xb2\x3c\x4d": (">", 1e-9),
}
_PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"


def read_timed_capture(path: str | os.PathLike) -> list[Chunk]:
    """Read a recorded byte stream as ``[(t_s, bytes), ...]`` in arrival order.

    Parameters
    ----------
    path : path-like
        A ``.serlog``, a ``.pcap``, or a raw capture (with or without a timing CSV beside it).

    Returns
    -------
    list of (float, bytes)
        Chunks with their arrival time in seconds: session time for a ``.serlog`` (so decoding a
        session's log gives the times of its ``heart_rate.csv``), else since the first chunk.

    Raises
    ------
    UserError
        If the file is missing, not a regular file or unreadable, or its format is not one of
        the above (a ``.serlog`` or ``.pcap`` with bad magic says so).
    SessionFormatError
        If a timing CSV or a pcap header is malformed.
    """
    path = check_capture_file(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(SERLOG_MAGIC))
    except OSError as exc:
        raise UserError(f"{path}: expected a readable capture file, found {exc.strerror or exc}") from None
    if head.startswith(SERLOG_MAGIC):
        return list(read_serlog(path).data_chunks())
    if head[:4] in _PCAP_MAGICS:
        chunks = _read_pcap(path)
    elif head[:4] == _PCAPNG_MAGIC:
        raise UserError(f"{path}: expected a libpcap file, found pcapng (convert: editcap -F pcap)")
    elif path.suffix.lower() in RAW_SUFFIXES:
        chunks = _read_raw(path)
    else:
        raise _bad_format(path, head)
    return _relative(chunks)


def check_capture_file(path: str | os.PathLike) -> Path:
    """``path`` as a Path if it is an existing regular file (never a FIFO or device that reads forever).

    Raises
    ------
    UserError
        If it is missing, a folder or not a regular file.
    """
    path = Path(path)
    found = not_a_file(path)
    if found:
        raise UserError(f"{path}: expected a readable capture file, found {found}")
    return path


def _bad_format(path: Path, head: bytes) -> UserError:
    """The error for a file whose magic fits no format: bad magic for a known suffix, else the suffix."""
    suffix = path.suffix.lower()
    if suffix == ".serlog":
        return SessionFormatError(f"{path}: expected a .serlog file starting with {SERLOG_MAGIC!r}, found {head!r}")
    if suffix == ".pcap":
        return SessionFormatError(f"{path}: expected a libpcap file starting with magic a1b2c3d4 or a1b23c4d, "
                                  f"found {head[:4].hex() or 'an empty file'}")
    return UserError(f"{path}: expected a .serlog, .pcap or raw .dat/.bin/.raw/.txt capture, "
                     f"found suffix {path.suffix!r}")


def _relative(chunks: list[Chunk]) -> list[Chunk]:
    """Shift times so the first chunk is at 0."""
    if not chunks:
        return []
    t0 = chunks[0][0]
    return [(t - t0, data) for t, data in chunks]


def _read_pcap(path: Path) -> list[Chunk]:
    """Payloads of a libpcap file's records with their record times (a cut last record is dropped)."""
    blob = path.read_bytes()
    if len(blob) < 24:
        raise SessionFormatError(f"{path}: expected a 24-byte pcap header, found {len(blob)} bytes")
    endian, tick = _PCAP_MAGICS[blob[:4]]
    rec = struct.Struct(endian + "IIII")
    chunks: list[Chunk] = []
    pos = 24
    while pos + rec.size <= len(blob):
        sec, frac, incl, _orig = rec.unpack_from(blob, pos)
        end = pos + rec.size + incl
        if end > len(blob):
            break
        chunks.append((sec + frac * tick, blob[pos + rec.size : end]))
        pos = end
    return chunks


def _read_raw(path: Path) -> list[Chunk]:
    blob = path.read_bytes()
    timing = find_timing_file(path)
    if timing is None:
        return [(0.0, blob)] if blob else []
    rows = _read_timing_rows(timing)
    if not rows:
        raise SessionFormatError(f"{timing}: expected the arrival times of {path.name}'s bytes, found an "
                                 "empty file (move it away to decode without times)")
    if not is_number(rows[0][0]):
        return _chunks_from_starts(blob, rows, _offset_column(rows[0], path, timing), timing)
    return _chunks_from_ends(blob, rows, timing)


def find_timing_file(path: str | os.PathLike) -> Path | None:
    """The timing CSV that belongs to a raw capture, or None (see the module docstring)."""
    path = Path(path)
    for name in (f"{path.stem}-timing.csv", f"{path.stem}_timing.csv"):
        if (path.parent / name).is_file():
            return path.parent / name
    for cand in sorted(path.parent.glob("*timing.csv")):
        prefix = cand.name[: -len("timing.csv")].rstrip("-_")
        if prefix and path.stem.startswith(prefix) and cand.is_file():
            return cand
    return None


def _read_timing_rows(timing: Path) -> list[list[str]]:
    """The non-empty rows of a timing CSV; SessionFormatError naming it if it is not CSV text."""
    try:
        with open(timing, newline="", encoding="utf-8") as fh:
            return [row for row in csv.reader(fh) if row]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise not_text_error(timing, exc) from None



def _offset_column(header: list[str], path: Path, timing: Path) -> int:
    """Index of the ``byte_offset_*`` column that matches the capture's stem (else the first)."""
    cols = [i for i, name in enumerate(header) if name.startswith("byte_offset")]
    if not cols:
        raise SessionFormatError(f"{timing}: expected a byte_offset_* column, found {header}")
    for i in cols:
        tag = header[i][len("byte_offset") :].lstrip("_")
        if tag and path.stem.endswith("_" + tag):
            return i
    return cols[0]


def _parse_row(row: list[str], col: int, timing: Path, line: int) -> tuple[float, int]:
    """``(time, offset)`` of one timing row; SessionFormatError naming the line unless both are numbers."""
    try:
        t, offset = float(row[0]), int(row[col])
    except (ValueError, IndexError):
        t, offset = math.nan, -1
    if not math.isfinite(t) or offset < 0:
        raise SessionFormatError(
            f"{timing}: line {line}: expected 'time,offset' numbers (offset >= 0), found {','.join(row)!r}"
        )
    return t, offset


def _start_marks(rows: list[list[str]], col: int, timing: Path) -> list[tuple[float, int]]:
    """The ``(time, START offset)`` rows after the header; they must exist and be in offset order.

    Raises
    ------
    SessionFormatError
        If there is no row after the header, or an offset is below the one before it (the
        message names the timing file and line).
    """
    if len(rows) < 2:
        raise SessionFormatError(f"{timing}: expected 'time,offset' rows after the header, found none")
    marks: list[tuple[float, int]] = []
    for line, row in enumerate(rows[1:], 2):
        t, start = _parse_row(row, col, timing, line)
        if marks and start < marks[-1][1]:
            raise SessionFormatError(f"{timing}: line {line}: expected an offset >= {marks[-1][1]} "
                                     f"(offsets in order), found {start}")
        marks.append((t, start))
    return marks


def _chunks_from_ends(blob: bytes, rows: list[list[str]], timing: Path) -> list[Chunk]:
    """Rows ``(time before chunk, cumulative END offset)``: zephyr-bt's logger."""
    chunks: list[Chunk] = []
    start, t = 0, 0.0
    for line, row in enumerate(rows, 1):
        t, end = _parse_row(row, 1, timing, line)
        end = min(end, len(blob))
        if end > start:
            chunks.append((t, blob[start:end]))
            start = end
    if start < len(blob):
        chunks.append((t, blob[start:]))  # bytes past the last logged offset: keep them
    return chunks


def _chunks_from_starts(blob: bytes, rows: list[list[str]], col: int, timing: Path) -> list[Chunk]:
    """Header row then ``(time, START offset)`` rows: one frame per row."""
    marks = _start_marks(rows, col, timing)
    chunks: list[Chunk] = []
    if marks and marks[0][1] > 0:
        chunks.append((marks[0][0], blob[: marks[0][1]]))
    for k, (t, start) in enumerate(marks):
        end = marks[k + 1][1] if k + 1 < len(marks) else len(blob)
        if end > start:
            chunks.append((t, blob[start:end]))
    return chunks
