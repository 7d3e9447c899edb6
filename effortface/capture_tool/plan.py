"""A protocol plan: timed exercise phases that a capture steps through and logs by itself.

``PLAN.csv`` (``#`` lines are comments)::

    start_s,end_s,exercise[,speed_m_s,grade_pct,power_w,cadence_per_min,rom_m,back_kg,left_kg,right_kg,machine_kg]

one row per phase, session seconds, an exercise id of the catalog, and the parameters to log at its
start (empty: not logged). Phases may leave gaps but must not overlap. While recording,
:class:`PlanRunner` writes, at each phase's start, ``phase_start`` and the exercise-log rows of its
parameters (``speed``, ``grade``, ``power``, ``cadence``, ``rom`` labelled with the exercise;
``load`` labelled ``back_kg`` ...), and ``phase_end`` at its end (DESIGN.md "Exercise log"); and it
announces what comes next with a countdown.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path

from effortface.core.errors import UserError, not_text_error
from effortface.core.exercises import check_exercise_id

#: plan column -> (events.csv kind, label: None = the exercise id)
PARAMETER_COLUMNS = {"speed_m_s": ("speed", None), "grade_pct": ("grade", None), "power_w": ("power", None),
                     "cadence_per_min": ("cadence", None), "rom_m": ("rom", None),
                     "back_kg": ("load", "back_kg"), "left_kg": ("load", "left_kg"),
                     "right_kg": ("load", "right_kg"), "machine_kg": ("load", "machine_kg")}
REQUIRED_COLUMNS = ("start_s", "end_s", "exercise")
#: seconds before a phase starts or ends at which the countdown speaks
COUNTDOWN_S = (10, 5, 3, 2, 1)


class PlanError(UserError):
    """A plan file that cannot be followed; the message names the file and line."""


@dataclasses.dataclass(frozen=True)
class PlannedPhase:
    """One row of a plan: ``exercise`` from ``start_s`` to ``end_s`` with its parameters."""

    start_s: float
    end_s: float
    exercise: str
    parameters: tuple[tuple[str, float], ...] = ()

    def describe(self) -> str:
        """``squats 30 s (back_kg 10)``."""
        params = ", ".join(f"{name} {value:g}" for name, value in self.parameters)
        return f"{self.exercise} {self.end_s - self.start_s:g} s" + (f" ({params})" if params else "")

    def events(self) -> list[tuple[str, str, str]]:
        """The ``(kind, label, value)`` rows logged at the phase's start, ``phase_start`` first."""
        return [("phase_start", self.exercise, ""), *parameter_events(self.exercise, self.parameters)]


def parameter_events(exercise: str, parameters: Sequence[tuple[str, float]]) -> list[tuple[str, str, str]]:
    """The exercise-log rows ``(kind, label, value)`` of some parameters of ``exercise``.

    Parameters
    ----------
    exercise : str
        Catalog id: the label of ``speed``, ``grade``, ``power``, ``cadence`` and ``rom`` rows.
    parameters : sequence of (column, value)
        Keys of :data:`PARAMETER_COLUMNS` (``speed_m_s``, ``back_kg``...) and their values.
    """
    out = []
    for name, value in parameters:
        kind, label = PARAMETER_COLUMNS[name]
        out.append((kind, label or exercise, f"{value:g}"))
    return out


