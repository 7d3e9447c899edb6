"""Joint-positions CSV motion and skeleton files: the one reader of both CSV dialects (numpy only:
the runtime reads them).

**Joint-positions CSV** (``.csv``): a header ``t_s`` then three columns per joint, x, y, z in that
order (metres, Z up), then one row of numbers per frame. Two dialects name the columns, both read
by :func:`read_positions_csv` (the first joint column tells which; a file uses one):

* ``t_s,<joint>_x_m,<joint>_y_m,<joint>_z_m,...``: what :func:`write_positions_csv` writes, with a
  skeleton file beside the clip;
* ``t_s,<joint>_x,<joint>_y,<joint>_z,...``: the same without the unit in the column names.

Lines starting with ``#`` are comments and blank lines are skipped, anywhere in the file. Times
``t_s`` increase; the frame rate is 1 / the median step, and every step must be within
:data:`STEP_TOLERANCE` (50 %) of the median: a step outside is a dropped or repeated frame, which a
constant-rate :class:`~effortface.synth.motion.Motion` cannot hold (clock jitter smaller than that,
as in stamps recorded over LSL, is read at the median rate).

The **skeleton tree** (parents) comes from one of, not both:

* a comment ``# parents: Spine=Hips, Head=Spine, ...`` (``child=parent`` joint names of the header);
* a skeleton file beside the clip, ``<clip stem>.skeleton.json``, whose joints are the header's
  joints in the header's order.

Parents come before their children in the columns. Without either (and for joints a comment does
not name) the dialect's default applies: ``_x_m`` files, every joint is a root; ``_x`` files, the
first joint is the root and the others hang from it. Segments are found by joint name and work and
power need positions only, so the tree matters little for them.

**Skeleton file** (``.skeleton.json``): ``{"joints": [names], "parents": [index or -1]}`` with parents
listed before their children, optionally ``"rest_positions_m": [[x, y, z], ...]`` (a reference pose,
metres, Z up, used by ``effortface serve --input lsl`` for a ``MoCap`` stream).
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any, NoReturn

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text, write_json_atomic
from effortface.synth.motion import Motion, MotionFormatError, motion_from_positions

#: the suffix of a skeleton file beside a clip
SKELETON_SUFFIX = ".skeleton.json"
#: the first column of a joint-positions CSV
TIME_COLUMN = "t_s"
#: largest departure of a frame step from the median step, as a fraction of the median
STEP_TOLERANCE = 0.5
#: the comment key of a tree given in the file
PARENTS_KEY = "parents"


@dataclasses.dataclass(frozen=True)
class CsvDialect:
    """How a joint-positions CSV names its columns, and its tree when none is given.

    Attributes
    ----------
    axes : tuple of str
        The suffixes of a joint's x, y and z columns.
    first_joint_is_root : bool
        Default tree: the first joint is the root and the others hang from it (else all roots).
    """

    axes: tuple[str, str, str]
    first_joint_is_root: bool

    def columns(self, joint: str) -> list[str]:
        """The three column names of ``joint``."""
        return [joint + axis for axis in self.axes]

    def default_parents(self, n_joints: int) -> list[int]:
        """The tree of a file that gives none."""
        if self.first_joint_is_root:
            return [-1] + [0] * (n_joints - 1)
        return [-1] * n_joints


#: ``<joint>_x_m`` columns (written by :func:`write_positions_csv`) and ``<joint>_x`` columns
DIALECTS = (CsvDialect(("_x_m", "_y_m", "_z_m"), first_joint_is_root=False),
            CsvDialect(("_x", "_y", "_z"), first_joint_is_root=True))
_HEADER_FORMS = "t_s,<joint>_x_m,<joint>_y_m,<joint>_z_m,... or t_s,<joint>_x,<joint>_y,<joint>_z,... (metres, Z up)"


def csv_header(joint_names: Sequence[str]) -> list[str]:
    """The header of a joint-positions CSV for these joints (``t_s`` first, ``_x_m`` dialect)."""
    return [TIME_COLUMN] + [column for name in joint_names for column in DIALECTS[0].columns(name)]


def is_positions_csv(path: str | os.PathLike[str]) -> bool:
    """Whether a file's first line that is not a comment is a joint-positions header (either dialect)."""
    try:
        with open(path, encoding="utf-8") as fh:
            for _, line in zip(range(64), fh):
                text = line.strip()
                if text and not text.startswith("#"):
                    parse_header(Path(path), 1, text)
                    return True
    except (OSError, UnicodeDecodeError, MotionFormatError):
        pass
    return False


