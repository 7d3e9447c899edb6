"""The exercise catalog: how w and p (W/kg) are estimated from what the exercise log says.

The entries are data (``effortface/core/data/exercise_catalog.csv``, one row per exercise id, with
the source of every number; in the core because capture logs and plans exercises by the same ids);
this module reads them and applies their model. The models (``model`` column):

* ``constant``: ``w = w_ref``.
* ``gait``: ``w = w_ref * v / v_ref + g * v * grade / 100`` (lifting the body up the slope).
* ``treadmill``: ``gait`` with the walk entry below :data:`WALK_RUN_SPEED_M_S` and the run entry from it.
* ``reps``: ``w = w_ref * pace / pace_ref``; the work of one repetition is constant, so w follows the
  pace: the logged ``cadence``, else the pace of the ``reps`` rows, else ``pace_ref``.
* ``ergometer``: ``w = P / M + w_ref * cadence / cadence_ref``: the machine's power per kg plus the
  limbs' own segment work at that cadence.
* ``lift``: ``w = pace / 60 * 2 g L h / M + w_ref * pace / pace_ref``: the load L lifted and lowered
  over the range of motion h (no transfer: both count), plus the limbs.

Loads scale ``constant``, ``gait`` and ``reps`` as
``w * (1 + back_load_factor * back_kg / M + hand_load_factor * (left_kg + right_kg) / M)``, with the
factors measured on the reference clips (:mod:`effortface.synth.energy` with and without loads).
``p`` (the 0.25-s power) has w's mean over a cycle; the log gives no within-cycle detail, so
the estimate of p is w.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path

from effortface.core.errors import UserError
from effortface.core.exercises import CATALOG_CSV, read_catalog_rows
from effortface.synth.exercise_log import PhaseState

MODELS = ("constant", "gait", "treadmill", "reps", "ergometer", "lift")
#: walk-run transition of the ``treadmill`` entry, m/s (choice: the preferred transition speed)
WALK_RUN_SPEED_M_S = 2.0
#: range of motion of a ``lift`` when none is logged, m (choice)
DEFAULT_ROM_M = 0.5
G_M_PER_S2 = 9.81
_COLUMNS = ("id", "family", "model", "w_ref_per_kg", "ref_value", "ref_unit", "back_load_factor",
            "hand_load_factor", "source")


class CatalogError(UserError):
    """An exercise id or parameter the catalog cannot estimate; the message names the catalog."""


@dataclasses.dataclass(frozen=True)
class Exercise:
    """One catalog entry (see the module docstring for the models)."""

    id: str
    family: str
    model: str
    w_ref_per_kg: float
    ref_value: float
    ref_unit: str
    back_load_factor: float
    hand_load_factor: float
    source: str

    @property
    def keys(self) -> tuple[str, ...]:
        """Log labels whose parameters apply to this exercise: its id, then its family."""
        return (self.id, self.family) if self.family else (self.id,)


@dataclasses.dataclass(frozen=True)
class Catalog:
    """The exercise catalog read from a CSV file."""

    path: Path
    entries: Mapping[str, Exercise]

    def __getitem__(self, exercise_id: str) -> Exercise:
        try:
            return self.entries[exercise_id]
        except KeyError:
            raise CatalogError(f"exercise {exercise_id!r}: expected an id of the catalog {self.path} "
                               f"({', '.join(self.entries)})") from None

    def __contains__(self, exercise_id: object) -> bool:
        return exercise_id in self.entries

    def keys_for(self, exercise_id: str) -> tuple[str, ...]:
        """Log labels whose parameters apply to ``exercise_id`` (the treadmill gaits share ``treadmill``)."""
        entry = self[exercise_id]
        if entry.model == "treadmill":
            return (entry.id, "treadmill_walk", "treadmill_run")
        return entry.keys

    def work_per_kg(self, exercise_id: str, state: PhaseState, mass_kg: float) -> float:
        """w (W/kg) of ``exercise_id`` under ``state`` for a body of ``mass_kg``.

        Parameters
        ----------
        exercise_id : str
            A catalog id.
        state : PhaseState
            The logged parameters and loads in force.
        mass_kg : float
            The participant's body mass M.

        Returns
        -------
        float

        Raises
        ------
        CatalogError
            Unknown id, or a parameter the model needs (speed, power) not logged.
        """
        entry = self[exercise_id]
        if entry.model == "treadmill":
            speed = _required(entry, state.speed_m_s, "speed", "m/s", self.path)
            gait = "treadmill_walk" if speed < WALK_RUN_SPEED_M_S else "treadmill_run"
            return self.work_per_kg(gait, state, mass_kg)
        return _ESTIMATORS[entry.model](entry, state, mass_kg, self.path)


def _required(entry: Exercise, value: float | None, kind: str, unit: str, path: Path) -> float:
    """``value``, or a CatalogError saying the exercise needs a ``kind`` row in the log."""
    if value is None:
        raise CatalogError(f"exercise {entry.id!r} ({entry.model} in {path}): expected a {kind} row "
                           f"({unit}) in the exercise log, found none")
    return value


def _load_scale(entry: Exercise, state: PhaseState, mass_kg: float) -> float:
    """1 + the clip-measured effect of the carried loads."""
    hands = state.load_kg("left_kg") + state.load_kg("right_kg")
    return 1.0 + (entry.back_load_factor * state.load_kg("back_kg") + entry.hand_load_factor * hands) / mass_kg


def _pace(entry: Exercise, state: PhaseState) -> float:
    """Repetitions (strokes, steps) per minute: cadence, else the reps' pace, else the reference."""
    for pace in (state.cadence_per_min, state.reps_per_min):
        if pace is not None:
            return pace
    return entry.ref_value


