"""Error types shared by every stage.

A :class:`UserError` is an expected failure caused by the user's input (a bad file, a bad option,
a missing device). The command line prints its message as one line and exits with status 2.
"""

from __future__ import annotations

import csv
import enum


class UserError(ValueError):
    """A user-facing error: the message names the thing, what was expected and what was found."""


class SessionFormatError(UserError):
    """A session folder or one of its files does not follow the session format."""


def not_text_error(path: object, exc: UnicodeDecodeError | csv.Error, line: int | None = None) -> SessionFormatError:
    """The SessionFormatError for a file that should be UTF-8 CSV text but is not.

    Parameters
    ----------
    path : path-like
        The file, named in the message.
    exc : UnicodeDecodeError or csv.Error
        What reading it raised (a csv.Error also for a field over the csv module's size limit).
    line : int, optional
        The line being read (the csv reader's ``line_num``), named when given.

    Returns
    -------
    SessionFormatError
    """
    where = f"{path}: line {line}" if line else f"{path}"
    if isinstance(exc, UnicodeDecodeError):
        return SessionFormatError(f"{where}: expected UTF-8 text, found byte {exc.object[exc.start]:#04x} "
                                  "that is not UTF-8 (a binary file?)")
    if "field larger than field limit" in str(exc):
        return SessionFormatError(f"{where}: expected CSV fields of at most {csv.field_size_limit()} characters, "
                                  "found a longer one (a binary file, or a quote never closed?)")
    return SessionFormatError(f"{where}: expected CSV text, found unreadable CSV ({exc})")


def json_type(value: object) -> str:
    """The JSON name of a parsed value's type and the value (``object {...}``, ``string 'x'``), for
    messages; at most 80 characters."""
    names = {dict: "object", list: "array", str: "string", bool: "boolean", int: "number", float: "number"}
    return "null" if value is None else f"{names.get(type(value), type(value).__name__)} {value!r}"[:80]


class DeviceErrorReason(enum.Enum):
    """Machine-readable reason for a device failure, so a GUI can suggest a fix."""

    NOT_FOUND = "not found"
    BUSY = "busy"
    PERMISSION = "permission denied"
    TIMEOUT = "timeout"
    NO_KEY = "no network key"
    OTHER = "other"


class DeviceError(UserError):
    """A device (serial port, camera, ANT stick) could not be opened or used.

    Parameters
    ----------
    message : str
        One line naming the device, what was expected and what was found.
    reason : DeviceErrorReason
        Machine-readable cause.
    """

    def __init__(self, message: str, reason: DeviceErrorReason = DeviceErrorReason.OTHER) -> None:
        super().__init__(message)
        self.reason = reason
