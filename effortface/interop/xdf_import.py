"""XDF in: a LabRecorder recording -> a session folder (``effortface import xdf``).

Streams are chosen by type or name (:func:`pick_stream`): the heart-rate stream (default: the one
stream whose name, type, a channel label or a channel unit says heart rate or R-R intervals, as other
apps write them: ``HeartRate`` typed ``ExciteOMeter``, a channel ``HR`` in ``bpm``, an ``RR`` stream
in ``ms``; :func:`heart_rate_streams`). Its channels (:func:`hr_channels`): heart rate by label or
unit ``bpm``, R-R intervals by label or unit ``ms``/``s``; a stream of R-R intervals only becomes
heart rate (60000 / RR ms) with its R-R kept. Units are checked: a unit that is neither bpm nor a
time is refused, and so is a stream whose values are mostly outside :data:`HR_RANGE_BPM` (an EEG
named as heart rate); a single value outside that range is never a valid sample. Samples sharing a
time stamp form one ``heart_rate.csv`` row, as ``capture --lsl`` publishes them. Every marker stream
(type ``Markers`` or ``StringMarker``; effortface's JSON markers keep their kind, label and value,
other strings become ``marker`` events, with every channel of a multi-channel marker kept), an optional ``EffortWork`` stream (-> ``work.csv``), an optional
mocap stream (channels ``<joint>_x``, ``_y``, ``_z`` -> ``motion/mocap.csv``, a joint-positions CSV
attached at its own time in ``motion/motion.json``, as ``effortface motion attach --offset`` does),
and a video file given beside it with its frame times: a stream with one sample per frame
(``--video-stream``), or the LSL time of its first frame (``--video-offset``) and its frame rate.

Session time 0 is the earliest time stamp of the imported streams; ``session.json`` keeps
``lsl.clock_offset_s`` (``lsl_time = t_s + clock_offset_s``) as a capture with ``--lsl`` does.

Every stream is checked before anything is written (issue 29): time stamps finite and spanning at
most ``BOUNDS["t_s"]``; a heart-rate stream with samples and at least one numeric channel (a rate
outside :data:`effortface.core.physio_limits.HR_BPM` is written as not valid); a work stream with
two finite channels within ``BOUNDS["w_per_kg"]``; ``--video-offset`` finite. Each refusal is one
line naming the file, the stream and the sample. The session is written into a hidden folder
beside its place and renamed into place at the end, so a failed import leaves no session.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import os
import re
import secrets
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.capture_tool.importers.session import copy_video
from effortface.core.hr_sample import HrSample
from effortface.core.session.folder import (EVENTS_CSV, HEART_RATE_CSV, VIDEO_AVI, VIDEO_FRAMES_CSV, Event,
                                             EventWriter, FrameTimeWriter, HrWriter, Participant, SessionInfo,
                                             create_session, make_session_id, move_session_in,
                                             utc_now_iso)
from effortface.core.bounds import BOUNDS
from effortface.core.errors import UserError
from effortface.core.opencv import import_cv2
from effortface.core.fileio import atomic_write_text, fsync_folder, json_text
from effortface.core.physio_limits import IMPORT_HR_BPM
from effortface.core.version import __version__

XdfStream = dict[str, Any]

#: the heart rates an imported sample may have to be valid (bpm): the strap readers' ceiling
#: (:data:`effortface.core.physio_limits.HR_BPM`) with a stricter floor, since a stream from another
#: app may hold anything under its name (25 bpm: below it, an imported value is not taken as a rate)
HR_RANGE_BPM = IMPORT_HR_BPM
#: names, types and channel labels (lower case, letters and digits only) that say heart rate
HR_KEYS = frozenset({"heartrate", "hr", "hrbpm", "bpm", "pulse", "pulserate"})
#: ... and R-R (inter-beat) intervals
RR_KEYS = frozenset({"rr", "rrms", "rrinterval", "rrintervals", "rrintervalms", "ibi", "interbeatinterval", "nn"})
BPM_UNITS = frozenset({"bpm", "beatsmin", "beatsperminute", "1min", "min", "min1", "countmin"})
MS_UNITS = frozenset({"ms", "msec", "millisecond", "milliseconds"})
S_UNITS = frozenset({"s", "sec", "second", "seconds"})
#: stream types taken as markers by default
MARKER_TYPES = frozenset({"markers", "marker", "stringmarker", "events"})


class XdfImportError(UserError):
    """A stream is missing or ambiguous, or a file cannot be read; the message names it."""


def load_xdf(path: str | os.PathLike) -> list[XdfStream]:
    """The streams of an XDF file (pyxdf, clock offsets applied)."""
    import pyxdf  # lazy: only the importer needs it

    path = Path(path)
    if not path.is_file():
        raise XdfImportError(f"{path}: expected an XDF file, found {'a folder' if path.is_dir() else 'no such file'}")
    log = logging.getLogger("pyxdf")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)  # its notes and logged tracebacks would break the one-line error rule
    try:
        streams, _ = pyxdf.load_xdf(str(path), dejitter_timestamps=False)
    except (Exception, MemoryError) as exc:  # pyxdf raises bare Exceptions on a damaged file;
        # a chunk claiming 2^40 samples fails its allocation
        raise XdfImportError(f"{path}: expected an XDF file, found {type(exc).__name__}: {str(exc)[:200]}") from None
    finally:
        log.setLevel(level)
    return streams


def _field(stream: XdfStream, key: str) -> str:
    return str((stream["info"].get(key) or [""])[0])


def describe(streams: Sequence[XdfStream]) -> str:
    """``name (type), ...`` of the streams, for messages."""
    return ", ".join(f"{_field(s, 'name')!r} ({_field(s, 'type')})" for s in streams) or "no streams"


def find_stream(path: Path, streams: Sequence[XdfStream], wanted: str | None, default_type: str,
                option: str) -> XdfStream | None:
    """The one stream whose name or type is ``wanted`` (default: of type ``default_type``), or None.

    Raises
    ------
    XdfImportError
        Several match (naming them and the option that chooses).
    """
    key = wanted or default_type
    found = [s for s in streams if key in (_field(s, "name"), _field(s, "type"))] if wanted else \
        [s for s in streams if _field(s, "type") == default_type]
    if len(found) > 1:
        raise XdfImportError(f"{path}: expected one stream named or typed {key!r}, found {len(found)}: "
                             f"{describe(found)} (choose one by name with {option})")
    return found[0] if found else None


def pick_stream(path: Path, streams: Sequence[XdfStream], wanted: str | None, default_type: str,
                option: str) -> XdfStream:
    """Like :func:`find_stream`, but none found is an error naming the streams there are."""
    found = find_stream(path, streams, wanted, default_type, option)
    if found is None:
        raise XdfImportError(f"{path}: expected a stream named or typed {wanted or default_type!r} ({option}), "
                             f"found {describe(streams)}")
    return found


def channel_labels(stream: XdfStream) -> list[str]:
    """Channel labels from the stream description (empty strings where none)."""
    n = int(_field(stream, "channel_count") or 0)
    try:
        chans = stream["info"]["desc"][0]["channels"][0]["channel"]
        labels = [str((c.get("label") or [""])[0]) for c in chans]
    except (KeyError, IndexError, TypeError):
        labels = []
    return labels if len(labels) == n else [""] * n


def _samples(stream: XdfStream) -> tuple[np.ndarray, Any]:
    return np.asarray(stream["time_stamps"], dtype=float), stream["time_series"]


def _numeric(path: Path, stream: XdfStream, what: str, min_channels: int) -> np.ndarray:
    """A stream's samples as a (T, C) float array, or one line: no samples, too few channels, not numbers."""
    stamps, values = _samples(stream)
    name = _field(stream, "name") or _field(stream, "type")
    if len(stamps) == 0:
        raise XdfImportError(f"{path}: stream {name!r}: expected {what} samples, found none")
    try:
        array = np.asarray(values, dtype=float).reshape(len(stamps), -1)
    except (ValueError, TypeError):
        raise XdfImportError(f"{path}: stream {name!r}: expected numeric {what} channels, found "
                             f"{type(values).__name__} of {np.asarray(values).dtype} values") from None
    if array.shape[1] < min_channels:
        raise XdfImportError(f"{path}: stream {name!r}: expected at least {min_channels} {what} channel(s), "
                             f"found {array.shape[1]}")
    return array