def _constant(entry: Exercise, state: PhaseState, mass_kg: float, path: Path) -> float:
    return entry.w_ref_per_kg * _load_scale(entry, state, mass_kg)


def _gait(entry: Exercise, state: PhaseState, mass_kg: float, path: Path) -> float:
    speed = _required(entry, state.speed_m_s, "speed", "m/s", path)
    grade = state.grade_pct or 0.0
    level = entry.w_ref_per_kg * speed / entry.ref_value * _load_scale(entry, state, mass_kg)
    return max(level + G_M_PER_S2 * speed * grade / 100.0, 0.0)


def _reps(entry: Exercise, state: PhaseState, mass_kg: float, path: Path) -> float:
    return entry.w_ref_per_kg * _pace(entry, state) / entry.ref_value * _load_scale(entry, state, mass_kg)


def _ergometer(entry: Exercise, state: PhaseState, mass_kg: float, path: Path) -> float:
    power = _required(entry, state.power_w, "power", "W", path)
    return power / mass_kg + entry.w_ref_per_kg * _pace(entry, state) / entry.ref_value


def _lift(entry: Exercise, state: PhaseState, mass_kg: float, path: Path) -> float:
    pace = _pace(entry, state)
    load = sum(kg for _, kg in state.loads_kg)
    rom = state.rom_m if state.rom_m is not None else DEFAULT_ROM_M
    return pace / 60.0 * 2 * G_M_PER_S2 * load * rom / mass_kg + entry.w_ref_per_kg * pace / entry.ref_value


_ESTIMATORS = {"constant": _constant, "gait": _gait, "reps": _reps, "ergometer": _ergometer, "lift": _lift}


def read_catalog(path: str | os.PathLike = CATALOG_CSV) -> Catalog:
    """Read an exercise catalog CSV (``#`` lines are comments).

    Parameters
    ----------
    path : path-like
        Default: the catalog shipped with effortface.

    Returns
    -------
    Catalog

    Raises
    ------
    CatalogError
        Missing columns, an unknown model, a repeated id, a family that is not an id, or a number
        that is not finite (``w_ref_per_kg``, ``ref_value`` > 0 where the model uses them).
    """
    path = Path(path)
    try:
        rows = read_catalog_rows(path)
    except UserError as exc:
        raise CatalogError(str(exc)) from None
    if not rows or any(c not in rows[0] for c in _COLUMNS):
        raise CatalogError(f"{path}: expected columns {','.join(_COLUMNS)}, found "
                           f"{','.join(rows[0]) if rows else 'no rows'}")
    entries: dict[str, Exercise] = {}
    for line, row in enumerate(rows, start=2):
        entry = _entry(path, line, row)
        if entry.id in entries:
            raise CatalogError(f"{path}: row {line}: expected a new id, found {entry.id!r} again")
        entries[entry.id] = entry
    for entry in entries.values():
        if entry.family and entry.family not in entries:
            raise CatalogError(f"{path}: {entry.id}: family: expected an id of the catalog, found {entry.family!r}")
    return Catalog(path, entries)


def _entry(path: Path, line: int, row: Mapping[str, str]) -> Exercise:
    """One catalog row, checked."""
    if row["model"] not in MODELS:
        raise CatalogError(f"{path}: row {line}: model: expected one of {', '.join(MODELS)}, found {row['model']!r}")
    numbers = {}
    for col in ("w_ref_per_kg", "ref_value", "back_load_factor", "hand_load_factor"):
        text = (row[col] or "0").strip()
        try:
            numbers[col] = float(text)
        except ValueError:
            numbers[col] = math.nan
        needs_positive = col == "ref_value" and row["model"] not in ("constant",)
        if not math.isfinite(numbers[col]) or numbers[col] < 0 or (needs_positive and numbers[col] <= 0):
            raise CatalogError(f"{path}: row {line}: {col}: expected a number >= 0 (> 0 for ref_value), "
                               f"found {row[col]!r}")
    return Exercise(row["id"].strip(), (row["family"] or "").strip(), row["model"], numbers["w_ref_per_kg"],
                    numbers["ref_value"], row["ref_unit"], numbers["back_load_factor"],
                    numbers["hand_load_factor"], row["source"])


_DEFAULT: Catalog | None = None


def default_catalog() -> Catalog:
    """The catalog shipped with effortface (read once)."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = read_catalog()
    return _DEFAULT
