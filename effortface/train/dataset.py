"""Training datasets: session folders or a long CSV table -> one row per participant-second.

The long format (DESIGN.md, ``--table CSV``)::

    participant,session,t_s,sex,age,height_m,mass_kg,training_level,w_per_kg,p_per_kg,hr_bpm,<blendshapes...>

one column per blendshape, empty where not annotated. Optional columns: ``exercise`` (for the
unseen-exercise protocol; default: the session id's label, e.g. ``cardio``), ``hr_rest_bpm`` and
``hr_max_bpm`` (measured values; they override the chart and the HR_max formula).

From a session folder (:func:`session_table`), each second ``t_s = 0, 1, 2, ...`` gets:

- ``w_per_kg``, ``p_per_kg`` from ``work.csv`` (previous value held), else derived the way
  ``effortface work`` does (:mod:`effortface.synth.work`: the clips of ``motion/motion.json`` where
  they cover the time, the exercise log and its catalog elsewhere; NaN where neither does);
- ``hr_bpm``: valid strap samples linearly interpolated, empty across gaps longer than
  ``MAX_HR_GAP_S`` (choice);
- blendshape weights from each rater's key-frames evaluated at the video frame nearest that second;
  the rater policy is ``"mean"`` (mean over the raters who annotated that blendshape) or one rater's
  name. Under either policy only **complete** tracks count (:mod:`effortface.annotate.completeness`:
  keys cover the video with no gap over 30 s and the rater finished the pass); a half-finished track
  is left out, never averaged in as a constant. Only the seconds a **person** labelled count as
  human labels: keys a rater accepted from the machine and did not edit (origin ``machine``,
  :mod:`effortface.annotate.keyframes`) are the machine's; a second whose nearest key is one of them
  has no human label. A session whose complete tracks hold nothing else is left out of the table
  (:class:`MachineLabelsOnly`), and the table says which (``table.attrs["left_out"]``) and how many
  seconds of each origin its labels have (``table.attrs["label_origins"]``: ``typed``, ``edited``,
  and ``machine`` left out).
  The raters are ``"humans"`` (default) or ``"humans+machine"``: then, per second and blendshape where
  no human label exists (no complete human track), the machine track's weight at the nearest frame
  (``machine/face_landmarker.csv`` from ``effortface preannotate``; none where it found no face) is the
  label, and the column ``machine_<blendshape>`` is True on those rows (:data:`MACHINE_PREFIX`).

:func:`prepare` then adds ``hr_rest_bpm``, ``hr_max_bpm``, ``nhr`` and ``epoc_norm`` (EPOC from the
measured NHR through :mod:`effortface.synth.physiology`'s recursion), the inputs of both models.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.annotate.completeness import RULE_TEXT, rater_status
from effortface.annotate.keyframes import HUMAN_ORIGINS, ORIGINS, read_annotations
from effortface.core.errors import UserError
from effortface.core.fileio import check_regular_file, read_json, refuse_overwrite
from effortface.core.participant import LIMITS, SEX_ALIASES, SEXES  # the one limits table
from effortface.core.session.folder import (Session, check_not_recording, check_session, list_sessions,
                                             parse_session_id, read_session)
from effortface.train.hr_fit import HrSeries
from effortface.synth.work import WORK_CSV, derive_work, read_work_csv
from effortface.synth.physiology import (EpocParams, hr_max_bpm, hr_rest_bpm, epoc_step,
                              vo2max_ml_per_kg_min, VO2_REST_ML_PER_KG_MIN)

#: the long table's required columns, in order (blendshape columns follow)
TABLE_COLUMNS = ("participant", "session", "t_s", "sex", "age", "height_m", "mass_kg",
                 "training_level", "w_per_kg", "p_per_kg", "hr_bpm")
#: optional columns understood by :func:`read_table`
OPTIONAL_COLUMNS = ("exercise", "hr_rest_bpm", "hr_max_bpm")
PARTICIPANT_COLUMNS = ("sex", "age", "height_m", "mass_kg", "training_level")
#: the text columns :func:`read_table` holds as categoricals (one byte a row each, not a string pointer)
STRING_COLUMNS = ("participant", "session", "sex", "exercise")
#: longest strap gap bridged by interpolation, seconds (choice)
MAX_HR_GAP_S = 5.0
ANNOTATIONS_DIR = "annotations"
#: ``--raters``: who labels the face (the machine only where no human keyed)
RATER_SOURCES = ("humans", "humans+machine")
#: prefix of the columns that say a label came from the machine (``machine_mouth_open``...)
MACHINE_PREFIX = "machine_"


class DatasetError(UserError):
    """A training input (session, table, option) cannot make a dataset; the message names it."""


# --------------------------------------------------------------------------- the long table


def read_table(path: str | os.PathLike, blendshapes: BlendshapeSet | None = None) -> pd.DataFrame:
    """Read a long training table (see the module docstring).

    Parameters
    ----------
    path : path-like
        The CSV file.
    blendshapes : BlendshapeSet, optional
        Expected blendshape columns; by default every column that is neither required nor optional.

    Returns
    -------
    DataFrame
        The table with numeric columns as floats and an ``exercise`` column; the text columns
        (:data:`STRING_COLUMNS`) are categoricals with sorted categories (:func:`_categorical`).

    Raises
    ------
    DatasetError
        If the file cannot be read or has no rows, a column is missing, an id or ``t_s`` is empty or
        repeated, a value is not numeric or out of range (:func:`check_rows`, :func:`check_values`,
        :func:`check_participants`), or a participant's data contradict themselves; the message
        names the file.
    """
    path = check_regular_file(path, "a CSV table", DatasetError)
    try:
        df = pd.read_csv(path, dtype={c: "category" for c in STRING_COLUMNS})
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise DatasetError(f"{path}: expected a CSV training table, found {exc}") from None
    missing = [c for c in TABLE_COLUMNS if c not in df.columns]
    if missing:
        raise DatasetError(f"{path}: expected columns {', '.join(missing)} (long format "
                           f"{','.join(TABLE_COLUMNS)},<blendshapes>), found {', '.join(df.columns)}")
    names = list(blendshapes.names) if blendshapes else [
        c for c in df.columns if c not in TABLE_COLUMNS and c not in OPTIONAL_COLUMNS]
    absent = [c for c in names if c not in df.columns]
    if absent or not names:
        raise DatasetError(f"{path}: expected blendshape columns {', '.join(absent) or '(one or more)'}, "
                           f"found {', '.join(df.columns)}")
    numeric = [c for c in TABLE_COLUMNS[2:] if c != "sex"] + names + \
        [c for c in ("hr_rest_bpm", "hr_max_bpm") if c in df]
    for col in numeric:
        try:
            df[col] = pd.to_numeric(df[col]).astype(float)
        except (ValueError, TypeError):
            raise DatasetError(f"{path}: column {col}: expected numbers, found "
                               f"{df[col][pd.to_numeric(df[col], errors='coerce').isna() & df[col].notna()].iloc[0]!r}") from None
    df["exercise"] = _categorical(df["exercise"] if "exercise" in df else df["session"].map(_session_label))
    df["sex"] = _categorical(df["sex"].map(lambda v: SEX_ALIASES.get(str(v).strip().lower(), v)
                                           if pd.notna(v) else v))
    check_rows(df, str(path))
    check_participants(df, str(path))
    check_values(df, names, str(path))
    return df


def _categorical(values: pd.Series) -> pd.Series:
    """``values`` as a categorical whose categories are sorted (NaN stays missing).

    Sorting, ``groupby`` (with ``observed=True``), ``==`` and ``to_numpy(str)`` then give what they
    give on the strings themselves, while the table holds one small code a row.
    """
    if isinstance(values.dtype, pd.CategoricalDtype):
        categories = values.cat.categories
        return values if categories.is_monotonic_increasing else \
            values.cat.reorder_categories(sorted(categories))
    return values.astype("category")


def write_table(table: pd.DataFrame, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a table in the long format (required columns first); refuse to overwrite unless told.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.
    """
    path = refuse_overwrite(path, overwrite=overwrite, what="table")
    extra = [c for c in table.columns if c not in TABLE_COLUMNS]
    table[list(TABLE_COLUMNS) + extra].to_csv(path, index=False, float_format="%.6g")
    return path