def _key(text: str) -> str:
    """Lower case, letters and digits only: ``Heart Rate`` -> ``heartrate``, ``beats/min`` -> ``beatsmin``."""
    return re.sub(r"[^a-z0-9]", "", text.lower())


def channel_units(stream: XdfStream) -> list[str]:
    """Channel units from the stream description (``unit`` or ``units``; empty strings where none)."""
    n = int(_field(stream, "channel_count") or 0)
    try:
        chans = stream["info"]["desc"][0]["channels"][0]["channel"]
        units = [str(((c.get("unit") or c.get("units")) or [""])[0]) for c in chans]
    except (KeyError, IndexError, TypeError):
        units = []
    return units if len(units) == n else [""] * n


def _says(stream: XdfStream) -> tuple[bool, bool]:
    """(says heart rate, says R-R intervals) from the name, type, channel labels and units."""
    if _field(stream, "channel_format") == "string":
        return False, False
    names = {_key(_field(stream, "name")), _key(_field(stream, "type"))}
    labels = {_key(lab) for lab in channel_labels(stream)}
    units = {_key(u) for u in channel_units(stream)}
    hr = bool((names | labels) & HR_KEYS or units & BPM_UNITS)
    rr = bool((names | labels) & RR_KEYS)
    return hr, rr


