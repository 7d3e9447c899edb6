"""The exercise log: the rows of ``events.csv`` that say what the participant did, read as phases.

The vocabulary (DESIGN.md "Exercise log"; a contract, sessions from every release stay readable)::

    kind                      label                                   value
    phase_start / phase_end   an exercise id of the catalog           empty (earlier releases: a number, ignored)
    speed                     the exercise id                         m/s
    grade                     the exercise id                         percent
    power                     the exercise id                         watts
    cadence                   the exercise id                         rpm or repetitions per minute
    rom                       the exercise id                         range of motion of the lifted load, m
    reps                      the exercise id                         repetitions in the set so far
    load                      back_kg, left_kg, right_kg, machine_kg  kg, holding until the next row of that label

A parameter holds until the next row of the same kind and label, across phases (the treadmill keeps
its speed); a ``load`` holds until the next ``load`` row with that label. A ``phase_start`` while a
phase is open ends that phase. Other kinds (``sync``, ``marker``, ``link``, ``device_gap``...) are not
part of the log and are ignored here, except ``correction`` rows: the Capture stage's fix of a
mistaken phase key, applied first (:mod:`effortface.capture_tool.corrections`).

Rows written by earlier releases are read too: phase labels such as ``walk 1.5 m/s`` /
``run 3.4 m/s`` (treadmill walk / run at that speed), ``jumping jacks`` (spaces for ``_``),
``speed`` rows labelled ``treadmill_m_s``, and the Capture stage's ``load_kg=5;speed_kmh=8.5``
values (on ``phase_start`` or on ``load`` rows labelled with the phase): the speed in km/h becomes
the phase's speed in m/s and the load the exercise's lifted load (``machine_kg``, choice: the stage
did not say where it was carried). Any other number on ``phase_start`` is ignored.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path

from effortface.core.errors import SessionFormatError
from effortface.capture_tool.corrections import apply_corrections
from effortface.core.session.folder import EVENTS_CSV, Event, read_events

#: parameter kinds -> the name of the parameter in a :class:`PhaseState`
PARAMETER_KINDS = {"speed": "speed_m_s", "grade": "grade_pct", "power": "power_w",
                   "cadence": "cadence_per_min", "rom": "rom_m"}
#: load labels (kg) -> the name in a :class:`PhaseState`'s ``loads_kg``
LOAD_LABELS = ("back_kg", "left_kg", "right_kg", "machine_kg")
#: parameters that may be negative (a downhill grade)
SIGNED_PARAMETERS = ("grade",)
PHASE_KINDS = ("phase_start", "phase_end")
LOG_KINDS = (*PHASE_KINDS, *PARAMETER_KINDS, "reps", "load")
_LEGACY_GAIT = re.compile(r"^(walk|run)\s+(\d+(?:\.\d+)?)\s*m/s$")
_LEGACY_PARAMETER_LABELS = {"treadmill_m_s": "treadmill"}
_LEGACY_STAGE_VALUE = re.compile(r"^load_kg=([^;]*);speed_kmh=(.*)$")


def exercise_id(label: str) -> str:
    """The catalog id a log label names: lower case, spaces and ``-`` as ``_``.

    Earlier releases wrote ``jumping jacks``; ``walk 1.5 m/s`` / ``run 3.4 m/s`` become
    ``treadmill_walk`` / ``treadmill_run`` (their speed is read by :func:`read_exercise_log`).
    """
    text = label.strip().lower()
    gait = _LEGACY_GAIT.match(text)
    if gait:
        return f"treadmill_{gait[1]}"
    text = _LEGACY_PARAMETER_LABELS.get(text, text)
    return re.sub(r"[\s-]+", "_", text)


@dataclasses.dataclass(frozen=True)
class Change:
    """One logged value: at ``t_s`` the parameter became ``value`` (from ``line`` of events.csv)."""

    t_s: float
    value: float
    line: int


@dataclasses.dataclass(frozen=True)
class Phase:
    """One exercise phase.

    Attributes
    ----------
    exercise : str
        Catalog id (:func:`exercise_id` of the label).
    label : str
        The label as logged.
    start_s, end_s : float
        Session time of the phase; ``end_s`` is ``inf`` for a phase never ended.
    line : int
        Line of its ``phase_start`` in events.csv.
    implied : dict
        Parameters the label itself carries (``walk 1.5 m/s``: ``{"speed_m_s": 1.5}``).
    """

    exercise: str
    label: str
    start_s: float
    end_s: float
    line: int
    implied: dict[str, float] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class PhaseState:
    """The parameters in force during part of a phase (None: not logged).

    ``reps_per_min`` is the pace of the whole set from its last ``reps`` row (count / time since the
    phase started), None when the phase has none.
    """

    speed_m_s: float | None = None
    grade_pct: float | None = None
    power_w: float | None = None
    cadence_per_min: float | None = None
    rom_m: float | None = None
    reps_per_min: float | None = None
    loads_kg: tuple[tuple[str, float], ...] = ()

    def load_kg(self, label: str) -> float:
        """The load of ``label`` (``back_kg``...) in kg, 0 when none was logged."""
        return dict(self.loads_kg).get(label, 0.0)


@dataclasses.dataclass
class ExerciseLog:
    """A session's exercise log: phases, parameter and load timelines.

    Attributes
    ----------
    source : str
        The events.csv path (for messages).
    phases : list of Phase
        In time order.
    parameters : dict
        ``(exercise id, kind) -> [Change, ...]`` in time order, kind in :data:`PARAMETER_KINDS` or ``reps``.
    loads : dict
        ``label -> [Change, ...]`` for the labels of :data:`LOAD_LABELS`.
    """

    source: str
    phases: list[Phase]
    parameters: dict[tuple[str, str], list[Change]]
    loads: dict[str, list[Change]]

    def states(self, phase: Phase, keys: Sequence[str] = ()) -> list[tuple[float, float, PhaseState]]:
        """The phase cut at every change of a parameter or load: ``(start_s, end_s, state)`` pieces.

        Parameters
        ----------
        phase : Phase
        keys : sequence of str
            Further labels whose parameters apply to this phase (the catalog's family of the
            exercise, e.g. ``treadmill`` for ``treadmill_walk``); the phase's own id comes first.
        """
        labels = [phase.exercise, *[k for k in keys if k != phase.exercise]]
        cuts = {phase.start_s}
        for (label, _), changes in self.parameters.items():
            if label in labels:
                cuts.update(c.t_s for c in changes if phase.start_s < c.t_s < phase.end_s)
        for changes in self.loads.values():
            cuts.update(c.t_s for c in changes if phase.start_s < c.t_s < phase.end_s)
        starts = sorted(cuts)
        ends = starts[1:] + [phase.end_s]
        return [(a, b, self._state_at(phase, labels, a)) for a, b in zip(starts, ends)]

    def _state_at(self, phase: Phase, labels: Sequence[str], t_s: float) -> PhaseState:
        """The state of ``phase`` from ``t_s`` on (values logged at ``t_s`` count)."""
        values: dict[str, float | None] = {}
        for kind, name in PARAMETER_KINDS.items():
            found = [_held(self.parameters.get((label, kind), []), t_s) for label in labels]
            late = [_first_inside(self.parameters.get((label, kind), []), phase) for label in labels]
            values[name] = next((v for v in [*found, phase.implied.get(name), *late] if v is not None), None)
        rate = _pace_per_min(phase, [c for label in labels for c in self.parameters.get((label, "reps"), [])])
        loads = tuple((label, _held(self.loads.get(label, []), t_s) or 0.0) for label in LOAD_LABELS)
        return PhaseState(**values, reps_per_min=rate, loads_kg=loads)


def _pace_per_min(phase: Phase, reps: Sequence[Change]) -> float | None:
    """The set's pace from its last ``reps`` row inside the phase: count / time since the start."""
    inside = [c for c in reps if phase.start_s < c.t_s <= phase.end_s]
    if not inside:
        return None
    last = max(inside, key=lambda c: c.t_s)
    return 60.0 * last.value / (last.t_s - phase.start_s)