#: plausible ranges of the per-second columns (NaN allowed: not measured / not annotated)
VALUE_RANGES = {"hr_bpm": (25.0, 250.0), "w_per_kg": (0.0, 100.0), "p_per_kg": (0.0, 100.0)}
#: key-framed blendshape weights
WEIGHT_RANGE = (0.0, 1.0)


def _line(table: pd.DataFrame, mask: pd.Series) -> int:
    """CSV line number (header = line 1) of the first row where ``mask`` holds."""
    return int(np.flatnonzero(mask.to_numpy())[0]) + 2


def check_rows(table: pd.DataFrame, source: str) -> None:
    """DatasetError for a table without rows, rows without ids, or bad ``t_s``.

    Parameters
    ----------
    table : DataFrame
        The long table, numeric columns already floats, rows in file order.
    source : str
        The file, for the message.

    Raises
    ------
    DatasetError
        If there are no rows, a participant or session id is empty, ``t_s`` is not a finite
        number, or a session repeats a ``t_s``.
    """
    if table.empty:
        raise DatasetError(f"{source}: expected rows of participant-seconds, found only the header")
    for col in ("participant", "session"):
        empty = table[col].isna() | (table[col].astype(str).str.strip() == "")
        if empty.any():
            raise DatasetError(f"{source}: column {col}: expected an id on every row, found "
                               f"{int(empty.sum())} empty (first on line {_line(table, empty)})")
    bad = ~np.isfinite(table["t_s"])
    if bad.any():
        raise DatasetError(f"{source}: column t_s: expected a finite time on every row, found "
                           f"{table['t_s'][bad].iloc[0]} on line {_line(table, bad)}")
    dup = table.duplicated(["session", "t_s"])
    if dup.any():
        row = table[dup].iloc[0]
        raise DatasetError(f"{source}: session {row['session']}: expected one row per t_s, found "
                           f"t_s {row['t_s']:g} again on line {_line(table, dup)}")


