"""The ``heart_rate.csv`` row format: ``t_s,hr_bpm,rr_ms,beat_count,device,valid``.

One row per :class:`~effortface.capture_tool.protocols.HrSample`. ``rr_ms`` holds the sample's R-R intervals
joined by one space (empty if none); ``hr_bpm`` is empty when the sample is invalid (contact loss is
``valid=0``, never 0 bpm); ``beat_count`` is empty when the strap has no beat counter.
Shared by ``effortface decode`` and the recorder.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

from effortface.core import bounds
from effortface.core.errors import SessionFormatError, not_text_error
from effortface.core.fileio import check_regular_file
from effortface.core.hr_sample import HrSample

HR_CSV_COLUMNS = ("t_s", "hr_bpm", "rr_ms", "beat_count", "device", "valid")
HR_CSV_HEADER = ",".join(HR_CSV_COLUMNS)


def _num(x: float) -> str:
    """Shortest exact text of a number: ``72`` for 72.0, ``920.9`` for 920.9."""
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def format_hr_row(s: HrSample) -> str:
    """Format one sample as a CSV row (no newline).

    Parameters
    ----------
    s : HrSample
        The sample.

    Returns
    -------
    str
        ``t_s`` with 4 decimals, then ``hr_bpm`` (empty if None), ``rr_ms`` (space-joined),
        ``beat_count`` (empty if None), ``device`` and ``valid`` (0/1).
    """
    hr = "" if s.hr_bpm is None else _num(s.hr_bpm)
    rr = " ".join(_num(r) for r in s.rr_ms)
    beat = "" if s.beat_count is None else str(s.beat_count)
    device = s.device.replace(",", ";")  # a device id never carries the separator
    return f"{s.t_s:.4f},{hr},{rr},{beat},{device},{int(bool(s.valid))}"


def _parse_row(row: dict[str, str]) -> HrSample:
    """One csv.DictReader row -> HrSample (ValueError on a bad field)."""
    hr = row["hr_bpm"].strip()
    beat = row["beat_count"].strip()
    return HrSample(
        t_s=bounds.check("t_s", float(row["t_s"])),
        hr_bpm=float(hr) if hr else None,
        rr_ms=tuple(float(r) for r in row["rr_ms"].split()),
        beat_count=int(beat) if beat else None,
        device=row["device"],
        valid=row["valid"].strip() == "1",
    )


def read_hr_csv(path: str | os.PathLike) -> list[HrSample]:
    """Read a ``heart_rate.csv`` written with :func:`format_hr_row`.

    Parameters
    ----------
    path : path-like
        The CSV file (header ``t_s,hr_bpm,rr_ms,beat_count,device,valid``).

    Returns
    -------
    list of HrSample

    Raises
    ------
    SessionFormatError
        If the file is a folder or not UTF-8 CSV text, the header differs or a row cannot be
        parsed (the message names the file and line).
    """
    path = check_regular_file(path, "a heart-rate CSV file", SessionFormatError)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return _read_rows(csv.DictReader(fh), path)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise not_text_error(path, exc) from None


def _read_rows(reader: csv.DictReader, path: Path) -> list[HrSample]:
    """Check the header of ``reader`` (reading ``path``) and parse its rows."""
    if tuple(reader.fieldnames or ()) != HR_CSV_COLUMNS:
        raise SessionFormatError(
            f"{path}: expected header {HR_CSV_HEADER!r}, found {','.join(reader.fieldnames or [])!r}"
        )
    out: list[HrSample] = []
    for row in reader:
        try:
            out.append(_parse_row(row))
        except (ValueError, TypeError, AttributeError) as exc:
            raise SessionFormatError(
                f"{path}: line {reader.line_num}: expected a heart-rate row, found {row!r} ({exc})"
            ) from None
    return out
