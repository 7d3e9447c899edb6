"""Polar HRM files (Polar Precision Performance, ProTrainer; S-series, CS, RS watches).

``[Params]`` gives ``Monitor=`` (the watch, :data:`MONITORS`), ``Version=``, ``Date=YYYYMMDD``,
``StartTime=HH:MM:SS.s`` (the watch's local time, no zone) and ``Interval=`` (seconds between
samples; ``238`` means R-R mode). ``[HRData]``: one row per sample, heart rate (bpm) first, other
columns after it as ``SMode`` says; in R-R mode each row is one R-R interval in ms (1 ms resolution),
the beat's time the sum of the intervals before it. A rate of 0 is a sample without contact (kept,
marked not valid). ``[IntTimes]`` rows are laps.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from effortface.capture_tool.importers.recording import HrImportError, HrRecording

#: HRM ``Monitor=`` codes (Polar's HRM format description)
MONITORS = {1: "Polar Sport Tester / Vantage XL", 2: "Polar Vantage NV", 3: "Polar Accurex Plus",
            4: "Polar XTrainer Plus", 6: "Polar S520", 7: "Polar Coach", 8: "Polar S210", 9: "Polar S410",
            10: "Polar S510", 11: "Polar S610 / S610i", 12: "Polar S710 / S710i / S720i",
            13: "Polar S810 / S810i", 15: "Polar E600", 20: "Polar AXN500", 21: "Polar AXN700",
            22: "Polar S625X / S725X", 23: "Polar S725", 33: "Polar CS400", 34: "Polar CS600X",
            35: "Polar CS600", 36: "Polar RS400", 37: "Polar RS800", 38: "Polar RS800X"}
#: ``Interval=`` value of a file of R-R intervals
RR_MODE = 238


def sections(path: Path) -> dict[str, list[str]]:
    """``{section: lines}`` of an HRM file (lines stripped, blank ones dropped)."""
    try:
        text = path.read_text(encoding="latin-1")
    except OSError as exc:
        raise HrImportError(f"{path}: expected a readable file, found {exc.strerror}") from None
    out: dict[str, list[str]] = {}
    current = None
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("[") and line.endswith("]"):
            current = line[1:-1]
            out.setdefault(current, [])
        elif line and current is not None:
            out[current].append(line)
    return out


def _params(path: Path, lines: list[str]) -> dict[str, str]:
    params = dict(line.split("=", 1) for line in lines if "=" in line)
    missing = [k for k in ("Date", "StartTime", "Interval") if k not in params]
    if missing:
        raise HrImportError(f"{path}: HRM: expected {', '.join(missing)} in [Params], found {sorted(params)[:8]}")
    return params


def _start(path: Path, params: dict[str, str]) -> dt.datetime:
    try:
        day = dt.datetime.strptime(params["Date"].strip(), "%Y%m%d")
        hms = params["StartTime"].strip().split(":")
        return day + dt.timedelta(hours=int(hms[0]), minutes=int(hms[1]), seconds=float(hms[2]))
    except (ValueError, IndexError):
        raise HrImportError(f"{path}: HRM: expected Date=YYYYMMDD and StartTime=HH:MM:SS.s, found "
                            f"{params['Date']!r} and {params['StartTime']!r}") from None


def read_hrm(path: Path) -> HrRecording:
    """Read a Polar HRM file (per-sample or R-R mode).

    The times are the watch's local time (``start_utc`` is naive: its zone is unknown).
    """
    parts = sections(path)
    if "Params" not in parts or "HRData" not in parts:
        raise HrImportError(f"{path}: expected a Polar HRM file ([Params] and [HRData]), found sections "
                            f"{sorted(parts)[:6]}")
    params = _params(path, parts["Params"])
    monitor = params.get("Monitor", "").strip()
    device = MONITORS.get(int(monitor), f"Polar monitor {monitor}") if monitor.isdigit() else "Polar"
    rec = HrRecording(path, "hrm", device=device, producer=f"Polar HRM version {params.get('Version', '?').strip()}",
                      laps=sum(1 for line in parts.get("IntTimes", []) if ":" in line))
    start = _start(path, params)
    try:
        interval = float(params["Interval"])
        first = [float(line.split()[0]) for line in parts["HRData"]]
    except ValueError:
        raise HrImportError(f"{path}: HRM: expected numbers in Interval= and [HRData], found "
                            f"{params['Interval']!r} and {parts['HRData'][:2]}") from None
    if interval == RR_MODE:
        t = 0.0
        for rr in first:
            t += rr / 1000.0
            rec.add(t, None, (rr,))
    else:
        for k, hr in enumerate(first):
            rec.add(k * interval, hr if hr > 0 else float("nan"))
    rec.start_utc = start + dt.timedelta(seconds=rec.t_s[0] if rec.t_s else 0.0)
    return rec
