"""XML track files: Garmin TCX, GPX with the Garmin TrackPointExtension, and Peaksware/Timex PWX.

* TCX: every ``Trackpoint`` with a ``Time`` and a ``HeartRateBpm/Value`` (1 bpm resolution); the
  device is ``Activity/Creator/Name`` (with its ``Version``), the producer ``Author/Name``; ``Lap``
  elements are counted (a file of laps with no heart-rate trackpoint is refused).
* GPX: every ``trkpt`` with a ``time`` and an ``hr`` inside its ``extensions`` (Garmin
  TrackPointExtension v1 or v2, or any extension naming ``hr``/``heartrate``); the device is the
  ``creator`` attribute.
* PWX: ``workout/time`` is the start, every ``sample`` has a ``timeoffset`` (s) and an ``hr``;
  device ``workout/device/make`` + ``model``, producer the ``creator`` attribute; ``segment``
  summaries are the laps.

Elements are matched by their local name, whatever namespace prefix the file uses.
"""

from __future__ import annotations

import datetime as dt
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

from effortface.capture_tool.importers.recording import HrImportError, HrRecording

_FRACTION = re.compile(r"\.(\d+)")


def local(tag: str) -> str:
    """``{namespace}Name`` -> ``Name``."""
    return tag.rsplit("}", 1)[-1]


def parse_time(text: str) -> dt.datetime:
    """An ISO 8601 time (``Z`` or an offset; none is UTC; any number of fraction digits) as aware UTC.

    Raises
    ------
    ValueError
        Not such a time.
    """
    text = text.strip().replace("Z", "+00:00").replace("z", "+00:00")
    text = _FRACTION.sub(lambda m: "." + (m.group(1) + "000000")[:6], text, count=1)
    when = dt.datetime.fromisoformat(text)
    return when.replace(tzinfo=dt.timezone.utc) if when.tzinfo is None else when.astimezone(dt.timezone.utc)


def _children(elem: ET.Element, name: str) -> Iterator[ET.Element]:
    return (c for c in elem if local(c.tag) == name)


def _child(elem: ET.Element, name: str) -> ET.Element | None:
    return next(_children(elem, name), None)


def _text(elem: ET.Element | None, *path: str) -> str | None:
    for name in path:
        if elem is None:
            return None
        elem = _child(elem, name)
    return None if elem is None or elem.text is None else elem.text.strip()


def load_xml(path: Path, kind: str) -> ET.Element:
    """The root element, or one line saying the file is not XML."""
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise HrImportError(f"{path}: expected a {kind.upper()} (XML) file, found an XML error: {exc}") from None


def _float(path: Path, text: str | None, what: str) -> float | None:
    if text is None or text == "":
        return None
    try:
        return float(text)
    except ValueError:
        raise HrImportError(f"{path}: expected a number for {what}, found {text[:40]!r}") from None


def _time(path: Path, text: str | None, what: str) -> float:
    try:
        return parse_time(text or "").timestamp()
    except ValueError:
        raise HrImportError(f"{path}: expected an ISO 8601 time for {what}, found {(text or '')[:40]!r}") from None


def read_tcx(path: Path) -> HrRecording:
    """Read a TCX file's trackpoints with heart rate."""
    root = load_xml(path, "tcx")
    rec = HrRecording(path, "tcx")
    for elem in root.iter():
        name = local(elem.tag)
        if name == "Creator" and not rec.device:
            version = ".".join(v for v in (_text(elem, "Version", "VersionMajor"),
                                           _text(elem, "Version", "VersionMinor")) if v)
            name = _text(elem, "Name") or ""
            rec.device = name if not version or version in name else f"{name} v{version}".strip()
        elif name == "Author" and not rec.producer:
            rec.producer = _text(elem, "Name") or ""
        elif name == "Lap":
            rec.laps += 1
        elif name == "Trackpoint":
            hr = _float(path, _text(elem, "HeartRateBpm", "Value"), "HeartRateBpm")
            if hr is not None:
                rec.add(_time(path, _text(elem, "Time"), "a Trackpoint"), hr)
    _set_start(rec)
    return rec


def _gpx_hr(point: ET.Element) -> str | None:
    ext = _child(point, "extensions")
    if ext is None:
        return None
    found = next((e for e in ext.iter() if local(e.tag).lower() in ("hr", "heartrate")), None)
    return None if found is None or found.text is None else found.text.strip()


def read_gpx(path: Path) -> HrRecording:
    """Read a GPX file's track points with a heart rate in their extensions."""
    root = load_xml(path, "gpx")
    rec = HrRecording(path, "gpx", device=root.get("creator", ""))
    for point in root.iter():
        if local(point.tag) != "trkpt":
            continue
        hr = _float(path, _gpx_hr(point), "a trkpt's hr")
        if hr is not None:
            rec.add(_time(path, _text(point, "time"), "a trkpt"), hr)
    _set_start(rec)
    return rec


def read_pwx(path: Path) -> HrRecording:
    """Read a PWX file's samples with heart rate."""
    root = load_xml(path, "pwx")
    rec = HrRecording(path, "pwx", producer=root.get("creator", ""))
    workout = _child(root, "workout")
    if workout is None:
        raise HrImportError(f"{path}: PWX: expected a workout element, found {[local(c.tag) for c in root][:5]}")
    device = _child(workout, "device")
    if device is not None:
        rec.device = " ".join(x for x in (_text(device, "make"), _text(device, "model")) if x)
    start = _time(path, _text(workout, "time"), "the workout's start")
    rec.laps = sum(1 for _ in _children(workout, "segment"))
    for sample in _children(workout, "sample"):
        hr = _float(path, _text(sample, "hr"), "a sample's hr")
        offset = _float(path, _text(sample, "timeoffset"), "a sample's timeoffset")
        if hr is not None and offset is not None:
            rec.add(start + offset, hr)
    rec.start_utc = dt.datetime.fromtimestamp(start, dt.timezone.utc) + (
        dt.timedelta(seconds=rec.t_s[0] - start) if rec.t_s else dt.timedelta(0))
    return rec


def _set_start(rec: HrRecording) -> None:
    if rec.t_s:
        rec.start_utc = dt.datetime.fromtimestamp(rec.t_s[0], dt.timezone.utc)
