"""The ``.serlog`` format: every raw byte received from a device, with its host arrival time.

Layout (little-endian)::

    b"EFSERLOG 1\\n"                       magic and format version
    <one line of UTF-8 JSON>\\n             header: device, protocol, port, settings, created_utc
    records, each:  kind:uint8  t_s:float64  n:uint32  payload[n]

``kind`` 0 is data (the bytes of one read), 1 is a link event (payload: UTF-8 JSON ``{"kind",
"label", "value"}``, e.g. a gap or a reconnect). ``t_s`` is seconds on the session's monotonic
clock. Records are appended and flushed as they arrive, so a file cut by a crash is readable: a
truncated last record is ignored and counted by :func:`read_serlog`.
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

from effortface.core.errors import SessionFormatError
from effortface.core.fileio import not_a_file

MAGIC = b"EFSERLOG 1\n"
DATA, EVENT = 0, 1
_REC = struct.Struct("<BdI")
_MAX_PAYLOAD = 1 << 24  # 16 MiB: larger is a corrupt length, not a read


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
    """Read a ``.serlog`` file, tolerating a truncated last record.

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
    records, pos = _parse_records(blob, nl + 1)
    return Serlog(path, header, records, truncated_bytes=len(blob) - pos)


def _parse_records(blob: bytes, pos: int) -> tuple[list[SerlogRecord], int]:
    """Parse records from ``pos``; stop at the first incomplete or corrupt one."""
    records: list[SerlogRecord] = []
    while pos + _REC.size <= len(blob):
        kind, t_s, n = _REC.unpack_from(blob, pos)
        end = pos + _REC.size + n
        if kind not in (DATA, EVENT) or n > _MAX_PAYLOAD or end > len(blob):
            break
        records.append(SerlogRecord(kind, t_s, blob[pos + _REC.size:end]))
        pos = end
    return records, pos


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