def check_values(table: pd.DataFrame, blendshapes: Sequence[str], source: str,
                 sources: Mapping[str, str] | None = None) -> None:
    """DatasetError for a per-second value outside its range (:data:`VALUE_RANGES`, weights in
    :data:`WEIGHT_RANGE`); empty cells are allowed.

    Parameters
    ----------
    table : DataFrame
        The long table (one session's rows when ``sources`` is given).
    blendshapes : sequence of str
        The weight columns.
    source : str
        The file the table was read from, for the message (with the line).
    sources : mapping, optional
        Column -> the user's file its values come from (a session's ``heart_rate.csv``, ``work.csv``,
        ``annotations/``): the message names that file and the row's ``t_s`` instead of a line of
        a table the user never saw.

    Raises
    ------
    DatasetError
        Naming the source, the column, the range, the value and its line (or its file and time).
    """
    ranges = {**VALUE_RANGES, **{n: WEIGHT_RANGE for n in blendshapes}}
    for col, (lo, hi) in ranges.items():
        values = table[col]
        bad = values.notna() & ~values.between(lo, hi)
        if bad.any():
            where = (f"{sources.get(col, source)}: column {col}" if sources is not None
                     else f"{source}: column {col}")
            at = (f"at t_s {table['t_s'][bad].iloc[0]:g} s" if sources is not None
                  else f"on line {_line(table, bad)}")
            raise DatasetError(f"{where}: expected values from {lo:g} to {hi:g} (or empty), found "
                               f"{values[bad].iloc[0]:g} {at}")


def _value_sources(s: Session, blendshapes: Sequence[str]) -> dict[str, str]:
    """Per-second column -> the session file (or derivation) its values come from, for messages."""
    work = s.path / WORK_CSV
    derived = f"{s.path}: the work derived from motion/ and the exercise log"
    return {"hr_bpm": str(s.path / "heart_rate.csv"),
            "w_per_kg": str(work) if work.is_file() else derived,
            "p_per_kg": str(work) if work.is_file() else derived,
            **{n: str(s.path / "annotations") for n in blendshapes}}


def check_participants(table: pd.DataFrame, source: str) -> None:
    """DatasetError if a participant's sex/age/height/mass/TL is missing, implausible, or differs
    between rows.

    The ranges are :data:`effortface.core.participant.LIMITS`, the ones every stage uses: age
    10-100 years, height 0.5-2.6 m, mass 15-300 kg, TL 0-10, measured HR_rest 25-120 and HR_max
    100-240 bpm; sex female or male.

    Raises
    ------
    DatasetError
        Naming the source, the participant (and session) and the field.
    """
    for code, rows in table.groupby("participant", sort=False, observed=True):
        for col in PARTICIPANT_COLUMNS:
            values = rows[col].dropna().unique()
            if len(values) > 1:
                sessions = rows.drop_duplicates(col)["session"].tolist()
                raise DatasetError(f"{source}: participant {code}: expected one {col}, found "
                                   f"{', '.join(map(str, values))} (sessions {', '.join(sessions)})")
            if len(values) == 0:
                raise DatasetError(f"{source}: participant {code}: expected a {col}, found none")
            if rows[col].isna().any():
                session = rows[rows[col].isna()]["session"].iloc[0]
                raise DatasetError(f"{source}: session {session}: expected a {col} for participant "
                                   f"{code}, found none")
            _check_participant_value(source, str(code), col, values[0])
        for col in ("hr_rest_bpm", "hr_max_bpm"):
            if col in rows:
                for value in rows[col].dropna().unique():
                    _check_participant_value(source, str(code), col, value)