def _first_inside(changes: Sequence[Change], phase: Phase) -> float | None:
    """The first value logged during the phase: it also holds from the phase's start when nothing
    was logged before (the operator, or the recorder a moment after ``phase_start``, logs it late)."""
    return next((c.value for c in changes if phase.start_s <= c.t_s < phase.end_s), None)


def _held(changes: Sequence[Change], t_s: float) -> float | None:
    """The last value logged at or before ``t_s`` (None if none)."""
    value = None
    for c in changes:
        if c.t_s > t_s + 1e-9:
            break
        value = c.value
    return value


def read_exercise_log(path: str | os.PathLike) -> ExerciseLog:
    """Read the exercise log of an ``events.csv`` (or a session folder).

    Parameters
    ----------
    path : path-like
        The events.csv file, or the session folder that holds it.

    Returns
    -------
    ExerciseLog

    Raises
    ------
    SessionFormatError
        For a parameter or load that is not a number, a negative speed, power, cadence, range of
        motion, repetition count or load, an unknown load label, or a ``phase_end`` that closes no
        open phase of that label; the message names the file and line.
    """
    path = Path(path)
    if path.is_dir():
        path = path / EVENTS_CSV
    if not path.exists():
        return ExerciseLog(str(path), [], {}, {})
    return exercise_log(read_events(path), str(path))