def heart_rate_streams(streams: Sequence[XdfStream]) -> list[XdfStream]:
    """The streams that say heart rate (by name, type, channel label or unit ``bpm``); else those that
    say R-R intervals."""
    hr = [s for s in streams if _says(s)[0]]
    return hr or [s for s in streams if _says(s)[1]]


#: names, types and channel labels (keyed) that say ECG: a Polar H10's 130 Hz electrocardiogram
ECG_KEYS = ("ecg", "ekg", "electrocardiogram")


def is_ecg(stream: XdfStream) -> bool:
    """True for an ECG stream (its name, type or a channel label says ECG/EKG): not heart rate."""
    words = [_key(_field(stream, "name")), _key(_field(stream, "type")), *map(_key, channel_labels(stream))]
    return any(k in w for w in words for k in ECG_KEYS)


def _refuse_ecg(path: Path, stream: XdfStream) -> None:
    stamps = _samples(stream)[0]
    rate = f", {(len(stamps) - 1) / (stamps[-1] - stamps[0]):.0f} Hz" if len(stamps) > 1 and stamps[-1] > stamps[0] \
        else ""
    raise XdfImportError(f"{path}: stream {_field(stream, 'name')!r} ({_field(stream, 'type')}{rate}): ECG, not "
                         "heart rate (import the app's HR or RR stream with --hr-stream; --keep-ecg copies the ECG "
                         "into the session as ecg.csv)")


def pick_hr_stream(path: Path, streams: Sequence[XdfStream], wanted: str | None) -> XdfStream:
    """The heart-rate stream: ``wanted`` by name or type, else the one :func:`heart_rate_streams` finds.

    Raises
    ------
    XdfImportError
        None or several found (naming the streams and ``--hr-stream``).
    """
    if wanted:
        chosen = pick_stream(path, streams, wanted, "HeartRate", "--hr-stream")
        if is_ecg(chosen):
            _refuse_ecg(path, chosen)
        return chosen
    typed = [s for s in streams if _field(s, "type") == "HeartRate" and not is_ecg(s)]
    found = typed or [s for s in heart_rate_streams(streams) if not is_ecg(s)]
    if not found and any(is_ecg(s) for s in streams):
        _refuse_ecg(path, next(s for s in streams if is_ecg(s)))
    if not found:
        raise XdfImportError(f"{path}: expected a heart-rate stream (named or typed HeartRate, HR or RR, or a "
                             f"channel labelled so or in bpm; or name one with --hr-stream), found {describe(streams)}")
    if len(found) > 1:
        raise XdfImportError(f"{path}: expected one heart-rate stream, found {len(found)}: {describe(found)} "
                             "(choose one by name with --hr-stream)")
    return found[0]


def hr_channels(path: Path, stream: XdfStream) -> tuple[int | None, int | None, float]:
    """Which channels hold heart rate (bpm) and R-R intervals, and the factor to milliseconds of the latter.

    Returns
    -------
    hr_col, rr_col : int or None
        Column of the heart rate in bpm, of the R-R intervals (at least one is given).
    rr_to_ms : float
        1 for a channel in ms, 1000 for one in s.

    Raises
    ------
    XdfImportError
        A unit that is neither bpm nor a time, or several channels none of which says what it holds.
    """
    labels, units = channel_labels(stream), channel_units(stream)
    keys, ukeys = [_key(lab) for lab in labels], [_key(u) for u in units]
    name = f"{path}: stream {_field(stream, 'name')!r} ({_field(stream, 'type')})"
    hr_col = next((i for i, (k, u) in enumerate(zip(keys, ukeys)) if k in HR_KEYS or u in BPM_UNITS), None)
    rr_col = next((i for i, (k, u) in enumerate(zip(keys, ukeys))
                   if i != hr_col and (k in RR_KEYS or (u in MS_UNITS | S_UNITS and k not in HR_KEYS))), None)
    if hr_col is None and rr_col is None:
        if unlabelled_rr(stream):
            return None, 0, 1.0
        if len(labels) != 1:
            raise XdfImportError(f"{name}: expected a channel labelled hr_bpm, HeartRate or HR (or in bpm) or rr_ms, "
                                 f"RR or IBI (in ms), found labels {labels}")
        says_hr, says_rr = _says(stream)
        if ukeys[0] in MS_UNITS | S_UNITS or (says_rr and not says_hr):
            rr_col = 0
        else:
            hr_col = 0
    for col, allowed, what in ((hr_col, BPM_UNITS, "bpm"), (rr_col, MS_UNITS | S_UNITS, "ms or s")):
        if col is not None and ukeys[col] and ukeys[col] not in allowed:
            raise XdfImportError(f"{name}: channel {labels[col] or col!r}: expected a unit of {what}, found "
                                 f"{units[col]!r}: not imported as heart rate (convert it, or choose another "
                                 "stream with --hr-stream)")
    return hr_col, rr_col, 1000.0 if rr_col is not None and ukeys[rr_col] in S_UNITS else 1.0


