"""CSV and TSV heart-rate tables (phone apps such as Polar Sensor Logger, Elite HRV, HRV Logger).

The separator is found from the header line (``,``, ``;`` or tab). Columns are found by header,
letters and digits only, lower case: the time (``time``, ``timestamp``, ``Phone timestamp``,
``t_s``...: seconds, or ISO 8601 date-times), heart rate (``HR``, ``HR [bpm]``, ``heart rate``,
``bpm``...) and R-R intervals (``RR``, ``RR-interval [ms]``, ``IBI``...; in ms, or in s when the
header says ``[s]`` or the values are all below 3). ``--time-col``, ``--hr-col`` and ``--rr-col``
name a column when the header is ambiguous. A table of R-R intervals without a time column gets its
beats' times from the sum of the intervals.

A number in the time column is seconds from the start, unless it is a Unix time: 1e9 to 1e11 is
epoch seconds, 1e11 to 1e14 epoch milliseconds (HRV Logger's ``timestamp``); the start is then
absolute, UTC. An ISO 8601 time with a zone (``Z``, ``+02:00``) is absolute; one without (Polar Sensor
Logger's ``Phone timestamp``) is the phone's local time, its zone unknown.
"""

from __future__ import annotations

import csv
import datetime as dt
import math
import re
from pathlib import Path

from effortface.capture_tool.importers.recording import HrImportError, HrRecording
from effortface.capture_tool.importers.xml_tracks import parse_time
from effortface.core.errors import not_text_error

#: header keys (letters and digits only, lower case) that say heart rate ...
HR_KEYS = frozenset({"hr", "hrbpm", "heartrate", "heartratebpm", "bpm", "pulse", "pulserate", "hrbeatsmin"})
#: ... R-R intervals ...
RR_KEYS = frozenset({"rr", "rrms", "rrs", "rrinterval", "rrintervalms", "rrintervals", "rrintervalsms",
                     "rrintervalss", "ibi", "ibims", "ibis", "interbeatinterval", "nn", "nnms", "rri"})
#: ... and the time
TIME_KEYS = frozenset({"time", "times", "timestamp", "phonetimestamp", "ts", "t", "datetime", "date",
                       "elapsedtime", "elapsed", "seconds", "secs", "sec"})
#: a number in the time column from EPOCH_S[0] to EPOCH_S[1] is Unix seconds, from EPOCH_MS[0] to
#: EPOCH_MS[1] Unix milliseconds (2001-5138); below, seconds from the start (at most 11.6 days)
EPOCH_S = (1e9, 1e11)
EPOCH_MS = (1e11, 1e14)
#: an ISO 8601 time that names its zone
ZONED = re.compile(r"\d:\d\d(?::\d\d(?:[.,]\d+)?)?\s*(?:[Zz]|[+-]\d\d(?::?\d\d)?)$")


def key(text: str) -> str:
    """``HR [bpm]`` -> ``hrbpm``: lower case, letters and digits only."""
    return re.sub(r"[^a-z0-9]", "", text.lower())


def _find(path: Path, header: list[str], given: str | None, keys: frozenset[str], option: str,
          extra: tuple[str, ...] = ()) -> int | None:
    """Index of the column named ``given`` (exactly or by key), else the one column whose key says it."""
    keyed = [key(h) for h in header]
    if given is not None:
        for i, (h, k) in enumerate(zip(header, keyed)):
            if given in (h, h.strip()) or key(given) == k:
                return i
        raise HrImportError(f"{path}: {option} {given}: expected one of the columns {header}, found none")
    found = [i for i, k in enumerate(keyed) if k in keys or any(k.startswith(p) for p in extra)]
    if len(found) > 1:
        raise HrImportError(f"{path}: expected one {option[2:-4]} column, found {[header[i] for i in found]} "
                            f"(choose one with {option})")
    return found[0] if found else None


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise HrImportError(f"{path}: expected a text table (CSV or TSV), found {type(exc).__name__}") from None
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        raise HrImportError(f"{path}: expected a table with a header line, found an empty file")
    sep = max(("\t", ";", ","), key=lines[0].count)
    try:
        table = list(csv.reader(lines, delimiter=sep))
    except csv.Error as exc:  # a field over the csv module's limit
        raise HrImportError(str(not_text_error(path, exc))) from None
    header = [h.strip() for h in table[0]]
    return header, table[1:]


