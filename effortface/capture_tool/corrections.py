"""Corrections of the exercise log: a mistaken phase key is fixed by a new row, never by rewriting history.

The Capture stage logs ``correction`` rows in ``events.csv``::

    t_s,kind,label,value
    312.4,correction,squats,phase_start@300.1250

meaning: the phase started at 300.125 s (logged with another exercise id, e.g. ``lunges`` by a
mistaken F-key) was in fact ``squats``. :func:`apply_corrections` gives the events as corrected:
that ``phase_start``, the ``phase_end`` that closes it and the parameter rows labelled with the old
id inside the phase take the new id. The rows on disk never change.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

from effortface.core.session.folder import Event

CORRECTION_KIND = "correction"
_TARGET = "phase_start@"
#: kinds whose label is the exercise id of the phase they belong to
_LABELLED_BY_EXERCISE = ("phase_start", "phase_end", "speed", "grade", "power", "cadence", "rom", "reps")


def correction_value(phase_start_t_s: float) -> str:
    """The ``value`` of a correction row that names the phase started at ``phase_start_t_s``."""
    return f"{_TARGET}{phase_start_t_s:.4f}"


def corrected_start_t_s(event: Event) -> float | None:
    """The phase start a correction row names (None if ``event`` is not a readable correction)."""
    if event.kind != CORRECTION_KIND or not event.value.startswith(_TARGET):
        return None
    try:
        t_s = float(event.value[len(_TARGET):])
    except ValueError:
        return None
    return t_s if math.isfinite(t_s) else None


def apply_corrections(events: Sequence[Event]) -> list[Event]:
    """The events with every correction applied (the last correction of a phase wins).

    Parameters
    ----------
    events : sequence of Event
        As read from ``events.csv``.

    Returns
    -------
    list of Event
        Same order; corrected rows relabelled, correction rows kept (readers ignore their kind).
    """
    fixes: dict[int, str] = {}
    for ev in events:
        t_s = corrected_start_t_s(ev)
        if t_s is None:
            continue
        start = next((i for i, e in enumerate(events)
                      if e.kind == "phase_start" and abs(e.t_s - t_s) < 2e-4), None)
        if start is not None:
            fixes[start] = ev.label
    out = list(events)
    for start, new in fixes.items():
        old = events[start].label
        for i in range(start, len(events)):
            ev = events[i]
            if i > start and ev.kind == "phase_start":
                break
            if ev.kind in _LABELLED_BY_EXERCISE and ev.label == old:
                out[i] = dataclasses.replace(ev, label=new)
            if i > start and ev.kind == "phase_end" and ev.label == old:
                break
    return out
