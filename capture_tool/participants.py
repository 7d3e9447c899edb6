"""The lab's participant registry: ``participants.tsv`` in the lab (``--out``) folder, BIDS-like.

Columns (tab-separated, ``n/a`` for a value not measured; DESIGN.md)::

    participant_id  sex  age  height_m  mass_kg  training_level  hr_rest_bpm  hr_max_bpm

Demographics are entered once per participant and then picked by code: :func:`resolve_participant`
fills what the capture options leave out from the registry, refuses an option that contradicts it,
and says which of the required fields are still missing. A new participant is appended with
:func:`register` (the whole file rewritten atomically). ``session.json`` keeps the copy used at
capture time.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text
from effortface.capture_tool.session import Participant

REGISTRY_TSV = "participants.tsv"
COLUMNS = ("participant_id", "sex", "age", "height_m", "mass_kg", "training_level", "hr_rest_bpm", "hr_max_bpm")
#: participant fields a capture cannot go without -> the capture option that gives each
REQUIRED = {"sex": "--sex", "age": "--age", "height_m": "--height", "mass_kg": "--mass",
            "training_level": "--training-level"}
MISSING = "n/a"
#: how long a capture waits for another one registering in the same lab folder, seconds
LOCK_TIMEOUT_S = 5.0


class RegistryError(UserError):
    """A participants.tsv that cannot be read, or options that contradict it; names the file."""


def read_registry(path: str | os.PathLike) -> dict[str, Participant]:
    """Read ``participants.tsv``; an absent file is an empty registry.

    Returns
    -------
    dict
        participant code -> :class:`Participant`.

    Raises
    ------
    RegistryError
        Bad header, a row of the wrong length, a value that is not valid for its column, or one
        participant on two rows that differ (the message names the file, lines and column).
    """
    path = Path(path)
    if not path.exists():
        return {}
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise RegistryError(f"{path}: expected a tab-separated participants.tsv, found {exc}") from None
    header = lines[0].split("\t") if lines else []
    if tuple(header) != COLUMNS:
        raise RegistryError(f"{path}: line 1: expected the header {' '.join(COLUMNS)} (tab-separated), "
                            f"found {' '.join(header) or 'nothing'}")
    out: dict[str, Participant] = {}
    first_line: dict[str, int] = {}
    for n, text in enumerate(lines[1:], start=2):
        if not text.strip():
            continue
        person = _row(path, n, text.split("\t"))
        if person.code in out and out[person.code] != person:
            field = next(f for f in COLUMNS[1:] if getattr(out[person.code], _attr(f)) != getattr(person, _attr(f)))
            raise RegistryError(f"{path}: line {n}: participant {person.code}: expected one row per participant "
                                f"(or identical rows), found {field} {_cell(getattr(person, _attr(field)))} here and "
                                f"{_cell(getattr(out[person.code], _attr(field)))} on line {first_line[person.code]}")
        out.setdefault(person.code, person)
        first_line.setdefault(person.code, n)
    return out


def _attr(column: str) -> str:
    """The Participant attribute of a registry column."""
    return "code" if column == "participant_id" else column


def _row(path: Path, line: int, cells: list[str]) -> Participant:
    """One registry row as a Participant (RegistryError naming the line otherwise)."""
    if len(cells) != len(COLUMNS):
        raise RegistryError(f"{path}: line {line}: expected {len(COLUMNS)} tab-separated columns, found {len(cells)}")
    values: dict[str, object] = {}
    for column, cell in zip(COLUMNS, (c.strip() for c in cells)):
        if cell in ("", MISSING):
            continue
        if column in ("participant_id", "sex"):
            values[_attr(column)] = cell
            continue
        try:
            values[column] = float(cell)
        except ValueError:
            raise RegistryError(f"{path}: line {line}: column {column}: expected a number or n/a, "
                                f"found {cell!r}") from None
    try:
        return Participant(**values)  # type: ignore[arg-type]
    except (UserError, TypeError) as exc:
        raise RegistryError(f"{path}: line {line}: {exc}") from None


def _cell(value: object) -> str:
    """A registry cell: ``n/a`` for None, numbers without a useless ``.0``."""
    if value is None:
        return MISSING
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:g}"
    return str(value)


def resolve_participant(code: str, options: Mapping[str, object], registry_path: str | os.PathLike
                        ) -> tuple[Participant, bool]:
    """The participant for a capture: the options, completed from the registry.

    Parameters
    ----------
    code : str
        ``--participant``.
    options : mapping
        Participant fields given on the command line (None: not given).
    registry_path : path-like
        ``participants.tsv`` of the lab folder.

    Returns
    -------
    (Participant, bool)
        The participant, and True if the registry does not know it yet (to :func:`register`).

    Raises
    ------
    RegistryError
        An option that differs from the registry's value, a bad registry, or required fields that
        neither the options nor the registry give (all of them named, as capture options).
    """
    registry_path = Path(registry_path)
    known = read_registry(registry_path).get(code)
    values = {k: v for k, v in options.items() if v is not None}
    if known is not None:
        for field, given in values.items():
            stored = getattr(known, field)
            if stored is not None and _differs(stored, given):
                option = REQUIRED.get(field, f"--{field.replace('_', '-')}")
                raise RegistryError(f"{option} {_cell(given)}: expected {_cell(stored)} as in {registry_path} for "
                                    f"{code} (demographics are entered once; edit the registry to change them)")
        values = {**{f: getattr(known, f) for f in (*REQUIRED, "hr_rest_bpm", "hr_max_bpm")
                     if getattr(known, f) is not None}, **values}
    missing = [option for field, option in REQUIRED.items() if values.get(field) is None]
    if missing:
        raise RegistryError(f"participant {code}: expected {', '.join(missing)} (or a row for {code} in "
                            f"{registry_path}), found none")
    try:
        return Participant(code=code, **values), known is None  # type: ignore[arg-type]
    except UserError as exc:
        raise RegistryError(f"--participant / body options: {exc}") from None


def _differs(stored: object, given: object) -> bool:
    """True if a given option differs from the registry's value (sex aliases and 1e-9 allowed)."""
    if isinstance(stored, str):
        return Participant(code="X1", sex=str(given)).sex != stored
    return abs(float(stored) - float(given)) > 1e-9  # type: ignore[arg-type]


