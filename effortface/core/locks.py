"""Advisory locks with a visible owner: one writer of a session folder or a file at a time.

A lock is a small file (e.g. ``<session>/.recording.lock``) held with ``fcntl.flock`` by the
process that writes, and holding one JSON line that says who: ``pid``, ``host``, ``started_utc``
and ``what``. The kernel releases a ``flock`` when its process dies, even by ``kill -9``, so a
lock file left by a killed process is stale: it blocks nothing and the next holder takes it over.
Other programs ask :func:`lock_owner` before touching what the lock guards. Stdlib only.
"""

from __future__ import annotations

import datetime as _dt
import errno
import json
import os
import socket
from pathlib import Path
from typing import Any

from effortface.core.errors import UserError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no advisory locks, every lock is free
    fcntl = None  # type: ignore[assignment]


class LockedError(UserError):
    """What a lock guards is in use by another program (the message names it and its owner)."""


def describe_owner(owner: dict[str, Any]) -> str:
    """``pid 123 on host lab-pc since 2026-01-01T10:00:00Z (capture)``, for messages."""
    what = f" ({owner['what']})" if owner.get("what") else ""
    return (f"pid {owner.get('pid', '?')} on {owner.get('host', '?')} "
            f"since {owner.get('started_utc', '?')}{what}")


class FileLock:
    """An acquired lock; :meth:`release` (or leaving a ``with`` block) frees it and removes the file.

    Use :func:`acquire_lock` to get one.
    """

    def __init__(self, path: Path, fd: int, owner: dict[str, Any]) -> None:
        self.path = path
        self.owner = owner
        self._fd: int | None = fd

    def release(self) -> None:
        """Remove the lock file, then free the lock (idempotent)."""
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self._fd)  # closing the descriptor frees the flock
            self._fd = None

    def __enter__(self) -> FileLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _try_flock(fd: int, exclusive: bool) -> bool:
    """Take the flock on ``fd`` without waiting; False if another open file holds it."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return False
        raise
    return True


def _read_owner(path: Path) -> dict[str, Any]:
    """The owner line of a held lock file ({} if it is being written or unreadable)."""
    try:
        owner = json.loads(path.read_text(encoding="utf-8") or "{}")
    except (OSError, ValueError):
        return {}
    return owner if isinstance(owner, dict) else {}


def lock_owner(path: str | os.PathLike) -> dict[str, Any] | None:
    """Who holds the lock file ``path``, or None if nobody does (no file, or a stale one).

    Parameters
    ----------
    path : path-like
        The lock file.

    Returns
    -------
    dict or None
        ``{"pid", "host", "started_utc", "what"}`` of the holder (possibly partial).
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        if _try_flock(fd, exclusive=False):
            return None
        return _read_owner(path) or {"pid": "?"}
    finally:
        os.close(fd)


def acquire_lock(path: str | os.PathLike, what: str) -> FileLock:
    """Take the lock file ``path`` (created if needed; a stale one is taken over).

    Parameters
    ----------
    path : path-like
        The lock file; its folder must exist.
    what : str
        What the holder does, written in the owner line (``"capture"``...).

    Returns
    -------
    FileLock

    Raises
    ------
    LockedError
        If another process (or another open in this one) holds it; the message names its owner.
    """
    path = Path(path)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        if not _try_flock(fd, exclusive=True):
            os.close(fd)
            owner = _read_owner(path) or {"pid": "?"}
            raise LockedError(f"{path}: expected no other program at work, found {describe_owner(owner)}")
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:  # not a file its last holder removed between our open and our lock
            break
        os.close(fd)
    owner = {"pid": os.getpid(), "host": socket.gethostname(),
             "started_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"), "what": what}
    os.ftruncate(fd, 0)
    os.pwrite(fd, (json.dumps(owner) + "\n").encode("utf-8"), 0)
    return FileLock(path, fd, owner)