def _check_participant_value(source: str, code: str, col: str, value: object) -> None:
    """DatasetError unless ``value`` is a valid sex or lies within :data:`LIMITS` ``[col]``."""
    if col == "sex":
        if value not in SEXES:
            raise DatasetError(f"{source}: participant {code}: column sex: expected one of "
                               f"{', '.join(SEXES)}, found {value!r}")
        return
    if not LIMITS[col].accepts(value):
        raise DatasetError(f"{source}: participant {code}: column {col}: expected "
                           f"{LIMITS[col].expected()}, found {value:g}")


def _session_label(session_id: str) -> str:
    """The label part of a session id (``cardio``), or ``session`` if there is none."""
    try:
        return parse_session_id(str(session_id))[2] or "session"
    except UserError:
        return "session"


# --------------------------------------------------------------------------- sessions


def expand_paths(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """Session folders from a mix of sessions and folders of sessions (UserError if none).

    Sessions a capture is recording now are left out of folders, and refused when named. Each path
    given must be a session or hold one: an explicit empty folder is refused (issue 29), never
    skipped and then listed among a model's sources.
    """
    out: list[Path] = []
    for p in map(Path, paths):
        if (p / "session.json").is_file():
            check_not_recording(p, "train on")
        found = [p] if (p / "session.json").is_file() else list_sessions(p)
        if not found:
            what = "a folder with none" if p.is_dir() else "a file" if p.exists() else "nothing"
            raise DatasetError(f"{p}: expected a session folder or a folder of sessions, found {what}")
        out.extend(found)
    if not out:
        raise DatasetError(f"{', '.join(map(str, paths))}: expected session folders, found none")
    return out


class MachineLabelsOnly(DatasetError):
    """A session whose complete tracks are all keys accepted from the machine: no human label.

    ``reason`` says so in a few words (the model card's line for the session).
    """

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


def sessions_table(paths: Iterable[str | os.PathLike], blendshapes: BlendshapeSet = DEFAULT_SET,
                   rater_policy: str = "mean", raters: str = "humans") -> pd.DataFrame:
    """The long table of several sessions (or folders of sessions), checked for contradictions.

    Parameters
    ----------
    paths : iterable of path-like
        Session folders or folders that contain session folders.
    blendshapes : BlendshapeSet
        The blendshape set (column order).
    rater_policy : str
        ``"mean"`` or the name of one rater.
    raters : {"humans", "humans+machine"}
        Whether the machine track labels the seconds no human keyed (see the module docstring).

    Returns
    -------
    DataFrame
        The text columns (:data:`STRING_COLUMNS`) as categoricals, as :func:`read_table` gives them;
        ``attrs["left_out"]``: ``"<session>: <why>"`` of the sessions left out (labelled only by keys
        accepted from the machine), ``attrs["label_origins"]``: seconds of rater labels by origin.

    Raises
    ------
    DatasetError
        For a session without heart rate, without work, without annotations (or without the named
        rater), or a participant whose data differ between sessions; or when every session was left out.
    """
    folders = expand_paths(paths)
    origins = {o: 0 for o in ORIGINS}
    parts, left_out = [], []
    for f in folders:
        try:
            parts.append(session_table(f, blendshapes, rater_policy, raters, origins))
        except MachineLabelsOnly as exc:
            left_out.append(f"{f.name}: {exc.reason}")
    if not parts:
        raise DatasetError(f"{', '.join(map(str, folders))}: expected sessions with human labels, found "
                           f"only keys accepted from the machine ({'; '.join(left_out)})")
    table = pd.concat(parts, ignore_index=True)
    for col in (*PARTICIPANT_COLUMNS[1:], "hr_rest_bpm", "hr_max_bpm"):
        table[col] = pd.to_numeric(table[col]).astype(float)  # None (not recorded) -> NaN
    source = ", ".join(str(f.parent) for f in folders[:1]) or "sessions"
    check_participants(table, source)
    check_values(table, blendshapes.names, source)
    for col in STRING_COLUMNS:  # as read_table holds them
        table[col] = _categorical(table[col])
    table.attrs["left_out"], table.attrs["label_origins"] = left_out, origins
    return table


def session_table(folder: str | os.PathLike, blendshapes: BlendshapeSet = DEFAULT_SET,
                  rater_policy: str = "mean", raters: str = "humans",
                  origins: dict[str, int] | None = None) -> pd.DataFrame:
    """One session folder -> its per-second rows in the long format (plus ``exercise`` and measured HR).

    ``origins``, when given, is added the seconds of the raters' complete tracks by key origin.

    Raises
    ------
    MachineLabelsOnly
        If its complete tracks hold only keys accepted from the machine (no human label).
    DatasetError
        See :func:`sessions_table`.
    """
    s = check_session(folder)
    _check_hr_samples(s)
    hr_t = [h.t_s for h in s.heart_rate if h.valid and h.hr_bpm is not None]
    if len(hr_t) < 2:
        raise DatasetError(f"{s.path / 'heart_rate.csv'}: expected valid heart-rate samples, "
                           f"found {len(hr_t)}")
    end_s = max(hr_t[-1], s.frame_times_s[-1] if s.frame_times_s else 0.0)
    t = np.arange(0.0, math.floor(end_s) + 1.0)
    w, p = _work(s, t)
    check_raters(raters)
    weights = _weights(s, t, blendshapes, rater_policy, machine=raters == "humans+machine", origins=origins)
    from_machine = np.zeros(weights.shape, bool)
    if raters == "humans+machine":
        weights, from_machine = _fill_from_machine(s, t, blendshapes, weights)
    part = s.participant
    df = pd.DataFrame({"participant": part.code, "session": s.info.session_id, "t_s": t,
                       "sex": part.sex, "age": part.age, "height_m": part.height_m,
                       "mass_kg": part.mass_kg, "training_level": part.training_level,
                       "w_per_kg": w, "p_per_kg": p, "hr_bpm": _hr_per_second(s, t)})
    for j, name in enumerate(blendshapes.names):
        df[name] = weights[:, j]
    if raters == "humans+machine":
        for j, name in enumerate(blendshapes.names):
            df[MACHINE_PREFIX + name] = from_machine[:, j]
    df["exercise"] = _session_label(s.info.session_id)
    df["hr_rest_bpm"], df["hr_max_bpm"] = part.hr_rest_bpm, part.hr_max_bpm
    check_values(df, blendshapes.names, str(s.path), _value_sources(s, blendshapes.names))
    return df


def _check_hr_samples(s: Session) -> None:
    """DatasetError for a valid strap sample outside the hr_bpm range, checked before interpolation
    (which would hide it: -70 bpm between two 72 bpm samples became 50.8 bpm at the second)."""
    lo, hi = VALUE_RANGES["hr_bpm"]
    for i, h in enumerate(s.heart_rate):
        if h.valid and h.hr_bpm is not None and not lo <= h.hr_bpm <= hi:
            raise DatasetError(f"{s.path / 'heart_rate.csv'}: line {i + 2}: expected hr_bpm from {lo:g} to "
                               f"{hi:g} on a valid row, found {h.hr_bpm:g}")


def _hr_per_second(s: Session, t: np.ndarray) -> np.ndarray:
    """Valid strap HR interpolated at t; NaN outside the record and across long gaps."""
    valid = [(h.t_s, h.hr_bpm) for h in s.heart_rate if h.valid and h.hr_bpm is not None]
    ht, hv = (np.array(x, dtype=float) for x in zip(*valid))
    out = np.interp(t, ht, hv, left=np.nan, right=np.nan)
    i = np.clip(np.searchsorted(ht, t), 1, len(ht) - 1)
    out[(ht[i] - ht[i - 1]) > MAX_HR_GAP_S] = np.nan
    return out


def _work(s: Session, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """w and p (W/kg) per second from work.csv, else derived as ``effortface work`` does
    (:func:`effortface.synth.work.derive_work`: motion/ where clips cover the time, the exercise log
    elsewhere)."""
    path = s.path / WORK_CSV
    if path.is_file():
        try:
            work = read_work_csv(path)
        except UserError as exc:
            raise DatasetError(str(exc)) from None
        idx = np.clip(np.searchsorted(work.t_s, t + 1e-9, side="right") - 1, 0, len(work.t_s) - 1)
        return work.w_per_kg[idx], work.p_per_kg[idx]
    try:
        table = derive_work(s, t)
    except UserError as exc:
        raise DatasetError(str(exc)) from None
    return table.w_per_kg, table.p_per_kg


#: the numbers of a motion.json entry, with their bounds-table names and defaults
def check_raters(raters: str) -> str:
    """``raters`` if it is one of :data:`RATER_SOURCES`, else UserError naming ``--raters``."""
    if raters not in RATER_SOURCES:
        raise UserError(f"--raters: expected one of {', '.join(RATER_SOURCES)}, found {raters!r}")
    return raters


def _fill_from_machine(s: Session, t: np.ndarray, blendshapes: BlendshapeSet, weights: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Weights with the machine's where no human label exists, and where that was done (both (len(t), B))."""
    from effortface.annotate.machine.track import FOUR, read_machine_track

    track = read_machine_track(s.path)
    from_machine = np.zeros(weights.shape, bool)
    if track is None or track.t_s.size == 0:
        return weights, from_machine
    idx = _nearest_frames(np.asarray(track.t_s, float), t) if track.t_s.size > 1 else np.zeros(len(t), int)
    out = weights.copy()
    for j, name in enumerate(blendshapes.names):
        if name in FOUR:
            machine = np.clip(track.weights[idx, FOUR.index(name)], 0.0, 1.0)
            fill = ~np.isfinite(out[:, j]) & np.isfinite(machine)
            out[fill, j] = machine[fill]
            from_machine[:, j] = fill
    return out, from_machine


def _weights(s: Session, t: np.ndarray, blendshapes: BlendshapeSet, rater_policy: str,
             machine: bool = False, origins: dict[str, int] | None = None) -> np.ndarray:
    """Per-second weights (len(t), B) under the rater policy; DatasetError if unannotated (with ``machine``,
    a session with a machine track may have no human annotation: its weights are then all NaN)."""
    files = sorted((s.path / ANNOTATIONS_DIR).glob("*.json"))
    if machine and not files and s.frame_times_s and (s.path / "machine").is_dir():
        return np.full((len(t), len(blendshapes)), np.nan)
    if rater_policy != "mean":
        files = [f for f in files if f.stem == rater_policy]
        if not files:
            raters = sorted(f.stem for f in (s.path / ANNOTATIONS_DIR).glob("*.json"))
            raise DatasetError(f"{s.path / ANNOTATIONS_DIR}: expected rater {rater_policy!r} "
                               f"(--rater-policy), found {', '.join(raters) or 'no raters'}")
    if not files or not s.frame_times_s:
        raise DatasetError(f"{s.path}: expected key-framed annotations ({ANNOTATIONS_DIR}/<rater>.json) "
                           f"and video_frames.csv, found {len(files)} annotation files and "
                           f"{len(s.frame_times_s)} frames")
    frames = _nearest_frames(np.asarray(s.frame_times_s), t)
    found = {o: 0 for o in ORIGINS}
    stack = np.stack([_rater_weights(f, frames, blendshapes, s.info.session_id, s.frame_times_s, found)
                      for f in files])
    for origin, n in found.items():
        if origins is not None:
            origins[origin] += n
    with np.errstate(all="ignore"):
        counts = np.isfinite(stack).sum(axis=0)
        mean = np.where(counts > 0, np.nansum(stack, axis=0) / np.maximum(counts, 1), np.nan)
    if not np.isfinite(mean).any() and found["machine"] and not machine:
        raise MachineLabelsOnly(f"{s.path / ANNOTATIONS_DIR}: expected keys a person typed or edited, found "
                                f"only keys accepted from the machine ({found['machine']} s)",
                                reason=f"left out: its complete tracks are keys accepted from the machine, "
                                       f"not edited ({found['machine']} s)")
    if not np.isfinite(mean).any() and not (machine and (s.path / "machine").is_dir()):
        raise DatasetError(f"{s.path / ANNOTATIONS_DIR}: expected complete key-frame tracks "
                           f"({RULE_TEXT}), found none")
    return mean


def _nearest_frames(frame_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the frame whose arrival time is nearest each t."""
    i = np.clip(np.searchsorted(frame_t, t), 1, len(frame_t) - 1)
    return np.where(np.abs(frame_t[i - 1] - t) <= np.abs(frame_t[i] - t), i - 1, i)


def _rater_weights(path: Path, frames: np.ndarray, blendshapes: BlendshapeSet, session_id: str,
                   frame_times_s: Sequence[float], origins: dict[str, int]) -> np.ndarray:
    """One rater's weights for our blendshape set (NaN for tracks the file lacks or that are incomplete,
    and at the seconds whose label is a key accepted from the machine); ``origins`` is added the seconds
    of each origin of the complete tracks."""
    ann = read_annotations(path, session_id=session_id, rater=path.stem)
    status = rater_status(ann, frame_times_s)
    cols = []
    for n in blendshapes.names:
        if n in ann.tracks and status[n].complete:
            track = ann.tracks[n]
            found = track.origins(frames)
            for origin in ORIGINS:
                origins[origin] += int(np.count_nonzero(found == origin))
            cols.append(np.where(np.isin(found, HUMAN_ORIGINS), track.evaluate(frames), np.nan))
        else:
            cols.append(np.full(len(frames), np.nan))
    return np.column_stack(cols).astype(float)


# --------------------------------------------------------------------------- model inputs


def prepare(table: pd.DataFrame, hr_max_formula: str = "tanaka",
            epoc: EpocParams = EpocParams(), source: str = "table") -> pd.DataFrame:
    """Add ``hr_rest_bpm``, ``hr_max_bpm``, ``nhr`` and ``epoc_norm`` (a new frame, sorted).

    HR_rest comes from the chart (sex, age, TL) and HR_max from ``hr_max_formula`` unless the table
    gives measured values. NHR is clipped to [0, 1]; EPOC runs the physiology recursion on the
    measured NHR of each session.

    The new frame shares the table's columns where no reordering is needed (a table already sorted
    by participant, session and ``t_s``, as the long tables are; pandas copies on write, so neither
    frame sees the other's changes): keeping both costs the four new columns a row, not a second
    table.

    Raises
    ------
    DatasetError
        If a session has no heart rate at all, or rest >= max.
    """
    if table.empty:
        raise DatasetError(f"{source}: expected rows of participant-seconds, found none")
    out = table.sort_values(["participant", "session", "t_s"]).reset_index(drop=True)
    added = {col: np.full(len(out), np.nan) for col in ("hr_rest_bpm", "hr_max_bpm", "nhr", "epoc_norm")}
    order = []
    for sid, rows in out.groupby("session", sort=False, observed=True):
        try:
            values = _prepare_session(rows, hr_max_formula, epoc, source)
        except DatasetError:
            raise
        except UserError as exc:  # physiology: names the field only
            raise DatasetError(f"{source}: session {sid}: {exc}") from None
        at = rows.index.to_numpy()
        for col, v in values.items():
            added[col][at] = v
        order.append(at)
    out = out.assign(**added)  # measured hr_rest/max_bpm replaced in place, nhr and epoc_norm last
    order_rows = np.concatenate(order)
    if not np.array_equal(order_rows, np.arange(len(out))):  # a session id shared by participants
        out = out.take(order_rows).reset_index(drop=True)
    return out


def _prepare_session(rows: pd.DataFrame, formula: str, epoc: EpocParams, source: str
                     ) -> dict[str, np.ndarray]:
    """HR_rest, HR_max, NHR and EPOC_norm (one array each) for one session's rows."""
    first = rows.iloc[0]
    if not rows["hr_bpm"].notna().any():
        raise DatasetError(f"{source}: session {first['session']}: expected heart-rate values "
                           f"(hr_bpm), found none")
    rest = first["hr_rest_bpm"] if "hr_rest_bpm" in first and pd.notna(first["hr_rest_bpm"]) else hr_rest_bpm(
        first["age"], first["sex"], first["training_level"])
    top = first["hr_max_bpm"] if "hr_max_bpm" in first and pd.notna(first["hr_max_bpm"]) else hr_max_bpm(
        first["age"], formula)
    if top <= rest:
        raise DatasetError(f"{source}: participant {first['participant']}: expected hr_max_bpm > "
                           f"hr_rest_bpm, found {top:g} <= {rest:g}")
    n = len(rows)
    nhr = ((rows["hr_bpm"] - rest) / (top - rest)).clip(0, 1).to_numpy(float)
    vo2max = vo2max_ml_per_kg_min(first["age"], first["sex"], first["height_m"], first["mass_kg"],
                                  first["training_level"])
    return {"hr_rest_bpm": np.full(n, float(rest)), "hr_max_bpm": np.full(n, float(top)), "nhr": nhr,
            "epoc_norm": _epoc(rows["t_s"].to_numpy(float), nhr, vo2max, epoc) / epoc.scale_ml_per_kg}


def _epoc(t_s: np.ndarray, nhr: np.ndarray, vo2max: float, params: EpocParams) -> np.ndarray:
    """EPOC (ml/kg) by the physiology recursion on measured NHR (missing NHR holds the last value)."""
    filled = pd.Series(nhr).ffill().fillna(0.0).to_numpy()
    intensity = (VO2_REST_ML_PER_KG_MIN + filled * (vo2max - VO2_REST_ML_PER_KG_MIN)) / vo2max
    dt = np.diff(t_s, prepend=t_s[0])
    out = np.empty(len(t_s))
    e = np.asarray(0.0)
    for i in range(len(t_s)):
        if dt[i] > 0:
            e = epoc_step(e, intensity[i], params, float(dt[i]))
        out[i] = e
    return out


def hr_series(prepared: pd.DataFrame) -> list[HrSeries]:
    """One :class:`~effortface.train.hr_fit.HrSeries` per session of a prepared table."""
    out = []
    for sid, rows in prepared.groupby("session", sort=False, observed=True):
        f = rows.iloc[0]
        out.append(HrSeries(str(f["participant"]), str(sid), float(f["training_level"]),
                            rows["t_s"].to_numpy(float), rows["w_per_kg"].to_numpy(float),
                            rows["nhr"].to_numpy(float), float(f["hr_rest_bpm"]), float(f["hr_max_bpm"])))
    return out


def blendshape_columns(table: pd.DataFrame, blendshapes: BlendshapeSet | None = None) -> list[str]:
    """Blendshape column names of a table (the set's names, or every non-standard column)."""
    if blendshapes is not None:
        return list(blendshapes.names)
    known = set(TABLE_COLUMNS) | set(OPTIONAL_COLUMNS) | {"nhr", "epoc_norm"}
    return [c for c in table.columns if c not in known]


# --------------------------------------------------------------------------- synthetic data


def synthetic_table(n_participants: int = 6, seconds: int = 900, seed: int = 0,
                    blendshapes: Sequence[str] = DEFAULT_SET.names) -> pd.DataFrame:
    """A synthetic long table for tests and benchmarks (not for science).

    Each participant gets a TL, an expressiveness vector, a cardio and a strength session of work
    bouts; HR follows the paper's recursion at the participant's TL (plus noise), and the weights are
    non-linear functions of power, NHR and fatigue times the expressiveness, with autocorrelated
    noise, so random-frame CV looks better than it is.
    """
    from effortface.synth.physiology import NhrParams, nhr_step  # local: only the generator needs them

    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n_participants):
        code, tl = f"P{i + 1:02d}", float(rng.uniform(0, 7.5))
        e = rng.uniform(0.3, 1.0, len(blendshapes))
        body: dict[str, Any] = dict(sex=("female", "male")[i % 2], age=float(rng.integers(20, 50)),
                                    height_m=float(rng.uniform(1.6, 1.9)), mass_kg=float(rng.uniform(55, 90)))
        for kind, levels in (("cardio", (0.1, 4.0, 8.0, 12.0, 20.0)), ("strength", (0.1, 2.0, 3.5, 6.0))):
            sid = f"{code}_2026010{1 + (kind == 'strength')}-1000{i:02d}_{kind}"
            w = _bouts(rng, levels, seconds)
            p = np.clip(w * rng.lognormal(0, 0.15, seconds), 0, None)
            nhr = np.empty(seconds)
            state, par = np.asarray(0.05), NhrParams.from_training_level(tl)
            for k in range(seconds):
                nhr[k] = state = nhr_step(state, w[k], par)
            fatigue = np.cumsum(nhr) / 600.0
            y = _synthetic_weights(p, nhr, fatigue, e, rng)
            rest, top = hr_rest_bpm(body["age"], body["sex"], tl), hr_max_bpm(body["age"])
            hr = rest + np.clip(nhr + rng.normal(0, 0.01, seconds), 0, 1) * (top - rest)
            df = pd.DataFrame({"participant": code, "session": sid, "t_s": np.arange(seconds, dtype=float),
                               **body, "training_level": tl, "w_per_kg": w, "p_per_kg": p, "hr_bpm": hr})
            for j, name in enumerate(blendshapes):
                df[name] = y[:, j]
            df["exercise"] = kind
            rows.append(df)
    return pd.concat(rows, ignore_index=True)


def _bouts(rng: np.random.Generator, levels: Sequence[float], seconds: int) -> np.ndarray:
    """Work bouts of 40-120 s at the given levels, alternating with rest, jittered."""
    w: list[float] = []
    while len(w) < seconds:
        lvl = float(rng.choice(levels)) if len(w) % 2 == 0 else 0.1
        w.extend(np.clip(lvl + rng.normal(0, 0.3, int(rng.integers(40, 120))), 0, None))
    return np.array(w[:seconds])


def _synthetic_weights(p: np.ndarray, nhr: np.ndarray, fatigue: np.ndarray, e: np.ndarray,
                       rng: np.random.Generator) -> np.ndarray:
    """Non-linear normalised curves times expressiveness, with AR(1) noise."""
    exertion = 1 - np.exp(-p / 6.0)
    base = np.column_stack([
        0.6 * exertion + 0.4 * np.tanh(2 * fatigue),
        1 / (1 + np.exp(-12 * (nhr - 0.55))),
        exertion * np.exp(-fatigue) + 0.2 * (1 - np.exp(-fatigue)),
        np.clip(exertion - 0.3 * np.tanh(fatigue), 0, 1),
    ])[:, : len(e)]
    noise = np.zeros_like(base)
    for k in range(1, len(base)):
        noise[k] = 0.95 * noise[k - 1] + rng.normal(0, 0.02, base.shape[1])
    return np.clip((base + noise) * e, 0, 1)