def register(registry_path: str | os.PathLike, participant: Participant) -> Path:
    """Append ``participant`` to the registry (its text kept, rewritten atomically; created with its header).

    Raises
    ------
    RegistryError
        If the registry already has that code (use :func:`resolve_participant` first).
    """
    registry_path = Path(registry_path)
    with _locked(registry_path):
        people = read_registry(registry_path)
        if participant.code in people:
            raise RegistryError(f"{registry_path}: participant {participant.code}: expected a new code, "
                                f"found it registered")
        text = registry_path.read_text(encoding="utf-8") if registry_path.exists() else "\t".join(COLUMNS) + "\n"
        if not text.endswith("\n"):
            text += "\n"
        return atomic_write_text(registry_path, text + _line(participant) + "\n")


@contextlib.contextmanager
def _locked(registry_path: Path) -> Iterator[None]:
    """Hold ``.participants.tsv.lock`` beside the registry, so that two captures starting together
    in one lab folder do not lose each other's row (a lock file: portable, no fcntl)."""
    lock = registry_path.with_name(f".{registry_path.name}.lock")
    deadline = time.monotonic() + LOCK_TIMEOUT_S
    while True:
        try:
            os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            break
        except FileExistsError:
            if time.monotonic() > deadline:
                raise RegistryError(f"{lock}: expected the registry lock to be released within "
                                    f"{LOCK_TIMEOUT_S:g} s, found it held (remove it if no capture is "
                                    f"starting)") from None
            time.sleep(0.01)
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)


def _line(p: Participant) -> str:
    """One registry line."""
    return "\t".join(_cell(getattr(p, _attr(c))) for c in COLUMNS)
