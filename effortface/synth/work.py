"""Work and power per second of a session: from motion/ where clips cover the time, else from the log.

``work.csv`` (``t_s,w_per_kg,p_per_kg,source`` at 1 Hz, t_s = 0, 1, 2, ... to the end of the heart
rate or video) is what :func:`derive_work` computes and :func:`write_work` saves. ``source`` says
where each second comes from: ``motion:<clip>``, ``log:<exercise id>``, or empty (no clip and no
phase covers it: w and p are empty). The same function feeds training when a session has no
work.csv (:mod:`effortface.train.dataset`), so a captured session trains with no extra step.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from typing import TYPE_CHECKING

import numpy as np

from effortface.core.errors import UserError
from effortface.core import bounds
from effortface.core.fileio import atomic_write_text, read_json
from effortface.core.session.folder import SESSION_JSON, Session, list_sessions, read_session
from effortface.synth.catalog import Catalog, CatalogError, default_catalog
from effortface.synth.exercise_log import ExerciseLog, exercise_log
from effortface.synth.read_options import MotionReadOptions, check_unit_m, check_up

if TYPE_CHECKING:  # the energies load scipy: imported only when a session has motion
    from effortface.synth.energy import EnergyCurves
    from effortface.synth.motion import Motion

WORK_CSV = "work.csv"
WORK_HEADER = "t_s,w_per_kg,p_per_kg,source"
MOTION_DIR = "motion"
MOTION_JSON = "motion.json"


class WorkError(UserError):
    """A session whose work cannot be derived; the message names the session or file."""


class NoWorkSource(WorkError):
    """A session with nothing to derive work from (no motion/, no exercise phase): not an error in
    its files, so ``export bids`` states the omission instead of refusing."""


@dataclasses.dataclass(frozen=True)
class WorkTable:
    """w and p per second of one session.

    Attributes
    ----------
    t_s, w_per_kg, p_per_kg : ndarray
        1 Hz; NaN where nothing covers the second.
    source : list of str
        Per second: ``motion:<clip>``, ``log:<exercise id>`` or ``""``.
    """

    t_s: np.ndarray
    w_per_kg: np.ndarray
    p_per_kg: np.ndarray
    source: list[str]

    def to_csv(self) -> str:
        """The work.csv text."""
        out = io.StringIO()
        out.write(WORK_HEADER + "\n")
        for t, w, p, src in zip(self.t_s, self.w_per_kg, self.p_per_kg, self.source):
            out.write(f"{t:g},{_num(w)},{_num(p)},{src}\n")
        return out.getvalue()


def _num(x: float) -> str:
    """A CSV cell: 4 decimals, empty for NaN."""
    return "" if math.isnan(x) else f"{x:.4f}"


#: the columns every work.csv has (``source`` is optional)
WORK_COLUMNS = ("t_s", "w_per_kg", "p_per_kg")
#: cells read as "no value" (NaN) in the w and p columns besides an empty cell
_MISSING = ("", "nan", "n/a")


def read_work_csv(path: str | os.PathLike) -> WorkTable:
    """Read a ``work.csv`` (as :meth:`WorkTable.to_csv` writes it, as ``import xdf`` writes it, or
    hand-made with the first three columns): the one checked reader of the file, used by every
    command that reads it (``export bids``, ``train``, ``demo``).

    Empty (or ``nan``, ``n/a``) w/p cells become NaN, a missing ``source`` column becomes empty
    strings; a UTF-8 byte-order mark is accepted. Times need not be regular (an imported stream
    may have drop-outs) but must increase.

    Raises
    ------
    WorkError
        One line naming the file (and its line and field): not a regular file, not UTF-8 CSV text,
        missing columns, no rows, a short row, a cell that is not a number, a number outside the
        bounds table (``t_s``, ``w_per_kg``, ``p_per_kg`` of :mod:`effortface.core.bounds`), a time
        not after the one before.
    """
    import csv

    from effortface.core.errors import not_text_error
    from effortface.core.fileio import check_regular_file

    path = check_regular_file(path, "a work CSV file (t_s,w_per_kg,p_per_kg)", WorkError)
    cols: dict[str, list[float]] = {c: [] for c in WORK_COLUMNS}
    source: list[str] = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            header = [(f or "").strip() for f in reader.fieldnames or []]
            if any(c not in header for c in WORK_COLUMNS):
                raise WorkError(f"{path}: expected a header with columns {','.join(WORK_COLUMNS)}, "
                                f"found {','.join(header) if header else 'an empty file'!r}")
            reader.fieldnames = header
            for row in reader:
                _work_row(path, reader.line_num, row, cols, source)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise WorkError(str(not_text_error(path, exc))) from None
    if not source:
        raise WorkError(f"{path}: expected rows of {','.join(WORK_COLUMNS)}, found none")
    t_s, w, p = (np.array(cols[c]) for c in WORK_COLUMNS)
    return WorkTable(t_s, w, p, source)


def _work_row(path: Path, line: int, row: dict, cols: dict[str, list[float]], source: list[str]) -> None:
    """Check one work.csv row (``line``) and append it to ``cols`` and ``source``."""
    if any(row.get(c) is None for c in WORK_COLUMNS):
        raise WorkError(f"{path}: line {line}: expected the fields {','.join(WORK_COLUMNS)}, "
                        f"found a row of {sum(v is not None for k, v in row.items() if k is not None)} fields")
    for c in WORK_COLUMNS:
        cell = row[c].strip()
        if c != "t_s" and cell.lower() in _MISSING:
            cols[c].append(math.nan)
            continue
        try:
            value = float(cell)
        except ValueError:
            raise WorkError(f"{path}: line {line}: {c}: expected a number, found {cell!r:.40}") from None
        try:
            cols[c].append(bounds.check(c, value, f"{path}: line {line}: {c}"))
        except UserError as exc:
            raise WorkError(str(exc)) from None
    t = cols["t_s"]
    if len(t) > 1 and not t[-1] > t[-2]:
        raise WorkError(f"{path}: line {line}: t_s: expected times increasing (rows sorted by time), "
                        f"found {t[-1]:g} after {t[-2]:g}")
    source.append((row.get("source") or "").strip())


def session_seconds(s: Session) -> np.ndarray:
    """t_s = 0, 1, ... to the last heart-rate sample or video frame (or the last logged event)."""
    ends = [h.t_s for h in s.heart_rate[-1:]] + s.frame_times_s[-1:] + [e.t_s for e in s.events[-1:]]
    return np.arange(0.0, math.floor(max(ends, default=0.0)) + 1.0)


def derive_work(session: Session | str | os.PathLike, t_s: np.ndarray | None = None,
                catalog: Catalog | None = None, mapping: str | os.PathLike | None = None,
                read: MotionReadOptions | None = None) -> WorkTable:
    """w and p per second from ``motion/`` where clips cover the time, else from the exercise log.

    Parameters
    ----------
    session : Session or path-like
        A read session or its folder.
    t_s : ndarray, optional
        The seconds wanted (default :func:`session_seconds`).
    catalog : Catalog, optional
        Default: the shipped catalog.
    mapping : path-like, optional
        Joint-to-segment mapping file for the clips of ``motion/`` whose motion.json entry has no
        ``mapping`` of its own (default: the built-in conventions).
    read : MotionReadOptions, optional
        ``--unit-m``, ``--up``, ``--trust-skeleton`` for the clips whose entry records no ``unit_m`` /
        ``up`` of its own (default: detected); every clip goes through the plausibility gate.

    Returns
    -------
    WorkTable

    Raises
    ------
    WorkError
        If the session has neither a motion/ folder nor a phase in its exercise log (the subclass
        :class:`NoWorkSource`), or a phase's
        exercise or parameters cannot be estimated (names events.csv, its line and the catalog).
    """
    s = session if isinstance(session, Session) else read_session(session)
    t = session_seconds(s) if t_s is None else np.asarray(t_s, dtype=float)
    log = exercise_log(s.events, str(s.path / "events.csv"))
    has_motion = (s.path / MOTION_DIR / MOTION_JSON).is_file()
    if not has_motion and not log.phases:
        raise NoWorkSource(f"{s.path}: expected a motion/ folder (motion.json) or exercise phases "
                        f"(phase_start rows in events.csv) to derive work, found neither")
    w, p = np.full(len(t), np.nan), np.full(len(t), np.nan)
    source = [""] * len(t)
    _fill_from_log(log, s.participant.mass_kg, t, w, p, source, catalog or default_catalog())
    if has_motion:
        _fill_from_motion(s, log, t, w, p, source, mapping, read)
    return WorkTable(t, w, p, source)


def _fill_from_log(log: ExerciseLog, mass_kg: float | None, t: np.ndarray, w: np.ndarray, p: np.ndarray,
                   source: list[str], catalog: Catalog) -> None:
    """Write each phase's catalog estimate into the seconds it covers."""
    if not log.phases:
        return
    if mass_kg is None:
        raise WorkError(f"{log.source}: expected the participant's mass_kg in session.json to estimate work "
                        f"from the exercise log, found none")
    for phase in log.phases:
        try:
            pieces = log.states(phase, catalog.keys_for(phase.exercise))
            for start, end, state in pieces:
                inside = np.flatnonzero((t >= start - 1e-9) & (t < end - 1e-9))
                value = catalog.work_per_kg(phase.exercise, state, mass_kg)
                w[inside] = p[inside] = value
                for i in inside:
                    source[i] = f"log:{phase.exercise}"
        except CatalogError as exc:
            raise WorkError(f"{log.source}: line {phase.line}: {exc}") from None