#: values (ms) that unlabelled channels must all hold to be taken as R-R intervals
UNLABELLED_RR_MS = (250.0, 2000.0)


def unlabelled_rr(stream: XdfStream) -> bool:
    """True for a numeric stream whose channels say nothing (no label, no unit) and whose every finite,
    non-zero value is an R-R interval in ms (:data:`UNLABELLED_RR_MS`): a phone app's R-R channels
    (0 or NaN where a sample has fewer intervals)."""
    said = [t for t in (*channel_labels(stream), *channel_units(stream)) if t not in ("", "None")]  # pyxdf: <label/>
    if said or _field(stream, "channel_format") == "string":
        return False
    try:
        values = np.asarray(stream["time_series"], dtype=float)
    except (ValueError, TypeError):
        return False
    seen = values[np.isfinite(values) & (values != 0)]
    low, high = UNLABELLED_RR_MS
    return bool(seen.size) and bool(np.all((seen >= low) & (seen <= high)))


def _check_hr_range(path: Path, stream: XdfStream, hr_bpm: np.ndarray, what: str) -> None:
    """XdfImportError unless most finite values are heart rates within :data:`HR_RANGE_BPM`."""
    name = f"{path}: stream {_field(stream, 'name')!r} ({_field(stream, 'type')})"
    finite = hr_bpm[np.isfinite(hr_bpm)]
    if finite.size == 0:
        raise XdfImportError(f"{name}: expected heart-rate samples, found no finite value")
    low, high = HR_RANGE_BPM
    inside = np.count_nonzero((finite >= low) & (finite <= high))
    if inside * 2 < finite.size:
        raise XdfImportError(f"{name}: expected heart rates of {low:g}-{high:g} bpm ({what}), found "
                             f"{finite.size - inside} of {finite.size} values outside (median "
                             f"{float(np.median(finite)):.4g} bpm): not imported as heart rate "
                             "(choose another stream with --hr-stream)")


def hr_rows(path: Path, stream: XdfStream, t0: float) -> list[HrSample]:
    """``heart_rate.csv`` rows: samples sharing a time stamp make one row (their R-R intervals).

    A stream of R-R intervals only gives heart rate 60000 / RR (ms) of the row's last interval; a
    heart rate outside :data:`HR_RANGE_BPM` is never valid.

    Raises
    ------
    XdfImportError
        An empty stream, a unit that is not bpm or a time, values that are not heart rates (one line).
    """
    stamps, values = _samples(stream)
    device = _field(stream, "name") or "xdf"
    if len(stamps) == 0:
        raise XdfImportError(f"{path}: stream {device!r}: expected heart-rate samples, found an empty stream")
    hr_col, rr_col, rr_to_ms = hr_channels(path, stream)
    values = _numeric(path, stream, "heart-rate", 1)
    if hr_col is None and rr_col == 0 and unlabelled_rr(stream) and values.shape[1] > 1:
        return _rr_channel_rows(path, stream, stamps, values, t0, device)
    rr_ms = values[:, rr_col] * rr_to_ms if rr_col is not None else None
    with np.errstate(divide="ignore", invalid="ignore"):
        hr_all: np.ndarray = values[:, hr_col] if hr_col is not None else 60000.0 / np.asarray(rr_ms)
    what = "its channel in bpm" if hr_col is not None else "60000 / its R-R intervals in ms"
    _check_hr_range(path, stream, hr_all, what)
    low, high = HR_RANGE_BPM
    rows: list[HrSample] = []
    order = np.argsort(stamps, kind="stable")  # sorted once and split: linear in samples
    unique, starts = np.unique(stamps[order], return_index=True)
    hr_groups = np.split(hr_all[order], starts[1:])
    no_rr: list[np.ndarray] = [np.empty(0)] * len(unique)
    rr_groups = np.split(np.asarray(rr_ms)[order], starts[1:]) if rr_ms is not None else no_rr
    for stamp, hr_group, rr_group in zip(unique, hr_groups, rr_groups):
        hr = float(hr_group[-1] if hr_col is None else hr_group[0])
        rr = tuple(float(v) for v in rr_group if math.isfinite(v))
        ok = math.isfinite(hr) and low <= hr <= high
        rows.append(HrSample(round(float(stamp) - t0, 4), hr if ok else None, rr, None, device, ok))
    return rows


