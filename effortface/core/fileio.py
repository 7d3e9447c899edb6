"""Crash-safe file writes shared by every stage (stdlib only, so the runtime may import it).

A write goes to a temporary file in the same folder, is flushed and fsynced, then renamed over the
target with ``os.replace``, and the folder is fsynced so the rename itself survives a power cut: a
reader (or a crash) sees the old file or the new one, never half. A failed write (disk full...) is
an OSError naming the target file; temporary files a killed writer left are removed by the next
write of the same file once they are :data:`STALE_TMP_S` old.
"""

from __future__ import annotations

import errno
import json
import os
import secrets
import stat
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from effortface.core.errors import UserError

#: a temporary file of an atomic write older than this was left by a killed writer (no write takes so long)
STALE_TMP_S = 300.0


def refuse_overwrite(path: str | os.PathLike[str], *, overwrite: bool = False, what: str = "file",
                     hint: str = "") -> Path:
    """Return ``path`` as a Path, or refuse if it exists and ``overwrite`` is False.

    Parameters
    ----------
    path : path-like
        The file or folder about to be written.
    overwrite : bool
        True when the user asked to replace it.
    what : str
        What the path is, for the message (``"file"``, ``"model folder"``...).
    hint : str
        Appended to the message, e.g. ``" (use --force)"``.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: {what} exists; refusing to overwrite{hint}")
    return path


def not_a_file(path: str | os.PathLike[str]) -> str | None:
    """None if ``path`` is an existing regular file, else what is there, for a refusal message.

    Returns
    -------
    str or None
        ``"nothing (no such file)"``, ``"a folder"`` or ``"a special file (FIFO, device or socket)"``
        (which would block or read forever).
    """
    path = Path(path)
    if path.is_file():
        return None
    if not path.exists():
        return "nothing (no such file)"
    return "a folder" if path.is_dir() else "a special file (FIFO, device or socket)"


def check_new_png(option: str, value: str | os.PathLike[str]) -> Path:
    """A new ``.png`` path in an existing writable folder, for an option such as ``--plot``.

    Checked before any work is done, so a bad path costs nothing.

    Parameters
    ----------
    option : str
        The option's name, for the message (``"--plot"``, ``"--screenshot"``).
    value : path-like
        The path given.

    Returns
    -------
    Path

    Raises
    ------
    UserError
        One line naming the option and the path: not ``.png``, a folder, an existing file (never
        overwritten), a missing or read-only folder.
    """
    path = Path(value)
    if path.suffix.lower() != ".png":
        raise UserError(f"{option} {value}: expected a path ending in .png, found {path.suffix or 'no suffix'!r}")
    if path.is_dir():
        raise UserError(f"{option} {value}: expected a new PNG file, found a folder")
    if path.exists() or path.is_symlink():
        raise UserError(f"{option} {value}: expected a new file, found one exists (not overwritten)")
    folder = path.parent
    if not folder.is_dir():
        raise UserError(f"{option} {value}: expected an existing folder for the PNG, found "
                        f"{'a file' if folder.exists() else 'nothing'} at {str(folder)!r}")
    if not os.access(folder, os.W_OK):
        raise UserError(f"{option} {value}: expected a writable folder, found {str(folder)!r} read-only")
    return path


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO[bytes]], Any]) -> Path:
    """Call ``write(fh)`` on a temp file beside ``path``, fsync it, rename it over ``path``, fsync the folder.

    The new file's mode is what ``open(path, "w")`` would give: an existing file keeps its mode, a new
    one gets 0666 minus the umask (0644 under the usual umask 022), so that colleagues on a shared lab
    drive can read it (see :func:`_create_temp_beside`).

    Parameters
    ----------
    path : path-like
        Target file; its folder must exist.
    write : callable
        Writes the content to the binary file object it is given.

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    OSError
        If the file cannot be written (disk full, read-only...): its ``filename`` is ``path``,
        and the previous file, if any, is left as it was.
    """
    path = Path(path)
    remove_stale_temps(path)
    try:
        fd, tmp = _create_temp_beside(path)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    try:
        _keep_mode(fd, tmp, path)
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.errno is not None and exc.filename is None:  # ENOSPC...: name it
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise
    fsync_folder(path.parent)
    return path


#: fresh random names tried for a temporary file before giving up (a clash is already unlikely)
_TEMP_NAME_ATTEMPTS = 100


def _create_temp_beside(path: Path) -> tuple[int, Path]:
    """Create a new, empty temporary file beside ``path``; return its descriptor and path.

    Created with ``O_CREAT | O_EXCL`` and mode 0666, so the kernel applies the umask as for any
    new file. (``tempfile.mkstemp`` always gives 0600, and reading the umask to fix that afterwards
    is not thread-safe: ``os.umask`` can only be read by setting it.)
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0) | getattr(os, "O_NOFOLLOW", 0)
    for _ in range(_TEMP_NAME_ATTEMPTS):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temporary name after {_TEMP_NAME_ATTEMPTS} tries",
                          str(path.parent))


def _keep_mode(fd: int, tmp: Path, path: Path) -> None:
    """Give the temporary file the permission bits of the file it replaces, if there is one."""
    try:
        mode = stat.S_IMODE(path.stat().st_mode)
    except (FileNotFoundError, NotADirectoryError):
        return
    if hasattr(os, "fchmod"):
        os.fchmod(fd, mode)
    else:  # pragma: no cover - Windows has no fchmod
        os.chmod(tmp, mode)


def fsync_folder(folder: str | os.PathLike[str]) -> None:
    """fsync a folder so the renames and creations in it survive a power cut (no-op where unsupported)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot fsync a folder; the rename is still atomic
    finally:
        os.close(fd)


def remove_stale_temps(path: str | os.PathLike[str], min_age_s: float = STALE_TMP_S) -> list[Path]:
    """Remove the temporary files of atomic writes of ``path`` that are ``min_age_s`` old or older.

    Parameters
    ----------
    path : path-like
        The target file whose ``.<name>.*.tmp`` siblings are looked at.
    min_age_s : float
        Younger temporary files may belong to a write under way and are kept.

    Returns
    -------
    list of Path
        The files removed.
    """
    path = Path(path)
    now = time.time()
    gone = []
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        try:
            if now - tmp.stat().st_mtime >= min_age_s:
                tmp.unlink()
                gone.append(tmp)
        except OSError:
            continue
    return gone


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 ``text`` atomically (see :func:`atomic_write`)."""
    data = text.encode("utf-8")
    return atomic_write(path, lambda fh: fh.write(data))


def write_json_atomic(path: str | os.PathLike[str], data: Any) -> Path:
    """Write ``data`` as indented JSON atomically (see :func:`atomic_write`)."""
    return atomic_write_text(path, json.dumps(data, indent=2, sort_keys=False) + "\n")