#: motion.json keys of a clip's loads, in the order of :class:`~effortface.synth.segments.Loads`
ENTRY_LOAD_KEYS = ("load_left_kg", "load_right_kg", "load_back_kg")
#: the exercise log's load labels in the same order
LOG_LOAD_LABELS = ("left_kg", "right_kg", "back_kg")


def _fill_from_motion(s: Session, log: ExerciseLog, t: np.ndarray, w: np.ndarray, p: np.ndarray,
                      source: list[str], mapping: str | os.PathLike | None = None,
                      read: MotionReadOptions | None = None) -> None:
    """Overwrite the seconds that a clip of ``motion/motion.json`` covers with its energies.

    A clip's segments come from its entry's ``mapping`` (kept by ``motion attach --mapping``), else
    ``mapping``, else the built-in conventions; its unit and up axis from its entry's ``unit_m`` /
    ``up`` (kept by ``motion attach``), else ``read``'s, else detected. Every clip goes through the
    plausibility gate (:func:`effortface.synth.plausibility.check_read`).

    A clip's loads are its entry's ``load_*_kg`` keys when it has any (earlier releases), else the
    exercise log's ``load`` rows in force at each second: one energy computation per distinct set.
    """
    index = s.path / MOTION_DIR / MOTION_JSON
    part = s.participant
    if part.mass_kg is None or part.sex is None:
        raise WorkError(f"{s.path / 'session.json'}: expected the participant's mass_kg and sex to compute "
                        f"work from motion/, found {part.mass_kg!r} and {part.sex!r}")
    read = read or MotionReadOptions()
    for entry in read_motion_index(index):
        clip_path = index.parent / str(entry["path"])
        try:
            _fill_from_clip(clip_path, entry, log, (part.mass_kg, part.sex), t, w, p, source, mapping, read)
        except UserError as exc:  # the clip named (a reader names it; a mapping or energy error may not)
            raise type(exc)(str(exc) if str(clip_path) in str(exc) else f"{clip_path}: {exc}") from None


