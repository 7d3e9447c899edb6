"""The ``.serlog`` format: every raw byte received from a device, with its host arrival time.

Layout (little-endian)::

    b"EFSERLOG 1\\n"                       magic and format version
    <one line of UTF-8 JSON>\\n             header: device, protocol, port, settings, created_utc
    records, each:  kind:uint8  t_s:float64  n:uint32  payload[n]

``kind`` 0 is data (the bytes of one read), 1 is a link event (payload: UTF-8 JSON ``{"kind",
"label", "value"}``, e.g. a gap or a reconnect). ``t_s`` is seconds on the session's monotonic
clock. Records are appended and flushed as they arrive, so a file cut by a crash is readable: a
truncated last record is ignored and counted by :func:`read_serlog`.

A damaged record (a flipped kind byte, a length longer or shorter than its payload, a time that is
not a number) costs only itself: the reader resynchronises at the next offset where a well-formed
record is followed by another well-formed record (or the end of the file), and counts the bytes it
skipped and the places (:attr:`Serlog.skipped_bytes`, :meth:`Serlog.damage_warning`).
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from effortface.core.bounds import BOUNDS
from effortface.core.errors import SessionFormatError
from effortface.core.fileio import not_a_file

MAGIC = b"EFSERLOG 1\n"
DATA, EVENT = 0, 1
_REC = struct.Struct("<BdI")
_MAX_PAYLOAD = 1 << 24  # 16 MiB: larger is a corrupt length, not a read
#: a record time between 0 and this (a denormal from stray bytes) is damage: the clock ticks in ns
_MIN_T_S = 1e-9


@dataclasses.dataclass(frozen=True)
class SerlogRecord:
    """One record: ``kind`` (DATA or EVENT), host time ``t_s`` and ``payload`` bytes."""

    kind: int
    t_s: float
    payload: bytes

    def event(self) -> dict[str, str]:
        """The event dict of an EVENT record; ``{}`` if its payload is not a UTF-8 JSON object.

        Returns
        -------
        dict
            ``{"kind", "label", "value"}``, or ``{}`` for a corrupt payload (see :meth:`is_corrupt_event`).
        """
        try:
            event = json.loads(self.payload.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            return {}
        return event if isinstance(event, dict) else {}

    def is_corrupt_event(self) -> bool:
        """True for an EVENT record whose payload is not a UTF-8 JSON object."""
        return self.kind == EVENT and not self.event()


@dataclasses.dataclass
class Serlog:
    """A read ``.serlog``: its header, records, and how many trailing bytes were truncated."""

    path: Path
    header: dict
    records: list[SerlogRecord]
    truncated_bytes: int = 0
    #: bytes of damaged records the reader skipped to resynchronise, in how many places, and the first offset
    skipped_bytes: int = 0
    skipped_places: int = 0
    first_skip_at: int | None = None

    def damage_warning(self) -> str | None:
        """``'warning: FILE: skipped N damaged bytes in K places (first at byte B)'``, or None if none."""
        if not self.skipped_bytes:
            return None
        return (f"warning: {self.path}: skipped {self.skipped_bytes} damaged bytes in {self.skipped_places} "
                f"place{'s' if self.skipped_places != 1 else ''} (first at byte {self.first_skip_at})")

    def data_chunks(self) -> Iterator[tuple[float, bytes]]:
        """Yield ``(t_s, bytes)`` for every data record, in arrival order."""
        for rec in self.records:
            if rec.kind == DATA:
                yield rec.t_s, rec.payload

    def data_bytes(self) -> bytes:
        """All received bytes concatenated."""
        return b"".join(p for _, p in self.data_chunks())


class SerlogWriter:
    """Append-only writer; every :meth:`write` goes to the OS at once (nothing waits in a buffer).

    Parameters
    ----------
    path : path-like
        File to create. An existing file is never overwritten: it is appended to only when
        ``append=True`` (a reconnect within the same session), otherwise FileExistsError.
    header : dict
        JSON-serialisable description of the device and its settings.
    append : bool
        Continue an existing log (its header is kept).
    """

    def __init__(self, path: str | os.PathLike, header: dict, *, append: bool = False) -> None:
        self.path = Path(path)
        exists = self.path.exists() and self.path.stat().st_size > 0
        if exists and not append:
            raise FileExistsError(f"{self.path}: serial log exists; refusing to overwrite")
        self._fh: BinaryIO = open(self.path, "ab", buffering=0)
        if not exists:
            line = json.dumps(header, sort_keys=True).encode("utf-8")
            self._fh.write(MAGIC + line + b"\n")
        self.bytes_written = 0

    def write(self, t_s: float, data: bytes) -> None:
        """Append one read's bytes received at ``t_s``."""
        if data:
            self._write_all(_REC.pack(DATA, t_s, len(data)) + data)
            self.bytes_written += len(data)

    def write_event(self, t_s: float, kind: str, label: str = "", value: str = "") -> None:
        """Append a link event (gap, reconnect...) so a replay can reproduce it."""
        payload = json.dumps({"kind": kind, "label": label, "value": value}).encode("utf-8")
        self._write_all(_REC.pack(EVENT, t_s, len(payload)) + payload)

    def _write_all(self, record: bytes) -> None:
        """Write a whole record. An unbuffered write may be short (the disk filled mid-record): the
        rest is retried, so a full disk raises OSError instead of leaving a record silently torn."""
        view = memoryview(record)
        while view:
            n = self._fh.write(view)
            if not n:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
            view = view[n:]

    def sync(self) -> None:
        """Force the data to disk (``os.fsync``); called about once a second by the link."""
        os.fsync(self._fh.fileno())

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran."""
        return self._fh.closed

    def close(self) -> None:
        """Close the file (idempotent)."""
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> SerlogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _check_file(path: str | os.PathLike) -> Path:
    """``path`` as a Path if it is an existing regular file.

    Raises
    ------
    SessionFormatError
        If it is missing, a folder, or not a regular file (a FIFO, a device...).
    """
    path = Path(path)
    found = not_a_file(path)
    if found:
        raise SessionFormatError(f"{path}: expected a .serlog file, found {found}")
    return path


def read_serlog(path: str | os.PathLike) -> Serlog:
    """Read a ``.serlog`` file, tolerating a truncated last record and resynchronising after damage.

    Parameters
    ----------
    path : path-like
        The file.

    Returns
    -------
    Serlog

    Raises
    ------
    SessionFormatError
        If the path is not a regular file, does not start with the serlog magic or its header
        is not JSON.
    """
    path = _check_file(path)
    blob = path.read_bytes()
    if not blob.startswith(MAGIC):
        raise SessionFormatError(
            f"{path}: expected a .serlog file starting with {MAGIC!r}, found {blob[:11]!r}"
        )
    nl = blob.find(b"\n", len(MAGIC))
    try:
        header = json.loads(blob[len(MAGIC):nl].decode("utf-8")) if nl > 0 else None
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        header = None
    if not isinstance(header, dict):
        raise SessionFormatError(f"{path}: expected a JSON header line after the magic, found none")
    parsed = _parse_records(blob, nl + 1)
    return Serlog(path, header, parsed.records, truncated_bytes=parsed.truncated_bytes,
                  skipped_bytes=parsed.skipped_bytes, skipped_places=parsed.skipped_places,
                  first_skip_at=parsed.first_skip_at)


@dataclasses.dataclass
class _Parsed:
    records: list[SerlogRecord]
    truncated_bytes: int = 0
    skipped_bytes: int = 0
    skipped_places: int = 0
    first_skip_at: int | None = None


def _plausible_header(blob: bytes, pos: int) -> tuple[int, float, int] | None:
    """The ``(kind, t_s, n)`` of a record header at ``pos`` if it can be one (its payload may run past the end)."""
    if pos + _REC.size > len(blob) or blob[pos] not in (DATA, EVENT):
        return None
    kind, t_s, n = _REC.unpack_from(blob, pos)
    if not (t_s == 0.0 or BOUNDS["t_s"].contains(t_s) and t_s >= _MIN_T_S) or n > _MAX_PAYLOAD:
        return None
    return kind, t_s, n


def _record_end(blob: bytes, pos: int, min_t_s: float) -> int | None:
    """End offset of a well-formed record at ``pos`` (time from ``min_t_s`` on) followed by the end or a
    plausible header no earlier in time: where a resynchronisation may land."""
    end = _fitting_end(blob, pos)
    if end is None or not _followed_well(blob, end):
        return None
    t_s = _REC.unpack_from(blob, pos)[1]
    nxt = _plausible_header(blob, end)
    if t_s < min_t_s or (nxt is not None and nxt[1] < t_s):
        return None
    return end


def _fitting_end(blob: bytes, pos: int) -> int | None:
    """End offset of a record at ``pos`` whose header is plausible and whose payload fits in the file."""
    head = _plausible_header(blob, pos)
    if head is None or pos + _REC.size + head[2] > len(blob):
        return None
    return pos + _REC.size + head[2]


def _followed_well(blob: bytes, end: int) -> bool:
    """True if the file ends at ``end`` (or within a torn header) or a plausible header starts there."""
    return len(blob) - end < _REC.size or _plausible_header(blob, end) is not None


def _parse_records(blob: bytes, pos: int) -> _Parsed:
    """Parse records from ``pos``, resynchronising after a damaged one; a torn last record is truncation.

    A record whose successor is garbage is dropped too when its length was wrong: too long (a
    well-formed record chain starts inside its payload) or short by less than a header (the garbage
    after it is smaller than a record); otherwise only the garbage is skipped.
    """
    out = _Parsed([])
    while pos < len(blob):
        end = _fitting_end(blob, pos)
        t_min = out.records[-1].t_s if out.records else 0.0
        if end is not None and not _followed_well(blob, end):
            inside = _resync(blob, pos + 1, t_min, end)
            after = _resync(blob, end, t_min) if inside is None else None
            stop = inside if inside is not None else after if after is not None and after - end < _REC.size else None
            if stop is not None:
                _skip(out, pos, stop)
                pos = stop
                continue
        if end is not None:
            kind, t_s, _ = _REC.unpack_from(blob, pos)
            out.records.append(SerlogRecord(kind, t_s, blob[pos + _REC.size:end]))
            pos = end
            continue
        nxt = _resync(blob, pos + 1, t_min)
        if nxt is None:
            if _plausible_header(blob, pos) is not None or len(blob) - pos < _REC.size:  # a crash cut it
                out.truncated_bytes = len(blob) - pos
            else:
                _skip(out, pos, len(blob))
            break
        _skip(out, pos, nxt)
        pos = nxt
    return out


def _skip(out: _Parsed, start: int, stop: int) -> None:
    """Count the damaged bytes ``[start, stop)``."""
    out.skipped_bytes += stop - start
    out.skipped_places += 1
    if out.first_skip_at is None:
        out.first_skip_at = start


def _resync(blob: bytes, start: int, min_t_s: float, stop: int | None = None) -> int | None:
    """The first offset in ``[start, stop)`` where a well-formed record chain begins at or after ``min_t_s``
    (None if none does)."""
    stop = len(blob) - _REC.size + 1 if stop is None else min(stop, len(blob) - _REC.size + 1)
    for pos in range(start, stop):
        if blob[pos] in (DATA, EVENT) and _record_end(blob, pos, min_t_s) is not None:
            return pos
    return None


def read_serlog_header(path: str | os.PathLike) -> dict:
    """Read only the JSON header of a ``.serlog`` (device, protocol, port...), not its records.

    Raises
    ------
    SessionFormatError
        If the file does not start with the serlog magic or its header is not a JSON object.
    """
    path = _check_file(path)
    with open(path, "rb") as fh:
        magic = fh.read(len(MAGIC))
        line = fh.readline(1 << 20)
    if magic != MAGIC:
        raise SessionFormatError(f"{path}: expected a .serlog file starting with {MAGIC!r}, found {magic!r}")
    try:
        header = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        header = None
    if not isinstance(header, dict):
        raise SessionFormatError(f"{path}: expected a JSON header line after the magic, found none")
    return header


def is_serlog(path: str | os.PathLike) -> bool:
    """True if the file starts with the serlog magic."""
    with open(path, "rb") as fh:
        return fh.read(len(MAGIC)) == MAGIC