def _rr_channel_rows(path: Path, stream: XdfStream, stamps: np.ndarray, values: np.ndarray, t0: float,
                     device: str) -> list[HrSample]:
    """Rows of a stream of unlabelled R-R channels: each sample's finite non-zero values are its R-R
    intervals (ms), its heart rate 60000 / the last of them; samples sharing a stamp make one row."""
    rr_per_sample = [tuple(float(v) for v in row if math.isfinite(v) and v != 0) for row in values]
    last = np.array([rr[-1] if rr else np.nan for rr in rr_per_sample])
    with np.errstate(divide="ignore", invalid="ignore"):
        _check_hr_range(path, stream, 60000.0 / last, "60000 / its R-R intervals in ms")
    low, high = HR_RANGE_BPM
    rows: list[HrSample] = []
    for stamp in np.unique(stamps):
        idx = np.flatnonzero(stamps == stamp)
        rr = tuple(v for i in idx for v in rr_per_sample[i])
        hr = 60000.0 / rr[-1] if rr else math.nan
        ok = math.isfinite(hr) and low <= hr <= high
        rows.append(HrSample(round(float(stamp) - t0, 4), hr if ok else None, rr, None, device, ok))
    return rows


def _json_path(doc: Any, key_path: str) -> Any:
    """``doc["a"]["b"]`` for ``a.b`` (None where a step is missing)."""
    for step in key_path.split("."):
        if not isinstance(doc, dict) or step not in doc:
            return None
        doc = doc[step]
    return doc


def _json_docs(stream: XdfStream) -> list[Any] | None:
    """The JSON value of each sample's first channel of a string stream, or None when the first is not JSON."""
    if _field(stream, "channel_format") != "string" or len(_samples(stream)[0]) == 0:
        return None
    docs = []
    for sample in stream["time_series"]:
        try:
            docs.append(json.loads(str(sample[0]) if len(sample) else ""))
        except (ValueError, RecursionError):
            docs.append(None)
    return docs if isinstance(docs[0], dict) else None


def _json_key(docs: list[Any], hr_key: str | None) -> str | None:
    """The key path of the heart rate: ``hr_key``, else a top-level key of the first sample that says heart rate."""
    if hr_key is not None:
        return hr_key
    return next((k for k in docs[0] if _key(str(k)) in HR_KEYS), None)


def json_hr_stream(path: Path, stream: XdfStream, hr_key: str | None, rr_key: str | None) -> XdfStream | None:
    """A string stream of JSON text holding heart rate (``hr_key``, e.g. ``hr`` or ``data.hr``) as a numeric
    stream with channels ``hr_bpm`` (bpm) and ``rr_ms`` (ms; a list of R-R intervals at ``rr_key`` gives
    one sample per interval at the same time stamp), or None when the stream is not such JSON.

    Raises
    ------
    XdfImportError
        ``hr_key`` given but found in no sample (naming the keys the first sample has).
    """
    docs = _json_docs(stream)
    if docs is None:
        return None
    key = _json_key(docs, hr_key)
    if key is None:
        return None
    stamps_in = _samples(stream)[0]
    stamps, rows = [], []
    for stamp, doc in zip(stamps_in, docs):
        hr = _json_path(doc, key)
        rr = _json_path(doc, rr_key) if rr_key else None
        rr_list = rr if isinstance(rr, list) else ([rr] if rr is not None else [None])
        for value in rr_list:
            stamps.append(stamp)
            rows.append([_as_float(hr), _as_float(value)])
    if all(math.isnan(r[0]) for r in rows):
        if hr_key is None:
            return None
        raise XdfImportError(f"{path}: stream {_field(stream, 'name')!r}: --hr-json-key {hr_key}: expected a number "
                             f"at that key path, found none (the first sample's keys: {sorted(docs[0])[:10]})")
    info = dict(stream["info"], channel_format=["float32"], channel_count=["2"],
                desc=[{"channels": [{"channel": [{"label": ["hr_bpm"], "unit": ["bpm"]},
                                                 {"label": ["rr_ms"], "unit": ["ms"]}]}]}])
    return {"info": info, "time_stamps": np.asarray(stamps, float), "time_series": np.asarray(rows, float)}


