"""The lab's participant registry: ``participants.tsv`` in the lab (``--out``) folder, BIDS-like.

Columns (tab-separated, ``n/a`` for a value not measured; DESIGN.md)::

    participant_id  sex  age  height_m  mass_kg  training_level  hr_rest_bpm  hr_max_bpm

Demographics are entered once per participant and then picked by code. One truth per participant:
:func:`lab_registry` reads ``participants.tsv``, or, in a lab without one, builds the registry from
the lab's own sessions (each code's latest ``session.json``). :func:`resolve_participant` fills what
the capture options leave out from that registry, refuses options that contradict it
(:class:`ParticipantConflict`, naming every differing field with both values) unless the record is
changed on purpose, and says which required fields are still missing. :func:`save_participant`
writes a new participant, or a changed record whose previous values are kept, dated, in
``participants_history.tsv`` (earlier sessions keep the copy in their own ``session.json``).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import math
import os
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text
from effortface.core.session.folder import Participant, SessionFormatError, list_sessions, read_session_info

REGISTRY_TSV = "participants.tsv"
#: previous records of participants whose record was changed on purpose (COLUMNS + ``replaced_utc``)
HISTORY_TSV = "participants_history.tsv"
COLUMNS = ("participant_id", "sex", "age", "height_m", "mass_kg", "training_level", "hr_rest_bpm", "hr_max_bpm")
#: participant fields a capture cannot go without -> the capture option that gives each
REQUIRED = {"sex": "--sex", "age": "--age", "height_m": "--height", "mass_kg": "--mass",
            "training_level": "--training-level"}
MISSING = "n/a"
#: how long a capture waits for another one registering in the same lab folder, seconds
LOCK_TIMEOUT_S = 5.0


#: what a refused capture tells the user to do to change a record on purpose
UPDATE_HINT = "pass --update-participant to change the record (earlier sessions keep theirs)"


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
    lines = _registry_lines(path)
    header = [cell.strip() for cell in lines[0].split("\t")] if lines else []  # "mass_kg " as Excel may save it
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


#: how UTF-16 text begins (Excel's "Unicode Text"), named rather than shown as an undecodable byte
UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")


def _registry_lines(path: Path) -> list[str]:
    """The lines of a participants.tsv saved as UTF-8, with or without a byte-order mark (Excel's "CSV
    UTF-8" writes one); RegistryError naming a UTF-16 file's byte-order mark or another encoding."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RegistryError(f"{path}: expected a tab-separated participants.tsv, found {exc}") from None
    if raw.startswith(UTF16_BOMS):
        raise RegistryError(f"{path}: expected UTF-8 text, found UTF-16 (a byte-order mark {raw[:2].hex(' ').upper()}, "
                            "as Excel's \"Unicode Text\" saves it): save it as UTF-8 (\"CSV UTF-8\" or tab-separated)")
    try:
        return raw.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise RegistryError(f"{path}: expected a tab-separated participants.tsv, found {exc}") from None


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


class ParticipantConflict(RegistryError):
    """Options that differ from the lab's record of a code; every differing field is named.

    Attributes
    ----------
    code : str
        The participant code.
    record : Participant
        The lab's record.
    source : str
        Where the record comes from (``participants.tsv`` or the session it was read from).
    differences : list of (field, record value, given value)
        Each field whose given value differs from the record.
    """

    def __init__(self, code: str, record: Participant, source: str,
                 differences: list[tuple[str, object, object]], hint: str = UPDATE_HINT) -> None:
        self.code, self.record, self.source, self.differences = code, record, source, differences
        super().__init__(conflict_message(code, source, differences, hint))


def conflict_message(code: str, source: str, differences: list[tuple[str, object, object]],
                     hint: str = UPDATE_HINT) -> str:
    """One line: the lab's record of ``code`` and what was found instead, field by field."""
    expected = ", ".join(f"{f} {_cell(r)}" for f, r, _ in differences)
    found = ", ".join(f"{f} {_cell(g)}" for f, _, g in differences)
    return (f"participant {code}: expected the lab's record ({expected} in {source}), found {found}"
            + (f"; {hint}" if hint else ""))


def differences(record: Participant, values: Mapping[str, object]) -> list[tuple[str, object, object]]:
    """The fields of ``values`` (None: not given) that differ from ``record`` where it has a value.

    Returns
    -------
    list of (field, record value, given value)
        In registry column order.
    """
    out = []
    for column in COLUMNS[1:]:
        given, stored = values.get(column), getattr(record, column)
        if given is not None and stored is not None and _differs(stored, given):
            out.append((column, stored, given))
    return out


def lab_registry(lab_dir: str | os.PathLike) -> dict[str, Participant]:
    """The lab's participants: ``participants.tsv``, and each code it lacks (all codes, in a lab
    without one) from that code's latest session.

    Parameters
    ----------
    lab_dir : path-like
        The lab folder (``--out``): holds the registry and the session folders.

    Returns
    -------
    dict
        participant code -> :class:`Participant` (empty for a lab with neither).

    Raises
    ------
    RegistryError
        A participants.tsv that cannot be read (the message names the file and line).
    """
    return dict(lab_records(lab_dir)[0])


def lab_records(lab_dir: str | os.PathLike) -> tuple[dict[str, Participant], dict[str, str]]:
    """:func:`lab_registry` and, per code, where its record comes from (the file to name in a message)."""
    lab = Path(lab_dir)
    path = lab / REGISTRY_TSV
    people: dict[str, Participant] = {}
    source: dict[str, str] = {}
    for person, session_json in _session_records(lab):  # oldest first: the latest session wins
        people[person.code], source[person.code] = person, str(session_json)
    if path.exists():  # the registry's rows win; a code it lacks keeps its sessions' record
        registered = read_registry(path)
        people.update(registered)
        source.update(dict.fromkeys(registered, str(path)))
    return people, source


def _session_records(lab: Path) -> list[tuple[Participant, Path]]:
    """Each session's participant with its session.json, oldest first (by created_utc, then name);
    sessions that cannot be read are left out (recovery and validation report them)."""
    if not lab.is_dir():
        return []
    found = []
    for folder in list_sessions(lab):
        try:
            info = read_session_info(folder)
        except (SessionFormatError, UserError):
            continue
        found.append((info.created_utc, folder.name, info.participant, folder / "session.json"))
    return [(person, path) for _, _, person, path in sorted(found, key=lambda r: (r[0], r[1]))]


def resolve_participant(code: str, options: Mapping[str, object], registry_path: str | os.PathLike,
                        *, update: bool = False, hint: str = UPDATE_HINT) -> tuple[Participant, bool]:
    """The participant for a capture: the options, completed from the lab's record.

    Parameters
    ----------
    code : str
        ``--participant``.
    options : mapping
        Participant fields given on the command line (None: not given).
    registry_path : path-like
        ``participants.tsv`` of the lab folder (read through :func:`lab_registry` of its folder).
    update : bool
        Options that differ from the record change it on purpose (``--update-participant``).
    hint : str
        What the refusal tells the user to do to change the record.

    Returns
    -------
    (Participant, bool)
        The participant, and True if it must be saved with :func:`save_participant` (a new code, or
        a record changed on purpose).

    Raises
    ------
    ParticipantConflict
        An option that differs from the lab's record (without ``update``).
    RegistryError
        A bad registry, or required fields that neither the options nor the record give (all of
        them named, as capture options).
    """
    registry_path = Path(registry_path)
    people, sources = lab_records(registry_path.parent)
    known = people.get(code)
    values = {k: v for k, v in options.items() if v is not None}
    changed = False
    if known is not None:
        diff = differences(known, values)
        if diff and not update:
            raise ParticipantConflict(code, known, sources[code], diff, hint)
        changed = bool(diff)
        values = {**{f: getattr(known, f) for f in (*REQUIRED, "hr_rest_bpm", "hr_max_bpm")
                     if getattr(known, f) is not None}, **values}
    missing = [option for field, option in REQUIRED.items() if values.get(field) is None]
    if missing:
        raise RegistryError(f"participant {code}: expected {', '.join(missing)} (or a row for {code} in "
                            f"{registry_path}), found none")
    try:
        return Participant(code=code, **values), known is None or changed  # type: ignore[arg-type]
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


def save_participant(registry_path: str | os.PathLike, participant: Participant,
                     when: dt.datetime | None = None) -> Path:
    """Write ``participant`` to the lab's registry: a new row, or its code's row replaced.

    The file is written with every participant the lab knows (:func:`lab_registry`: codes known
    only from sessions join it), so that the lab's participants stay known; a new code alone is
    appended (the file's text kept). A replaced row that differs is appended to
    ``participants_history.tsv`` with the time it was replaced; sessions keep their own copy.

    Parameters
    ----------
    registry_path : path-like
        ``participants.tsv`` of the lab folder.
    participant : Participant
        The record to keep.
    when : datetime, optional
        When the record changes (UTC; default now).

    Returns
    -------
    Path
        The registry.
    """
    registry_path = Path(registry_path)
    when = when or dt.datetime.now(dt.timezone.utc)
    with _locked(registry_path):
        people = lab_registry(registry_path.parent)
        registered = read_registry(registry_path) if registry_path.exists() else {}
        old = people.get(participant.code)
        if old == participant and participant.code in registered:
            return registry_path
        if old is not None and old != participant:
            _append_history(registry_path.with_name(HISTORY_TSV), old, when)
        people[participant.code] = participant
        if registry_path.exists() and old is None and set(registered) == set(people) - {participant.code}:
            text = registry_path.read_text(encoding="utf-8")
            text += ("" if text.endswith("\n") else "\n") + _line(participant) + "\n"
        else:
            text = "\n".join(["\t".join(COLUMNS), *(_line(people[c]) for c in sorted(people))]) + "\n"
        return atomic_write_text(registry_path, text)


def _append_history(path: Path, old: Participant, when: dt.datetime) -> None:
    """Append ``old`` to the history with the UTC time it was replaced (header written once)."""
    stamp = when.astimezone(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    text = path.read_text(encoding="utf-8") if path.exists() else "\t".join((*COLUMNS, "replaced_utc")) + "\n"
    atomic_write_text(path, text + _line(old) + "\t" + stamp + "\n")


def read_history(lab_dir: str | os.PathLike) -> list[tuple[Participant, str]]:
    """The records replaced on purpose, oldest first: (previous record, replaced_utc)."""
    path = Path(lab_dir) / HISTORY_TSV
    if not path.exists():
        return []
    out = []
    for n, text in enumerate(_registry_lines(path)[1:], start=2):
        if text.strip():
            cells = text.split("\t")
            out.append((_row(path, n, cells[:-1]), cells[-1].strip()))
    return out


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


def participant_options(args: argparse.Namespace) -> tuple[str, dict[str, object]]:
    """``--participant``'s checked code and the body options (``--sex``, ``--age``, ``--height``,
    ``--mass``, ``--training-level``) as the lab registry takes them (``capture``, ``import hr``)."""
    try:
        code = Participant(code=args.participant).code
    except UserError as exc:
        raise UserError(f"--participant: {exc}") from None
    return code, {"sex": args.sex, "age": args.age, "height_m": args.height, "mass_kg": args.mass,
                  "training_level": args.training_level}