def _fill_from_clip(clip_path: Path, entry: dict, log: ExerciseLog, body: tuple[float, str], t: np.ndarray,
                    w: np.ndarray, p: np.ndarray, source: list[str], mapping: str | os.PathLike | None,
                    read: MotionReadOptions) -> None:
    """:func:`_fill_from_motion` for one clip of motion.json (``entry``) read from ``clip_path`` with the
    entry's ``unit_m``, ``up`` and ``trust_skeleton`` (kept by ``motion attach``), else ``read``'s,
    through the plausibility gate."""
    from effortface.synth.plausibility import read_checked

    segments = _segment_mapping(entry.get("mapping") or mapping, clip_path)
    options = MotionReadOptions(
        unit_m=entry["unit_m"] if entry.get("unit_m") is not None else read.unit_m,
        up=entry["up"] if entry.get("up") is not None else read.up,
        mapping=segments, trust_skeleton=bool(entry.get("trust_skeleton")) or read.trust_skeleton)
    clip, _ = read_checked(clip_path, options)
    offset_s = float(entry.get("offset_s", 0.0))
    inside = np.flatnonzero((t >= offset_s) & (t <= offset_s + (clip.n_frames - 1) / clip.fps))
    if any(k in entry for k in ENTRY_LOAD_KEYS):
        loads = [tuple(float(entry.get(k, 0.0)) for k in ENTRY_LOAD_KEYS)] * len(inside)
    else:
        loads = [tuple(_log_load(log, label, t[i]) for label in LOG_LOAD_LABELS) for i in inside]
    for load in sorted(set(loads)):
        rows = inside[[k for k, x in enumerate(loads) if x == load]]
        curves = _clip_curves(clip, *body, load, segments, clip_path)
        w[rows] = np.interp(t[rows], curves.t_s + offset_s, curves.w_per_kg)
        p[rows] = np.interp(t[rows], curves.t_s + offset_s, curves.p_per_kg)
    for i in inside:
        source[i] = f"motion:{entry['path']}"