def _as_float(value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        return math.nan
    return out if math.isfinite(out) else math.nan


def _with_json_streams(path: Path, streams: list[XdfStream], hr_key: str | None,
                       rr_key: str | None) -> list[XdfStream]:
    """``streams`` with each JSON text stream holding heart rate replaced by its numeric form."""
    out = []
    for stream in streams:
        if _key(_field(stream, "type")) in MARKER_TYPES:
            out.append(stream)
            continue
        converted = json_hr_stream(path, stream, hr_key, rr_key)
        out.append(converted if converted is not None else stream)
    return out


def check_stamps(path: Path, streams: Sequence[XdfStream], extra: np.ndarray | None = None) -> float:
    """Session time 0 (the earliest stamp) after checking every stream's stamps; one line naming the bad one.

    Raises
    ------
    XdfImportError
        A stamp that is not finite, or stamps spanning more than ``BOUNDS["t_s"]`` allows (a marker
        at +-1e15 s).
    """
    named = [(_field(s, "name") or _field(s, "type"), _samples(s)[0]) for s in streams]
    if extra is not None:
        named.append(("--video frames", np.asarray(extra, float)))
    for name, stamps in named:
        bad = np.flatnonzero(~np.isfinite(stamps))
        if bad.size:
            raise XdfImportError(f"{path}: stream {name!r}: expected finite time stamps, found {stamps[bad[0]]} "
                                 f"at sample {int(bad[0])}")
    starts = [float(st.min()) for _, st in named if len(st)]
    if not starts:
        raise XdfImportError(f"{path}: expected time-stamped samples in the imported streams, found none")
    t0 = min(starts)
    bound = BOUNDS["t_s"]
    for name, stamps in named:
        if len(stamps) and not bound.contains(float(stamps.max()) - t0):
            raise XdfImportError(f"{path}: stream {name!r}: expected time stamps within {bound.high:g} s of the "
                                 f"first, found {float(stamps.max()) - t0:g} s after it")
    return t0


def marker_events(stream: XdfStream, t0: float) -> list[Event]:
    """Events of a marker stream (effortface JSON markers keep kind, label, value; the channels after the
    first of a multi-channel marker become the value, joined by `` | ``)."""
    stamps, values = _samples(stream)
    out = []
    for stamp, sample in zip(stamps, values):
        text = str(sample[0]) if len(sample) else ""
        rest = " | ".join(str(v) for v in list(sample)[1:])
        try:
            doc = json.loads(text)
            event = Event(stamp - t0, str(doc["kind"]), str(doc.get("label", "")),
                          str(doc.get("value", "")) + (f" | {rest}" if rest else ""))
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError):  # a deeply nested marker
            event = Event(stamp - t0, "marker", text, rest)
        out.append(event)
    return out


def _write_work(path: Path, folder: Path, stream: XdfStream, t0: float) -> None:
    labels = channel_labels(stream)
    stamps = _samples(stream)[0]
    values = _numeric(path, stream, "work", 2)
    cols = [labels.index(c) if c in labels else i for i, c in enumerate(("w_per_kg", "p_per_kg"))]
    for col, field in zip(cols, ("w_per_kg", "p_per_kg")):
        bound = BOUNDS[field]
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~((values[:, col] >= bound.low) & (values[:, col] <= bound.high)))
        if bad.size:
            raise XdfImportError(f"{path}: stream {_field(stream, 'name')!r}: {field}: expected "
                                 f"{bound.describe()}, found {values[bad[0], col]:g} at sample {int(bad[0])}")
    lines = ["t_s,w_per_kg,p_per_kg"] + [f"{t - t0:.4f},{v[cols[0]]:.6g},{v[cols[1]]:.6g}"
                                         for t, v in zip(stamps, values)]
    atomic_write_text(folder / "work.csv", "\n".join(lines) + "\n")


#: the name of the joint-positions clip a mocap stream becomes in the session's ``motion/``
MOCAP_CSV = "mocap.csv"


#: ``session.json``'s ``lsl`` key saying where the imported mocap clip's skeleton tree came from
MOCAP_TREE_KEY = "mocap_skeleton"


def _write_mocap(path: Path, staging: Path, stream: XdfStream, t0: float,
                 skeleton: Path | None) -> tuple[Path, float, str]:
    """The mocap stream as a joint-positions CSV in ``staging`` (session times) with its skeleton file:
    ``skeleton``'s tree, or (an XDF stream carries none) the first joint the parent of every other one.
    Returns the CSV, the session time of its first frame and where the tree came from."""
    from effortface.synth.motion_csv import csv_header, read_skeleton, skeleton_beside

    labels = channel_labels(stream)
    joints = [lab[:-2] for lab in labels[::3]]
    if not joints or any(labels[3 * i:3 * i + 3] != [f"{j}_x", f"{j}_y", f"{j}_z"] for i, j in enumerate(joints)):
        raise XdfImportError(f"{path}: mocap stream {_field(stream, 'name')!r}: expected channel labels "
                             f"<joint>_x, <joint>_y, <joint>_z, found {labels[:6]}")
    stamps, values = _samples(stream)
    if len(stamps) < 2:
        raise XdfImportError(f"{path}: mocap stream {_field(stream, 'name')!r}: expected at least 2 frames, "
                             f"found {len(stamps)}")
    rows = [",".join(csv_header(joints))] + [",".join(f"{x:.9g}" for x in [t - t0, *v])
                                             for t, v in zip(stamps, np.asarray(values, float))]
    clip = staging / MOCAP_CSV
    atomic_write_text(clip, "\n".join(rows) + "\n")
    if skeleton is None:
        tree: dict[str, Any] = {"joints": joints, "parents": [-1] + [0] * (len(joints) - 1)}
        origin = f"none in the stream: {joints[0]} taken as the parent of every other joint"
    else:
        given = read_skeleton(skeleton)
        if given["joints"] != joints:
            raise XdfImportError(f"--mocap-skeleton {skeleton}: expected the {len(joints)} joints of mocap stream "
                                 f"{_field(stream, 'name')!r} in its channel order ({', '.join(joints[:4])}...), "
                                 f"found {', '.join(given['joints'][:4])}... ({len(given['joints'])} joints)")
        tree = {"joints": joints, "parents": [int(p) for p in given["parents"]]}
        if given["rest_positions_m"] is not None:
            tree["rest_positions_m"] = np.round(given["rest_positions_m"], 6).tolist()
        origin = f"--mocap-skeleton {skeleton.name}"
    atomic_write_text(skeleton_beside(clip), json_text(tree))
    return clip, float(stamps[0] - t0), origin


