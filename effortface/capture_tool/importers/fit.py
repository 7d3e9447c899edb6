"""Garmin FIT activity files (Garmin, Suunto, Wahoo, Coros, Polar watches and bike computers).

Read with ``fitdecode`` (CRC checked). Samples: the ``record`` messages with a ``heart_rate``
field (1 bpm resolution, usually 1 s or "smart" recording). R-R: the ``hrv`` messages (up to five
intervals in seconds, 1 ms resolution) that follow a record are kept with it. Device: ``file_id``
manufacturer and product; producer: its ``software`` version when a ``device_info`` or
``file_creator`` message gives one. A file with ``lap`` or ``session`` messages and no heart-rate
record is refused as laps only.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

from effortface.capture_tool.importers.recording import HrImportError, HrRecording

#: FIT's "no value" for the hrv message's intervals (65.535 s) and anything above 60 s
_RR_INVALID_S = 60.0


def _value(msg: Any, field: str) -> Any:
    return msg.get_value(field, fallback=None)


def _product(msg: Any) -> str:
    man = _value(msg, "manufacturer")
    prod = _value(msg, "garmin_product") or _value(msg, "product")
    return " ".join(str(x) for x in (man, prod) if x is not None)


def read_fit(path: Path) -> HrRecording:
    """Read a FIT file's heart-rate records and R-R intervals.

    Raises
    ------
    HrImportError
        Not a FIT file, or damaged (one line naming the file and what fitdecode found).
    """
    import fitdecode  # lazy: only FIT import needs it

    rec = HrRecording(path, "fit")
    try:
        with fitdecode.FitReader(str(path)) as reader:
            for frame in reader:
                if isinstance(frame, fitdecode.FitDataMessage):
                    _take(rec, frame)
    except fitdecode.FitError as exc:
        raise HrImportError(f"{path}: expected a FIT file, found {type(exc).__name__}: {str(exc)[:160]}") from None
    if rec.t_s:
        rec.start_utc = dt.datetime.fromtimestamp(rec.t_s[0], dt.timezone.utc)
    return rec


def _take(rec: HrRecording, msg: Any) -> None:
    """Add what one data message says to ``rec``."""
    if msg.name == "file_id" and not rec.device:
        rec.device = _product(msg)
    elif msg.name in ("file_creator", "device_info") and not rec.producer:
        software = _value(msg, "software_version")
        if software is not None and (msg.name == "file_creator" or _value(msg, "device_index") in (0, "creator")):
            rec.producer = f"{rec.device} software {software}".strip()
    elif msg.name in ("lap", "session"):
        rec.laps += msg.name == "lap"
    elif msg.name == "record":
        stamp, hr = _value(msg, "timestamp"), _value(msg, "heart_rate")
        if isinstance(stamp, dt.datetime) and hr is not None:
            rec.add(stamp.timestamp(), float(hr))
    elif msg.name == "hrv" and rec.t_s:
        times = _value(msg, "time") or ()
        rr = tuple(round(float(s) * 1000.0, 3) for s in (times if isinstance(times, (tuple, list)) else (times,))
                   if s is not None and float(s) < _RR_INVALID_S)
        rec.rr_ms[-1] = rec.rr_ms[-1] + rr