def parse_header(path: Path, line: int, text: str) -> tuple[list[str], CsvDialect]:
    """The joint names and dialect of a header line (see the module docstring).

    Parameters
    ----------
    path : Path
        The file, named in the error message.
    line : int
        The header's line number (1-based), named in the error message.
    text : str
        The header line.

    Returns
    -------
    names : list of str
    dialect : CsvDialect

    Raises
    ------
    MotionFormatError
        Not ``t_s`` then at least one joint; a joint's columns not ``<joint>`` + the dialect's
        x, y, z suffixes (the joint's first column is named); a joint named twice.
    """
    cells = [c.strip() for c in text.split(",")]
    dialect = next((d for d in DIALECTS if len(cells) > 1 and cells[1].endswith(d.axes[0])), None)
    if cells[0] != TIME_COLUMN or dialect is None:
        shown = repr(text[:120]) if text else "no line but comments"
        raise MotionFormatError(f"{path}: line {line}: expected the header {_HEADER_FORMS}, found {shown}")
    names: list[str] = []
    for column in range(1, len(cells), 3):
        found = cells[column:column + 3]
        joint = found[0][:-len(dialect.axes[0])] if found[0].endswith(dialect.axes[0]) else ""
        if not joint or found != dialect.columns(joint):
            raise MotionFormatError(f"{path}: line {line}, column {column + 1}: expected "
                                    f"{','.join(dialect.columns(joint or '<joint>'))}, found {','.join(found)!r}")
        if joint in names:
            raise MotionFormatError(f"{path}: line {line}, column {column + 1}: expected a joint name not used "
                                    f"before, found {joint!r} again")
        names.append(joint)
    return names, dialect