def _attach_mocap(path: Path, folder: Path, stream: XdfStream, clip: Path, offset_s: float,
                  skeleton: Path | None) -> None:
    """Attach the mocap clip to the (complete) staged session at its own time (``motion/mocap.csv`` and
    ``motion/motion.json``, as ``effortface motion attach --offset``): its work is then derived like
    any attached clip's. A clip that cannot be read as a body (joints mapped to segments, human ranges)
    is one line naming the XDF file and the stream."""
    from effortface.synth.attach import attach_clip

    from effortface.synth.motion_csv import skeleton_beside

    try:
        attach_clip(folder, clip, offset_s=offset_s)
    except UserError as exc:  # named as the user knows them, not by their staging copies
        where = f"{path}: mocap stream {_field(stream, 'name')!r}"
        tree = f"--mocap-skeleton {skeleton}" if skeleton is not None else f"{where} (its default tree)"
        message = str(exc).replace(str(skeleton_beside(clip)), tree).replace(str(clip), where)
        raise XdfImportError(message if where in message or tree in message else f"{where}: {message}") from None


def _write_ecg(path: Path, folder: Path, stream: XdfStream, t0: float, info: SessionInfo) -> None:
    """``ecg.csv`` (``t_s,ecg``): the ECG stream's first channel as recorded; its unit in ``session.json``."""
    stamps = _samples(stream)[0]
    values = _numeric(path, stream, "ECG", 1)[:, 0]
    lines = ["t_s,ecg"] + [f"{t - t0:.4f},{v:.6g}" for t, v in zip(stamps, values)]
    atomic_write_text(folder / "ecg.csv", "\n".join(lines) + "\n")
    info.devices["ecg"] = {"stream": _field(stream, "name"), "unit": channel_units(stream)[0] or "unknown",
                           "samples": int(len(stamps))}


def _frame_times(path: Path, streams: Sequence[XdfStream], video: Path, video_stream: str | None,
                 video_offset_s: float | None) -> np.ndarray:
    """LSL times of the video's frames: from a stream (one sample per frame) or an offset + fps."""
    cv2 = import_cv2()  # lazy: only with a video (OpenCV log silenced)

    cap = cv2.VideoCapture(str(video))
    n_frames, fps = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), float(cap.get(cv2.CAP_PROP_FPS))
    cap.release()
    if n_frames <= 0:
        raise XdfImportError(f"--video {video}: expected a readable video, found no frames")
    if video_stream is not None:
        stream = pick_stream(path, streams, video_stream, "VideoFrames", "--video-stream")
        stamps = _samples(stream)[0]
        if len(stamps) < n_frames:
            raise XdfImportError(f"--video-stream {video_stream}: expected one sample per frame ({n_frames}), "
                                 f"found {len(stamps)}")
        return stamps[:n_frames]
    if video_offset_s is None:
        raise XdfImportError(f"--video {video}: expected its frame times, --video-stream NAME or "
                             "--video-offset S, found neither")
    if not (math.isfinite(fps) and fps > 0):
        raise XdfImportError(f"--video {video}: expected a frame rate, found {fps:g}")
    return video_offset_s + np.arange(n_frames) / fps