def read_clip(path: str | os.PathLike, *, unit_m: float | None = None, up: str | None = None) -> Motion:
    """:func:`effortface.synth.motion.read_motion` with the caller's unit and up axis (None: the file's own)."""
    from effortface.synth.motion import read_motion

    return read_motion(Path(path), unit_m=unit_m, up=up)


def _log_load(log: ExerciseLog, label: str, t_s: float) -> float:
    """The load of ``label`` logged last at or before ``t_s`` (0 kg when none)."""
    held = [c.value for c in log.loads.get(label, []) if c.t_s <= t_s + 1e-9]
    return held[-1] if held else 0.0


def _clip_curves(clip: Motion, mass_kg: float, sex: str, load: tuple[float, ...],
                 mapping: dict | str | os.PathLike | None = None, clip_path: Path | None = None) -> EnergyCurves:
    """Work and power of a clip for the participant's body carrying ``load`` (left, right, back kg);
    ``mapping`` a segment mapping (a motion.json entry's JSON form, or a file) or None for the
    built-in conventions."""
    from effortface.synth.energy import work_and_power
    from effortface.synth.segments import Loads, build_body

    where = clip_path if clip_path is not None else clip.source
    body = build_body(clip.joint_names, clip.parents, mass_kg, sex, loads=Loads(*load),
                      mapping=_segment_mapping(mapping, where), reference_positions_m=clip.positions_m,
                      source=where)
    return work_and_power(clip, body)


def _segment_mapping(mapping: dict | str | os.PathLike | None, where: str | os.PathLike) -> dict | Path | None:
    """A motion.json entry's mapping (its JSON form, versioned: :func:`~effortface.synth.segments.mapping_from_json`),
    an already read mapping, or ``--mapping``'s file, as :func:`~effortface.synth.segments.build_body` takes it."""
    from effortface.synth.segments import mapping_from_json

    if isinstance(mapping, dict):
        if all(isinstance(v, tuple) for v in mapping.values()):  # read already
            return mapping
        return mapping_from_json(mapping, f"{where}: motion.json mapping")
    return None if mapping is None else Path(mapping)


#: the motion.json format ``motion attach`` writes: version 2 (issue 34) adds ``"version"`` and the
#: entries' ``unit_m``, ``up``, ``trust_skeleton`` and a versioned ``mapping``; version 1 (no
#: ``"version"``) is read as before
MOTION_JSON_VERSION = 2
MOTION_ENTRY_NUMBERS = {"offset_s": ("offset_s", 0.0), "load_left_kg": ("load_kg", 0.0),
                        "load_right_kg": ("load_kg", 0.0), "load_back_kg": ("load_kg", 0.0)}


def read_motion_index(path: str | os.PathLike) -> list[dict]:
    """The entries of a session's ``motion/motion.json``: ``{"files": [{path, offset_s, load_*_kg}]}``.

    Version 2 (:data:`MOTION_JSON_VERSION`, ``"version": 2``) entries may also give ``unit_m``,
    ``up`` (read with them), ``trust_skeleton`` and ``mapping`` (a mapping file's JSON form,
    :func:`effortface.synth.segments.mapping_from_json`); version 1 files (no ``"version"``) read as before.

    Returns
    -------
    list of dict
        Each with ``path`` (str, relative to the file's folder), ``offset_s`` (default 0),
        ``unit_m`` and ``up`` (None when not given) and the ``load_*_kg`` keys the entry gives
        (checked; absent ones stay absent, so that the exercise log's loads apply), other keys as they are.

    Raises
    ------
    WorkError
        One line naming the file and the entry: not JSON, wrong shape, a value of the wrong type,
        a number outside the bounds table (:mod:`effortface.core.bounds`).
    """
    path = Path(path)
    doc = read_json(path, 'JSON {"files": [{path, offset_s}]}', WorkError)
    version = doc.get("version", 1) if isinstance(doc, dict) else 1
    if version not in (1, MOTION_JSON_VERSION) or isinstance(version, bool):
        raise WorkError(f"{path}: version: expected 1 or {MOTION_JSON_VERSION}, found {version!r}")
    files = doc.get("files") if isinstance(doc, dict) else None
    if not isinstance(files, list):
        raise WorkError(f'{path}: expected {{"files": [{{path, offset_s}}]}}, found {type(doc).__name__} '
                        f"without a files list")
    return [_motion_entry(path, i, e) for i, e in enumerate(files)]