def read_table(path: Path, *, time_col: str | None = None, hr_col: str | None = None,
               rr_col: str | None = None) -> HrRecording:
    """Read a CSV/TSV table of heart rate and/or R-R intervals found by header.

    Raises
    ------
    HrImportError
        No heart-rate or R-R column, an ambiguous one, or a cell that is not a number or a time.
    """
    header, rows = _rows(path)
    t_i = _find(path, header, time_col, TIME_KEYS, "--time-col", ("time", "timestamp"))
    hr_i = _find(path, header, hr_col, HR_KEYS, "--hr-col", ("hrbpm", "heartrate"))
    rr_i = _find(path, header, rr_col, RR_KEYS, "--rr-col", ("rrinterval", "ibi"))
    if hr_i is None and rr_i is None:
        raise HrImportError(f"{path}: expected a heart-rate column (HR, HR [bpm], heart rate) or an R-R column "
                            f"(RR, RR-interval [ms], IBI) in the header, found {header} (name one with --hr-col "
                            "or --rr-col)")
    rec = HrRecording(path, "csv", device=path.stem, producer="")
    rr_to_ms = _rr_factor(header[rr_i], [r[rr_i] for r in rows if rr_i < len(r)]) if rr_i is not None else 1.0
    elapsed = 0.0
    clock = None
    for n, row in enumerate(rows, start=2):
        hr = _number(path, row, hr_i, n, header)
        rr = _number(path, row, rr_i, n, header)
        rr_ms = (rr * rr_to_ms,) if rr is not None and rr > 0 else ()
        if hr is None and not rr_ms:
            continue
        if t_i is None:
            elapsed += (rr_ms[0] / 1000.0) if rr_ms else 0.0
            t = elapsed
        else:
            t, kind = _time(path, row, t_i, n, header)
            clock = kind if clock is None else clock
        rec.add(t, hr, rr_ms)
    if clock in ("utc", "local") and rec.t_s:
        start = dt.datetime.fromtimestamp(rec.t_s[0], dt.timezone.utc)
        rec.start_utc = start if clock == "utc" else start.replace(tzinfo=None)
    return rec


def _rr_factor(name: str, cells: list[str]) -> float:
    """1 for R-R in ms, 1000 in s (the header says ``[s]``/``(s)``, or every value is below 3)."""
    if re.search(r"[\[(]\s*ms\s*[\])]|\bms\b", name.lower()):
        return 1.0
    if re.search(r"[\[(]\s*s(ec)?\s*[\])]", name.lower()):
        return 1000.0
    values = []
    for cell in cells[:200]:
        try:
            values.append(float(cell))
        except ValueError:
            pass
    return 1000.0 if values and max(values) < 3.0 else 1.0


def _number(path: Path, row: list[str], col: int | None, n: int, header: list[str]) -> float | None:
    if col is None or col >= len(row) or not row[col].strip():
        return None
    try:
        value = float(row[col])
    except ValueError:
        raise HrImportError(f"{path}: line {n}: column {header[col]!r}: expected a number, found "
                            f"{row[col][:40]!r}") from None
    return value if math.isfinite(value) else None


def _time(path: Path, row: list[str], col: int, n: int, header: list[str]) -> tuple[float, str]:
    """(seconds, clock) of a time cell; clock ``relative`` (seconds from the start), ``utc`` (a Unix time,
    or an ISO 8601 time with a zone) or ``local`` (an ISO 8601 time without a zone: the phone's own
    time, taken at face value)."""
    cell = row[col].strip() if col < len(row) else ""
    try:
        value = float(cell)
    except ValueError:
        pass
    else:
        if EPOCH_MS[0] <= value < EPOCH_MS[1]:
            return value / 1000.0, "utc"
        return value, "utc" if EPOCH_S[0] <= value < EPOCH_S[1] else "relative"
    try:
        return parse_time(cell).timestamp(), "utc" if ZONED.search(cell) else "local"
    except ValueError:
        raise HrImportError(f"{path}: line {n}: column {header[col]!r}: expected seconds or an ISO 8601 time, "
                            f"found {cell[:40]!r}") from None