def import_xdf(path: str | os.PathLike, out_dir: str | os.PathLike, participant: Participant, *,
               hr_stream: str | None = None, marker_streams: Sequence[str] = (),
               work_stream: str | None = None, mocap_stream: str | None = None,
               video: str | os.PathLike | None = None, video_stream: str | None = None,
               video_offset_s: float | None = None, label: str | None = None,
               hr_json_key: str | None = None, rr_json_key: str | None = None, keep_ecg: bool = False,
               mocap_skeleton: str | os.PathLike | None = None) -> Path:
    """Turn an XDF recording into a new session folder in ``out_dir``; return it.

    Parameters
    ----------
    path : path-like
        The ``.xdf`` file.
    out_dir : path-like
        Folder that receives the session folder (never reused).
    participant : Participant
        Who was recorded.
    hr_stream : str, optional
        Name or type of the heart-rate stream (default: the one of type ``HeartRate``).
    marker_streams : sequence of str
        Names or types of marker streams (default: every stream of type ``Markers``).
    work_stream, mocap_stream : str, optional
        Name or type of an ``EffortWork`` stream (default: one of that type if present) and of a
        mocap stream (none by default).
    video : path-like, optional
        The video recorded beside it; ``video_stream`` (one sample per frame) or ``video_offset_s``
        (LSL time of frame 0) gives its frame times.
    label : str, optional
        Appended to the session id.
    hr_json_key, rr_json_key : str, optional
        Key paths (``hr``, ``data.hr``) of the heart rate and R-R intervals (ms, a number or a list)
        in a string stream of JSON text (default: a top-level key that says heart rate, no R-R).
    keep_ecg : bool
        Copy an ECG stream (a Polar H10's) into the session as ``ecg.csv`` (``t_s,ecg``, its unit in
        ``session.json``); without it an ECG stream is never taken as heart rate.
    mocap_skeleton : path-like, optional
        A skeleton file (``{"joints": [...], "parents": [...]}``, the stream's joints in its channel
        order) giving the mocap clip's tree; without it the first joint is the parent of every other
        one (an XDF stream carries no tree), said in ``session.json`` (``lsl.mocap_skeleton``).

    Raises
    ------
    XdfImportError
        Missing or ambiguous streams, unreadable files (one line each).
    """
    path = Path(path)
    if video_offset_s is not None and not (math.isfinite(video_offset_s) and abs(video_offset_s) <= 1e10):
        raise XdfImportError(f"--video-offset: expected a finite LSL time in seconds (at most 1e10), "
                             f"found {video_offset_s:g}")
    streams = _with_json_streams(path, load_xdf(path), hr_json_key, rr_json_key)
    hr = pick_hr_stream(path, streams, hr_stream)
    ecg = [s for s in streams if is_ecg(s)] if keep_ecg else []
    if keep_ecg and len(ecg) != 1:
        raise XdfImportError(f"{path}: --keep-ecg: expected one ECG stream, found {len(ecg)}"
                             f"{': ' + describe(ecg) if ecg else ''}")
    markers = ([pick_stream(path, streams, m, "Markers", "--marker-stream") for m in marker_streams]
               or [s for s in streams if _key(_field(s, "type")) in MARKER_TYPES])
    work = (pick_stream if work_stream else find_stream)(path, streams, work_stream, "EffortWork", "--work-stream")
    mocap = pick_stream(path, streams, mocap_stream, "MoCap", "--mocap-stream") if mocap_stream else None
    video_path = Path(video) if video is not None else None
    if video_path is not None and not video_path.is_file():
        raise XdfImportError(f"--video {video_path}: expected a video file, found no such file")
    frames = _frame_times(path, streams, video_path, video_stream, video_offset_s) if video_path else None
    used = [s for s in (hr, *markers, work, mocap, *ecg) if s is not None]
    if len(_samples(hr)[0]) == 0:  # named before the stamps of all streams are checked
        raise XdfImportError(f"{path}: stream {_field(hr, 'name') or 'xdf'!r}: expected heart-rate samples, "
                             "found an empty stream")
    t0 = check_stamps(path, used, frames)
    hr_table = hr_rows(path, hr, t0)
    events = sorted((e for m in markers for e in marker_events(m, t0)), key=lambda e: e.t_s)
    info = SessionInfo(session_id=make_session_id(participant.code, _dt.datetime.now(), label),
                       participant=participant, devices={"heart_rate": {"device": _field(hr, "name"),
                                                                         "protocol": "lsl", "port": str(path)}},
                       complete=False, created_utc=utc_now_iso(),
                       software={"name": "effortface", "version": __version__},
                       extra={"lsl": {"clock_offset_s": t0, "imported_from": path.name,
                                      "streams": [_field(s, "name") for s in used]}})
    staging = Path(out_dir) / f".import-{secrets.token_hex(6)}.tmp"
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    try:
        folder = create_session(staging, info)
        _write_rows(HrWriter(folder / HEART_RATE_CSV), hr_table)
        _write_rows(EventWriter(folder / EVENTS_CSV), events)
        if work is not None:
            _write_work(path, folder, work, t0)
        skeleton = Path(mocap_skeleton) if mocap_skeleton is not None else None
        clip = _write_mocap(path, staging, mocap, t0, skeleton) if mocap is not None else None
        if clip is not None:
            info.extra["lsl"][MOCAP_TREE_KEY] = clip[2]
        for stream in ecg:
            _write_ecg(path, folder, stream, t0, info)
        if video_path is not None and frames is not None:
            copy_video(video_path, folder / VIDEO_AVI)
            writer = FrameTimeWriter(folder / VIDEO_FRAMES_CSV)
            for k, stamp in enumerate(frames):
                writer.write(k, float(stamp - t0))
            writer.close()
        info.complete = True
        info.save(folder, overwrite=True)
        if clip is not None and mocap is not None:
            _attach_mocap(path, folder, mocap, clip[0], clip[1], skeleton)
        final = move_session_in(folder, out_dir, info)  # whole or not at all, suffixed if its id is taken
        fsync_folder(out_dir)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return final


def _write_rows(writer: Any, rows: Sequence[Any]) -> None:
    for row in rows:
        writer.write(row)
    writer.close()
