"""Crash-safe file writes shared by every stage (stdlib only, so the runtime may import it).

A write goes to a temporary file in the same folder, is flushed and fsynced, then renamed over the
target with ``os.replace``, and the folder is fsynced so the rename itself survives a power cut: a
reader (or a crash) sees the old file or the new one, never half. A failed write (disk full...) is
an OSError naming the target file; temporary files a killed writer left are removed by the next
write of the same file once they are :data:`STALE_TMP_S` old.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import itertools
import json
import os
import re
import secrets
import stat
import time
import zipfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

from effortface.core.errors import UserError
from effortface.core.stops import stops_deferred

#: a temporary file of an atomic write older than this was left by a killed writer (no write takes so long)
STALE_TMP_S = 300.0


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The SHA-256 of a file's bytes, hex (read in 1 MiB blocks)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def name_os_error(exc: OSError, path: str | os.PathLike[str]) -> OSError:
    """``exc`` naming ``path`` if it names no file (a full disk on a write or a close names none).

    The one place an OS error gets the file it happened on, so the command line's last-resort line
    (``<file>: expected a readable/writable path, found No space left on device``) names it.
    """
    if exc.filename is not None or exc.errno is None:
        return exc
    return type(exc)(exc.errno, exc.strerror, str(path))


@contextlib.contextmanager
def naming(path: str | os.PathLike[str]) -> Iterator[None]:
    """Re-raise an OSError of the block as :func:`name_os_error` of ``path``."""
    try:
        yield
    except OSError as exc:
        named = name_os_error(exc, path)
        if named is exc:
            raise
        raise named from None


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
    tmp = _temp_written(path, write)
    try:
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        raise name_os_error(exc, path) if isinstance(exc, OSError) else exc
    fsync_folder(path.parent)
    return path


def _temp_written(path: Path, write: Callable[[IO[bytes]], Any]) -> Path:
    """A temporary file beside ``path`` holding what ``write`` wrote, fsynced (removed if that fails).

    Raises
    ------
    OSError
        Naming ``path`` (disk full, read-only folder...).
    """
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
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.errno is not None and exc.filename is None:  # ENOSPC...: name it
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        raise
    return tmp


def _writer(content: bytes | str) -> Callable[[IO[bytes]], Any]:
    """A ``write(fh)`` for :func:`atomic_write` of ``content`` (``str`` as UTF-8)."""
    data = content.encode("utf-8") if isinstance(content, str) else content
    return lambda fh: fh.write(data)


def atomic_write_together(contents: Mapping[str | os.PathLike[str], bytes | str]) -> list[Path]:
    """Replace several files together or not at all (a CSV and its sidecar, corrections and ratings).

    Every new content is first written whole to a temporary file beside its target (fsynced); only
    when all are written are they renamed into place, one after the other, with stops deferred
    (:func:`effortface.core.stops.stops_deferred`), so a full disk or a SIGTERM leaves every target
    as it was or every target new. (Renames in one folder do not need space; a rename that still
    fails leaves the files already renamed new.)

    Parameters
    ----------
    contents : mapping
        Target path -> its new content (``str`` is written as UTF-8), in the order to rename them
        (put last the file whose presence says the set is whole).

    Returns
    -------
    list of Path
        The targets.

    Raises
    ------
    OSError
        Naming the target whose write failed; then no target was changed.
    """
    temps: list[tuple[Path, Path]] = []
    try:
        for target, content in contents.items():
            temps.append((_temp_written(Path(target), _writer(content)), Path(target)))
        with stops_deferred():
            for tmp, target in temps:
                with naming(target):
                    os.replace(tmp, target)
    finally:
        for tmp, _ in temps:
            tmp.unlink(missing_ok=True)
    for folder in dict.fromkeys(target.parent for _, target in temps):
        fsync_folder(folder)
    return [target for _, target in temps]


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


def json_text(data: Any) -> str:
    """``data`` as the indented JSON every JSON file of the project is written in."""
    return json.dumps(data, indent=2, sort_keys=False) + "\n"


def write_json_atomic(path: str | os.PathLike[str], data: Any) -> Path:
    """Write ``data`` as indented JSON atomically (see :func:`atomic_write`)."""
    return atomic_write_text(path, json_text(data))


#: the largest JSON file a reader accepts (session, annotation, model and motion index files are kB)
MAX_JSON_BYTES = 64 * 1024 * 1024
#: the deepest nesting a reader accepts (the formats nest 4 levels; Python's parser recurses)
MAX_JSON_DEPTH = 32


def check_regular_file(path: str | os.PathLike[str], what: str = "a regular file",
                       error: type[UserError] = UserError) -> Path:
    """Return ``path`` if it is a regular file, else raise ``error`` naming it and what is there.

    A FIFO or a device (``/dev/zero``) would block or read forever, so readers refuse them first.
    """
    found = not_a_file(path)
    if found is not None:
        raise error(f"{path}: expected {what}, found {found}")
    return Path(path)


def read_json(path: str | os.PathLike[str], what: str = "a JSON file",
              error: type[UserError] = UserError, *, max_bytes: int = MAX_JSON_BYTES) -> Any:
    """Parse a JSON file that was written by a person or a program that may have failed.

    Refuses, with one ``error`` line naming the file: a missing file, a folder, a FIFO or device,
    a file over ``max_bytes``, bytes that are not UTF-8, invalid JSON, and nesting deeper than
    :data:`MAX_JSON_DEPTH` (which would raise RecursionError in the parser or in later code).

    Parameters
    ----------
    path : path-like
        The file.
    what : str
        What it should be, for the message (``"a JSON annotation file"``).
    error : type
        The UserError subclass to raise (``SessionFormatError``, ``BundleFormatError``...).
    max_bytes : int
        Size limit.

    Returns
    -------
    object
        The parsed document (not yet checked for its shape).
    """
    path = check_regular_file(path, what, error)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{path}: expected {what} that can be read, found {exc.strerror or exc}") from None
    if len(raw) > max_bytes:
        raise error(f"{path}: expected {what} of at most {max_bytes} bytes, found a larger file")
    depth = _json_depth(raw)
    if depth > MAX_JSON_DEPTH:
        raise error(f"{path}: expected JSON nested at most {MAX_JSON_DEPTH} levels, found {depth}")
    try:
        return json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise error(f"{path}: expected {what} in UTF-8, found byte {raw[exc.start]:#04x} (a binary file?)") from None
    except (ValueError, RecursionError) as exc:
        raise error(f"{path}: expected {what}, found invalid JSON ({exc})") from None


def _json_depth(raw: bytes) -> int:
    """Deepest bracket nesting of JSON bytes outside strings (no recursion, linear time)."""
    brackets = _JSON_STRING.sub(b"", raw).translate(None, _NOT_BRACKET)
    steps = (1 if b in b"[{" else -1 for b in brackets)
    return max(itertools.accumulate(steps, initial=0))


_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)
_NOT_BRACKET = bytes(b for b in range(256) if b not in b"[]{}")


def check_apart(option: str, out: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str] | None],
                what: str = "an output") -> Path:
    """Refuse an output path that is, holds or lies inside one of the inputs; return it as a Path.

    The one rule of every writer, so that ``--force`` can never destroy an input. Paths are compared
    both as given (made absolute) and resolved through symbolic links, and a folder input's entries
    that are symbolic links (a session reached through a link) count as inputs too.

    Parameters
    ----------
    option : str
        The output option, for the message (``"--out"``).
    out : path-like
        The output file or folder (need not exist).
    inputs : iterable of path-like or None
        The files and folders the command reads (None entries are skipped).
    what : str
        What the output is, for the message (``"a model folder"``).

    Raises
    ------
    UserError
        One line naming the option, the output and the input it would overwrite.
    """
    out = Path(out)
    targets = {Path(os.path.abspath(out)), out.resolve()}
    for src in (Path(s) for s in inputs if s is not None):
        for form in _input_forms(src):
            for target in targets:
                if form == target or target in form.parents or form in target.parents:
                    where = "" if form == target else " inside it" if target in form.parents else " around it"
                    link = "" if form == Path(os.path.abspath(src)) else f" (through a link, at {form})"
                    raise UserError(f"{option} {out}: expected {what} apart from the inputs, found input "
                                    f"{src}{where}{link}")
    return out


def _input_forms(src: Path) -> set[Path]:
    """``src`` as given (absolute) and resolved, plus the resolved targets of links directly inside it."""
    forms = {Path(os.path.abspath(src)), src.resolve()}
    if src.is_dir():
        try:
            forms |= {entry.resolve() for entry in src.iterdir() if entry.is_symlink()}
        except OSError:
            pass  # an unreadable folder: the reader will say so
    return forms


def check_zip_sizes(path: Path, error: type[UserError], max_bytes: int, what: str) -> list[zipfile.ZipInfo]:
    """Refuse a zip bomb before anything is inflated: the members' uncompressed sizes (as the archive
    declares them, which :mod:`zipfile` holds each member to) summed over ``max_bytes``.

    Parameters
    ----------
    path : Path
        The archive (``.npz``, a Face Landmarker ``.task``...).
    error : type
        The UserError subclass to raise.
    max_bytes : int
        The most the content may take once uncompressed.
    what : str
        What the content is, for the message (``"arrays"``, ``"models"``).

    Returns
    -------
    list of zipfile.ZipInfo
        The members.

    Raises
    ------
    UserError
        Of type ``error``, naming the file, the limit and the size found.
    zipfile.BadZipFile, OSError
        When the file is not a zip (the caller names it).
    """
    with zipfile.ZipFile(path) as zf:
        infos = zf.infolist()
    total = 0
    for info in infos:
        total += info.file_size
        if total > max_bytes:
            raise error(f"{path}: expected at most {max_bytes} bytes of {what}, found {total} or more once "
                        "uncompressed")
    return infos