def read_skeleton(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a skeleton file: ``joints``, ``parents`` and optional ``rest_positions_m``.

    Parameters
    ----------
    path : path-like
        The ``.skeleton.json`` file.

    Returns
    -------
    dict
        ``joints`` (list of str), ``parents`` (ndarray of int), ``rest_positions_m`` ((J, 3) or None).

    Raises
    ------
    UserError
        Missing file, bad JSON or fields (named).
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        joints = [str(j) for j in doc["joints"]]
        parents = np.asarray(doc.get("parents", [-1] * len(joints)), dtype=int)
        rest = doc.get("rest_positions_m")
        rest_m = None if rest is None else np.asarray(rest, dtype=float).reshape(len(joints), 3)
    except FileNotFoundError:
        raise UserError(f"{path}: expected a skeleton file, found no such file") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UserError(f"{path}: expected a skeleton JSON {{\"joints\": [...], \"parents\": [...]}}, "
                        f"found {type(exc).__name__}: {exc}") from None
    if len(parents) != len(joints):
        raise UserError(f"{path}: parents: expected {len(joints)} values (one per joint), found {len(parents)}")
    return {"joints": joints, "parents": parents, "rest_positions_m": rest_m}


def skeleton_beside(path: Path) -> Path:
    """``clip.csv`` -> ``clip.skeleton.json``."""
    return path.with_name(path.stem + SKELETON_SUFFIX)


def read_positions_csv(path: str | os.PathLike[str]) -> Motion:
    """Read a joint-positions CSV in either dialect (see the module docstring) as a :class:`Motion`.

    Parameters
    ----------
    path : path-like
        The ``.csv`` file.

    Returns
    -------
    Motion
        Without rotations; the frame rate is 1 / the median step of ``t_s``. As the file holds it
        (metres, Z up: the format's); :func:`effortface.synth.motion.read_motion` checks its up axis
        and, for ``<joint>_x`` columns, its unit.

    Raises
    ------
    MotionFormatError
        Unreadable file; a bad header (line and column named); a row that is not the header's count
        of finite numbers (line and column); fewer than 2 frames; times that do not increase or skip
        or repeat a frame (line); a bad tree (the comment's line or the skeleton file named).
    """
    path = Path(path)
    comments: list[tuple[int, str]] = []
    try:
        with open(path, encoding="utf-8") as fh:
            lines = _numbered_data_lines(fh, comments)
            header_line, header = next(lines, (1, ""))
            names, dialect = parse_header(path, header_line, header)
            table = _read_rows(path, (text for _, text in lines), 1 + 3 * len(names))
    except FileNotFoundError:
        raise MotionFormatError(f"{path}: expected a joint-positions CSV, found no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MotionFormatError(f"{path}: expected a joint-positions CSV (UTF-8 text), found {exc}") from None
    step_s = _check_times(path, table[:, 0])
    parents = _tree(path, names, dialect, comments)
    positions_m = table[:, 1:].reshape(len(table), len(names), 3)
    motion = motion_from_positions(positions_m, names, parents, 1.0 / step_s, source=str(path))
    unit_from = "the column names (<joint>_x_m: metres)" if dialect is DIALECTS[0] else "the format (metres)"
    return dataclasses.replace(motion, reading={"unit_m": 1.0, "unit_from": unit_from, "up_axis": "z",
                                                "up_from": "the format (Z up)"})


def _numbered_data_lines(fh: IO[str], comments: list[tuple[int, str]]) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of the lines that are not blank or comments; comments go to ``comments``."""
    for number, line in enumerate(fh, 1):
        text = line.strip()
        if text.startswith("#"):
            comments.append((number, text))
        elif text:
            yield number, text


def _data_lines(path: Path) -> Iterator[tuple[int, str]]:
    """The numbered data lines of ``path`` after the header (a second pass, to name a bad row)."""
    with open(path, encoding="utf-8") as fh:
        lines = _numbered_data_lines(fh, [])
        next(lines, None)
        yield from lines


def _read_rows(path: Path, rows: Iterator[str], n_columns: int) -> np.ndarray:
    """The data rows as a (T, n_columns) float array (numpy's parser); a bad row is found and named."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": the frame count is checked below
            table = np.loadtxt(rows, delimiter=",", ndmin=2, comments=None, dtype=float)
    except ValueError as exc:
        _raise_bad_row(path, n_columns, str(exc))
    if table.shape[0] < 2:
        raise MotionFormatError(f"{path}: expected at least 2 frames (rows after the header), found {table.shape[0]}")
    if table.shape[1] != n_columns or not np.isfinite(table).all():
        _raise_bad_row(path, n_columns, f"{table.shape[1]} values per row")
    return table


def _raise_bad_row(path: Path, n_columns: int, fallback: str) -> NoReturn:
    """Raise the error naming the first row that is not ``n_columns`` finite numbers."""
    expected = f"{path}: expected rows of {n_columns} numbers (t_s, then x, y, z per joint)"
    for number, text in _data_lines(path):
        cells = text.split(",")
        if len(cells) != n_columns:
            raise MotionFormatError(f"{expected}, found {len(cells)} values at line {number}")
        for column, cell in enumerate(cells, 1):
            if not _is_finite_number(cell):
                raise MotionFormatError(f"{expected}, found {cell.strip()[:40]!r} at line {number}, column {column}")
    raise MotionFormatError(f"{expected}, found {fallback}")


def _is_finite_number(text: str) -> bool:
    """True if ``text`` is a finite number as numpy's parser reads it."""
    if "_" in text:  # float() takes 1_000, numpy's parser does not
        return False
    try:
        return bool(np.isfinite(float(text)))
    except ValueError:
        return False


def _check_times(path: Path, t_s: np.ndarray) -> float:
    """The median frame step (s); raise naming the line of a time that does not increase or of a
    step outside :data:`STEP_TOLERANCE` of the median."""
    step_s = np.diff(t_s)
    if not np.all(step_s > 0):
        frame = int(np.flatnonzero(~(step_s > 0))[0]) + 1
        _raise_at_frame(path, frame, f"{TIME_COLUMN}: expected increasing times, found {t_s[frame]:g} "
                                     f"after {t_s[frame - 1]:g}")
    median_s = float(np.median(step_s))
    off = np.abs(step_s - median_s) > STEP_TOLERANCE * median_s
    if off.any():
        frame = int(np.flatnonzero(off)[0]) + 1
        _raise_at_frame(path, frame, f"{TIME_COLUMN}: expected a frame every {median_s:g} s (steps within "
                                     f"{STEP_TOLERANCE:.0%} of it), found a step of {step_s[frame - 1]:g} s "
                                     f"(a dropped or repeated frame?)")
    return median_s


def _raise_at_frame(path: Path, frame: int, message: str) -> NoReturn:
    """Raise ``message`` naming the file line of data row ``frame`` (0-based)."""
    number = next(n for k, (n, _) in enumerate(_data_lines(path)) if k == frame)
    raise MotionFormatError(f"{path}: line {number}: {message}")


def _tree(path: Path, names: list[str], dialect: CsvDialect,
          comments: list[tuple[int, str]]) -> list[int]:
    """Parents from a ``# parents:`` comment or the skeleton file beside the clip (not both),
    else the dialect's default; checked to list parents before their children."""
    given = [(n, spec) for n, text in comments
             for key, _, spec in [text.lstrip("#").partition(":")] if key.strip().lower() == PARENTS_KEY]
    skeleton = skeleton_beside(path)
    if given and skeleton.is_file():
        raise MotionFormatError(f"{path}: line {given[0][0]}: expected the tree in one place, found a "
                                f"'# parents:' comment and {skeleton.name} beside the clip")
    if skeleton.is_file():
        return _skeleton_parents(skeleton, path, names)
    parents = dialect.default_parents(len(names))
    for number, spec in given:
        where = f"{path}: line {number}"
        for pair in filter(None, (p.strip() for p in spec.split(","))):
            child, _, parent = (s.strip() for s in pair.partition("="))
            if child not in names or parent not in names:
                raise MotionFormatError(f"{where}: parents: expected child=parent joint names of the header, "
                                        f"found {pair!r}")
            parents[names.index(child)] = names.index(parent)
            _check_parent_first(where, names, parents, names.index(child))
    return parents


def _skeleton_parents(skeleton: Path, path: Path, names: list[str]) -> list[int]:
    """The parents of a skeleton file whose joints are the CSV's, in its column order."""
    skel = read_skeleton(skeleton)
    if skel["joints"] != names:
        raise MotionFormatError(f"{skeleton}: joints: expected the {len(names)} joints of {path.name} in its column "
                                f"order ({', '.join(names[:4])}{', ...' if len(names) > 4 else ''}), found "
                                f"{len(skel['joints'])} ({', '.join(skel['joints'][:4])}"
                                f"{', ...' if len(skel['joints']) > 4 else ''})")
    parents = [int(p) for p in skel["parents"]]
    for joint in range(len(names)):
        _check_parent_first(str(skeleton), names, parents, joint)
    return parents


def _check_parent_first(where: str, names: list[str], parents: list[int], joint: int) -> None:
    """Raise unless ``joint``'s parent is -1 or an earlier joint (so the tree has no cycle)."""
    parent = parents[joint]
    if not -1 <= parent < joint:
        found = f"{names[joint]}={names[parent]}" if 0 <= parent < len(names) else f"{names[joint]}: {parent}"
        raise MotionFormatError(f"{where}: parents: expected each joint's parent to be a joint of an earlier "
                                f"column (parents first), found {found}")


def write_positions_csv(path: str | os.PathLike[str], motion: Motion) -> Path:
    """Write a :class:`Motion`'s joint positions as a joint-positions CSV (and its skeleton file).

    Parameters
    ----------
    path : path-like
        The ``.csv`` file (``_x_m`` dialect); ``<stem>.skeleton.json`` is written beside it.
    motion : Motion

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    rows = np.column_stack([motion.t_s, motion.positions_m.reshape(motion.n_frames, -1)])
    lines = [",".join(csv_header(motion.joint_names))] + [",".join(f"{v:.9g}" for v in r) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")
    write_json_atomic(skeleton_beside(path), {"joints": list(motion.joint_names),
                                              "parents": [int(p) for p in motion.parents]})
    return path