def read_plan(path: str | os.PathLike) -> list[PlannedPhase]:
    """Read and check a plan file.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    list of PlannedPhase
        In time order.

    Raises
    ------
    PlanError
        Unreadable file, missing or unknown columns, no rows, an exercise not in the catalog, a
        time or parameter that is not a number, negative (grade may be), an end not after its start,
        or two phases that overlap; the message names the file and line.
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            lines = [(i + 1, line) for i, line in enumerate(fh) if line.strip() and not line.startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanError(f"--plan {path}: expected a readable plan CSV, found {exc}") from None
    if not lines:
        raise PlanError(f"--plan {path}: expected a header {','.join(REQUIRED_COLUMNS)},... and phases, found none")
    try:
        cells = [(n, next(csv.reader([text]))) for n, text in lines]
    except csv.Error as exc:  # a field over the csv module's limit
        raise PlanError(f"--plan {not_text_error(path, exc)}") from None
    header = [c.strip() for c in cells[0][1]]
    _check_header(path, lines[0][0], header)
    phases = [_phase(path, line, dict(zip(header, (c.strip() for c in row)))) for line, row in cells[1:]]
    if not phases:
        raise PlanError(f"--plan {path}: expected at least one phase after the header, found none")
    _check_overlaps(path, phases, [n for n, _ in lines[1:]])
    return sorted(phases, key=lambda p: p.start_s)


def _check_header(path: Path, line: int, header: list[str]) -> None:
    """PlanError for a missing required column or an unknown one."""
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    unknown = [c for c in header if c not in REQUIRED_COLUMNS and c not in PARAMETER_COLUMNS]
    if missing or unknown:
        raise PlanError(f"--plan {path}: line {line}: expected columns {','.join(REQUIRED_COLUMNS)} and any of "
                        f"{','.join(PARAMETER_COLUMNS)}, found {'missing ' + ','.join(missing) if missing else ''}"
                        f"{'; ' if missing and unknown else ''}{'unknown ' + ','.join(unknown) if unknown else ''}")


def _phase(path: Path, line: int, row: dict[str, str]) -> PlannedPhase:
    """One checked plan row."""
    where = f"--plan {path}: line {line}"
    start, end = (_value(where, row, c) for c in ("start_s", "end_s"))
    if start is None or end is None or not end > start:
        raise PlanError(f"{where}: expected 0 <= start_s < end_s, found start_s {row.get('start_s')!r}, "
                        f"end_s {row.get('end_s')!r}")
    try:
        exercise = check_exercise_id(row.get("exercise", ""), where)
    except UserError as exc:
        raise PlanError(str(exc)) from None
    params = tuple((c, v) for c in PARAMETER_COLUMNS if (v := _value(where, row, c)) is not None)
    return PlannedPhase(start, end, exercise, params)


def _value(where: str, row: dict[str, str], column: str) -> float | None:
    """A cell as a finite number (>= 0 except grade), None when empty."""
    text = (row.get(column) or "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (value < 0 and column != "grade_pct"):
        raise PlanError(f"{where}: column {column}: expected a number >= 0, found {text!r}")
    return value


def _check_overlaps(path: Path, phases: list[PlannedPhase], lines: list[int]) -> None:
    """PlanError naming the first two phases that overlap."""
    order = sorted(range(len(phases)), key=lambda i: phases[i].start_s)
    for a, b in zip(order, order[1:]):
        if phases[b].start_s < phases[a].end_s:
            raise PlanError(f"--plan {path}: line {lines[b]}: expected phases that do not overlap, found "
                            f"{phases[b].exercise} starting at {phases[b].start_s:g} s before "
                            f"{phases[a].exercise} (line {lines[a]}) ends at {phases[a].end_s:g} s")


class PlanRunner:
    """Steps through a plan on the session clock: logs its rows and speaks a countdown.

    Parameters
    ----------
    phases : list of PlannedPhase
    mark : callable
        ``mark(kind, label, value)`` writes one event now (``Recorder.mark``).
    say : callable
        Receives one countdown line at a time (the CLI prints it on stdout).
    """

    def __init__(self, phases: list[PlannedPhase], mark: Callable[[str, str, str], object],
                 say: Callable[[str], None]) -> None:
        self.phases = phases
        self._mark = mark
        self._say = say
        self._queue = sorted(self._schedule(), key=lambda item: (item[0], item[1]))
        self._open: PlannedPhase | None = None

    @property
    def end_s(self) -> float:
        """When the last phase ends."""
        return max(p.end_s for p in self.phases)

    @property
    def done(self) -> bool:
        """True once every row has been logged."""
        return not self._queue

    def _schedule(self) -> list[tuple[float, int, Callable[[], None]]]:
        """(due time, order, action): countdowns first at equal times, then ends, then starts."""
        out: list[tuple[float, int, Callable[[], None]]] = []
        for n, phase in enumerate(self.phases, start=1):
            title = f"phase {n}/{len(self.phases)} {phase.describe()}"
            for before in COUNTDOWN_S:
                if phase.start_s - before >= 0:
                    say = functools.partial(self._say, f"{title} starts in {before} s")
                    out.append((phase.start_s - before, 0, say))
                if phase.end_s - before > phase.start_s:
                    say = functools.partial(self._say, f"{phase.exercise} ends in {before} s")
                    out.append((phase.end_s - before, 0, say))
            out.append((phase.start_s, 2, functools.partial(self._start, phase, title)))
            out.append((phase.end_s, 1, functools.partial(self._end, phase)))
        return out

    def _start(self, phase: PlannedPhase, title: str) -> None:
        self._open = phase
        for kind, label, value in phase.events():
            self._mark(kind, label, value)
        self._say(f"{title}: go")

    def _end(self, phase: PlannedPhase) -> None:
        self._open = None
        self._mark("phase_end", phase.exercise, "")
        self._say(f"{phase.exercise}: stop")

    def step(self, now_s: float) -> None:
        """Do everything due by session time ``now_s`` (call it often, e.g. every 0.1 s)."""
        while self._queue and self._queue[0][0] <= now_s:
            self._queue.pop(0)[2]()

    def finish(self) -> None:
        """Stop stepping; a phase still open (the capture stopped early) gets its ``phase_end`` now."""
        if self._open is not None:
            self._end(self._open)
        self._queue.clear()