def _motion_entry(path: Path, i: int, entry: object) -> dict:
    """One checked motion.json entry (see :func:`read_motion_index`)."""
    where = f"{path}: files[{i}]"
    if not isinstance(entry, dict) or not isinstance(entry.get("path"), str) or not entry["path"]:
        raise WorkError(f"{where}: expected {{path: str, offset_s: number}}, found {entry!r:.60}")
    out: dict = dict(entry)  # other keys (how the clip was aligned...) are kept as they are
    for key, (bound, default) in MOTION_ENTRY_NUMBERS.items():
        if key != "offset_s" and key not in entry:
            continue  # no load given: the exercise log's loads apply (see _fill_from_motion)
        try:
            out[key] = bounds.check(bound, entry.get(key, default), f"{where}.{key}")
        except UserError as exc:
            raise WorkError(str(exc)) from None
    try:  # how the clip was read when it was attached (None: detected)
        out["unit_m"] = check_unit_m(entry.get("unit_m"), f"{where}.unit_m")
        out["up"] = check_up(entry.get("up"), f"{where}.up")
    except UserError as exc:
        raise WorkError(str(exc)) from None
    if not isinstance(entry.get("mapping", {}), dict):
        raise WorkError(f"{where}.mapping: expected a mapping {{segment: [proximal, distal]}}, "
                        f"found {entry['mapping']!r:.60}")
    return out


def plan_work(folder: str | os.PathLike, *, force: bool = False,
              mapping: str | os.PathLike | None = None,
              read: MotionReadOptions | None = None) -> tuple[Path, WorkTable]:
    """Derive a session's work without writing it: the work.csv path and the table.

    Raises
    ------
    WorkError
        If work.csv exists and ``force`` is False, or see :func:`derive_work`.
    """
    s = read_session(folder)
    path = s.path / WORK_CSV
    if path.exists() and not force:
        raise WorkError(f"{path}: expected no work.csv (it may be hand-made), found one; "
                        f"use --force to replace it")
    return path, derive_work(s, mapping=mapping, read=read)


def write_work(folder: str | os.PathLike, *, force: bool = False) -> tuple[Path, WorkTable]:
    """Derive a session's work and save ``work.csv`` atomically.

    Parameters
    ----------
    folder : path-like
        The session folder.
    force : bool
        Replace an existing work.csv (which may be hand-made).

    Returns
    -------
    (Path, WorkTable)

    Raises
    ------
    WorkError
        If work.csv exists and ``force`` is False (nothing is written), or see :func:`derive_work`.
    """
    return write_works([folder], force=force)[0]


def work_folders(paths: Sequence[str | os.PathLike]) -> list[Path]:
    """Session folders from session folders and folders of sessions (UserError if none)."""
    out: list[Path] = []
    for p in map(Path, paths):
        out.extend([p] if (p / SESSION_JSON).is_file() or not p.is_dir() else list_sessions(p))
    if not out:
        raise UserError(f"{', '.join(map(str, paths))}: expected session folders, found none")
    return out


def write_works(folders: Sequence[str | os.PathLike], *, force: bool = False,
                mapping: str | os.PathLike | None = None,
                read: MotionReadOptions | None = None) -> list[tuple[Path, WorkTable]]:
    """``effortface work``: derive every session's work first (so a refusal writes nothing), then
    write each ``work.csv`` atomically; the paths and tables, in order (``mapping``, ``read``: see
    :func:`derive_work`)."""
    planned = [plan_work(folder, force=force, mapping=mapping, read=read) for folder in folders]
    for target, table in planned:
        atomic_write_text(target, table.to_csv())
    return planned