def exercise_log(events: Sequence[Event], source: str = EVENTS_CSV) -> ExerciseLog:
    """The exercise log of already-read events (see :func:`read_exercise_log`).

    Line numbers in messages count the header as line 1 and one event per line.
    """
    events = apply_corrections(events)  # a mistaken phase key fixed in Capture (a ``correction`` row)
    log = ExerciseLog(source, [], {}, {})
    open_phase: tuple[str, str, float, int, dict[str, float]] | None = None
    for line, ev in sorted(((i + 2, e) for i, e in enumerate(events)), key=lambda p: p[1].t_s):
        if ev.kind == "phase_start":
            if open_phase is not None:
                log.phases.append(Phase(*open_phase[:2], open_phase[2], ev.t_s, *open_phase[3:]))
            open_phase = (exercise_id(ev.label), ev.label, ev.t_s, line, _implied(ev.label))
            _add_stage_value(log, ev, line, source)
        elif ev.kind == "phase_end":
            if open_phase is None or exercise_id(ev.label) != open_phase[0]:
                found = f"phase {open_phase[1]!r} open" if open_phase else "no phase open"
                raise SessionFormatError(f"{source}: line {line}: phase_end {ev.label!r}: expected the end "
                                         f"of an open phase of that exercise, found {found}")
            log.phases.append(Phase(*open_phase[:2], open_phase[2], ev.t_s, *open_phase[3:]))
            open_phase = None
        elif ev.kind == "load" and _LEGACY_STAGE_VALUE.match(ev.value):
            _add_stage_value(log, ev, line, source)
        elif ev.kind == "load":
            _add_load(log, ev, line, source)
        elif ev.kind in PARAMETER_KINDS or ev.kind == "reps":
            value = _number(ev, line, source, signed=ev.kind in SIGNED_PARAMETERS)
            log.parameters.setdefault((exercise_id(ev.label), ev.kind), []).append(Change(ev.t_s, value, line))
    if open_phase is not None:
        log.phases.append(Phase(*open_phase[:2], open_phase[2], math.inf, *open_phase[3:]))
    return log


def _implied(label: str) -> dict[str, float]:
    """Parameters carried by a legacy label (``walk 1.5 m/s`` -> speed 1.5)."""
    gait = _LEGACY_GAIT.match(label.strip().lower())
    return {"speed_m_s": float(gait[2])} if gait else {}


def _add_stage_value(log: ExerciseLog, ev: Event, line: int, source: str) -> None:
    """The Capture stage's ``load_kg=X;speed_kmh=Y`` value: X as machine_kg, Y / 3.6 as the speed."""
    stage = _LEGACY_STAGE_VALUE.match(ev.value)
    if not stage:
        return
    load = _number(Event(ev.t_s, "load", "machine_kg", stage[1]), line, source)
    speed = _number(Event(ev.t_s, "speed", ev.label, stage[2]), line, source)
    log.loads.setdefault("machine_kg", []).append(Change(ev.t_s, load, line))
    log.parameters.setdefault((exercise_id(ev.label), "speed"), []).append(Change(ev.t_s, speed / 3.6, line))


def _add_load(log: ExerciseLog, ev: Event, line: int, source: str) -> None:
    """Append a load row to its label's timeline (SessionFormatError for an unknown label)."""
    if ev.label not in LOAD_LABELS:
        raise SessionFormatError(f"{source}: line {line}: load label: expected one of "
                                 f"{', '.join(LOAD_LABELS)}, found {ev.label!r}")
    log.loads.setdefault(ev.label, []).append(Change(ev.t_s, _number(ev, line, source), line))


def _number(ev: Event, line: int, source: str, *, signed: bool = False) -> float:
    """The value of a parameter row as a finite number (>= 0 unless ``signed``)."""
    unit = {"speed": "m/s", "grade": "%", "power": "W", "cadence": "per minute", "rom": "m", "reps": "",
            "load": "kg"}[ev.kind]
    try:
        value = float(ev.value)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (value < 0 and not signed):
        expected = "a number" if signed else "a number >= 0"
        raise SessionFormatError(f"{source}: line {line}: {ev.kind} {ev.label}: expected {expected}"
                                 f"{' ' + unit if unit else ''}, found {ev.value!r}")
    return value
