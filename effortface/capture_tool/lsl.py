"""Lab Streaming Layer (LSL) out during capture: the strap and the events as LSL streams.

With ``effortface capture --lsl`` (or the Capture stage's *Publish to LSL* box) a recording also
publishes, so that LabRecorder records them beside EEG, EMG or eye tracking:

- a stream of type ``HeartRate`` (name ``effortface heart rate <participant>``), 2 float32 channels
  ``hr_bpm`` (unit ``bpm``) and ``rr_ms`` (unit ``ms``), irregular rate. One LSL sample per R-R
  interval of a ``heart_rate.csv`` row (a row without R-R gives one sample with ``rr_ms`` NaN; a
  contact loss has ``hr_bpm`` NaN), time-stamped at the row's arrival time on the LSL clock.
  Source id ``effortface:hr:<device>:<port>``: stable per strap and port, so LabRecorder and
  consumers re-find the stream after a restart.
- a ``Markers`` stream (name ``effortface events <participant>``, one string channel, irregular
  rate, source id ``...:events``): every ``events.csv`` row as the JSON text
  ``{"kind": ..., "label": ..., "value": ...}`` at its session time.

Session times and LSL times differ by one offset, measured when the recording starts and kept in
``session.json`` under ``lsl.clock_offset_s`` (``lsl_time = t_s + clock_offset_s``), so the
session's files and an XDF recording line up.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

import pylsl

from effortface.capture_tool.protocols import HrSample
from effortface.core.version import __version__

HEART_RATE_TYPE = "HeartRate"
MARKERS_TYPE = "Markers"
HR_CHANNELS = (("hr_bpm", "bpm", "HeartRate"), ("rr_ms", "ms", "RRInterval"))


def hr_source_id(device: str, port: str) -> str:
    """The HeartRate stream's source id: stable for one strap on one port."""
    return f"effortface:hr:{device}:{port}"


def _describe(info: pylsl.StreamInfo, channels: tuple[tuple[str, str, str], ...], extra: dict[str, str]) -> None:
    """Channel labels, units and types, and acquisition details, in the stream's XML description."""
    desc = info.desc()
    chans = desc.append_child("channels")
    for label, unit, kind in channels:
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", kind)
    acq = desc.append_child("acquisition")
    acq.append_child_value("manufacturer", "effortface")
    acq.append_child_value("software_version", __version__)
    for key, value in extra.items():
        acq.append_child_value(key, value)


def hr_rows_to_lsl(sample: HrSample) -> list[list[float]]:
    """The LSL samples ``[hr_bpm, rr_ms]`` of one heart-rate row (one per R-R interval, at least one)."""
    hr = float(sample.hr_bpm) if sample.valid and sample.hr_bpm is not None else math.nan
    return [[hr, float(rr)] for rr in sample.rr_ms] or [[hr, math.nan]]


class LslPublisher:
    """The HeartRate and Markers outlets of one recording.

    Parameters
    ----------
    device : str
        The strap's name (``hxm``, ``ant``...).
    port : str
        Its port (part of the source id).
    participant : str
        Participant code (in the stream names).
    session_id : str
        The session folder's name (in the descriptions).
    """

    def __init__(self, device: str, port: str, participant: str, session_id: str) -> None:
        self.source_id = hr_source_id(device, port)
        extra = {"session_id": session_id, "participant": participant, "device": device}
        hr_info = pylsl.StreamInfo(f"effortface heart rate {participant}", HEART_RATE_TYPE, len(HR_CHANNELS),
                                   pylsl.IRREGULAR_RATE, "float32", self.source_id)
        _describe(hr_info, HR_CHANNELS, extra)
        ev_info = pylsl.StreamInfo(f"effortface events {participant}", MARKERS_TYPE, 1, pylsl.IRREGULAR_RATE,
                                   "string", self.source_id + ":events")
        _describe(ev_info, (("event", "", "Marker"),), extra)
        self._hr = pylsl.StreamOutlet(hr_info)
        self._events = pylsl.StreamOutlet(ev_info)
        self.clock_offset_s = 0.0
        self.pushed = 0
        self.errors = 0

    def sync(self, session_clock_s: float) -> float:
        """Measure ``lsl_time - session_time`` now; return it (kept as :attr:`clock_offset_s`)."""
        self.clock_offset_s = pylsl.local_clock() - session_clock_s
        return self.clock_offset_s

    def session_record(self) -> dict[str, Any]:
        """What ``session.json`` keeps under ``lsl``."""
        return {"clock_offset_s": self.clock_offset_s, "heart_rate_source_id": self.source_id,
                "events_source_id": self.source_id + ":events",
                "heart_rate_type": HEART_RATE_TYPE, "library_version": pylsl.library_version()}

    def __call__(self, kind: str, obj: Any) -> None:
        """Publish one recorder item (``("hr", HrSample)`` or ``("event", event)``).

        Runs in the recorder's writer thread after the files are written: a failure here is
        counted (:attr:`errors`), never raised, so publishing can never cost a row on disk.
        """
        try:
            if kind == "hr":
                stamp = obj.t_s + self.clock_offset_s
                for row in hr_rows_to_lsl(obj):
                    self._hr.push_sample(row, stamp)
                    self.pushed += 1
            elif kind == "event":
                text = json.dumps({"kind": obj.kind, "label": obj.label, "value": obj.value})
                self._events.push_sample([text], obj.t_s + self.clock_offset_s)
        except Exception:  # noqa: BLE001 - the recording must go on whatever LSL does
            self.errors += 1

    def close(self, linger_s: float = 0.5) -> None:
        """Close the outlets (consumers see the streams disappear).

        With consumers connected, waits ``linger_s`` first so that they receive the last samples
        (the ``session_stop`` marker) before the outlets go.
        """
        if self._hr.have_consumers() or self._events.have_consumers():
            time.sleep(linger_s)
        del self._hr, self._events
