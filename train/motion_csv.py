"""Plain joint-positions CSV motion and skeleton files (numpy only: the runtime reads them).

**Joint-positions CSV** (``.csv``): a header ``t_s,<joint>_x_m,<joint>_y_m,<joint>_z_m,...`` (three
columns per joint, in that order, metres, Z up), then one row per frame at a constant frame rate
(taken from the median step of ``t_s``). Parents come from a skeleton file beside the clip,
``<clip stem>.skeleton.json``; without one every joint is a root (segments are found by joint
name, so parents are not needed for work and power).

**Skeleton file** (``.skeleton.json``): ``{"joints": [names], "parents": [index or -1]}`` with parents
listed before their children, optionally ``"rest_positions_m": [[x, y, z], ...]`` (a reference pose,
metres, Z up, used by ``effortface serve --input lsl`` for a ``MoCap`` stream).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text, write_json_atomic
from effortface.train.motion import Motion, MotionFormatError, motion_from_positions

#: the suffix of a skeleton file beside a clip
SKELETON_SUFFIX = ".skeleton.json"
_AXES = ("_x_m", "_y_m", "_z_m")


def csv_header(joint_names: list[str] | tuple[str, ...]) -> list[str]:
    """The header of a joint-positions CSV for these joints (``t_s`` first)."""
    return ["t_s"] + [f"{name}{axis}" for name in joint_names for axis in _AXES]


def is_positions_csv(path: str | os.PathLike) -> bool:
    """Whether a file starts with a joint-positions header (``t_s,<joint>_x_m,...``)."""
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.readline(4096).strip().split(",")
    except (OSError, UnicodeDecodeError):
        return False
    return len(head) >= 4 and head[0] == "t_s" and head[1].endswith(_AXES[0])


def _joints_from_header(path: Path, header: list[str]) -> list[str]:
    """Joint names from ``t_s,<j>_x_m,<j>_y_m,<j>_z_m,...``; a one-line error otherwise."""
    if not header or header[0] != "t_s" or (len(header) - 1) % 3 or len(header) < 4:
        raise MotionFormatError(f"{path}: line 1: expected the header t_s,<joint>_x_m,<joint>_y_m,"
                                f"<joint>_z_m,... found {','.join(header)[:80]!r}")
    names = []
    for i in range(1, len(header), 3):
        stem = header[i][: -len(_AXES[0])]
        if [header[i + k] for k in range(3)] != [stem + a for a in _AXES] or not stem:
            raise MotionFormatError(f"{path}: line 1, column {i + 1}: expected {stem or '<joint>'}_x_m,"
                                    f"_y_m,_z_m, found {','.join(header[i:i + 3])!r}")
        names.append(stem)
    return names


def read_skeleton(path: str | os.PathLike) -> dict:
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


def read_positions_csv(path: str | os.PathLike) -> Motion:
    """Read a joint-positions CSV (see the module docstring) as a :class:`Motion`.

    Raises
    ------
    MotionFormatError
        Bad header, a row that is not numbers, a non-constant or non-increasing ``t_s``.
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as fh:
            header = fh.readline().strip().split(",")
            joints = _joints_from_header(path, header)
            table = np.loadtxt(fh, delimiter=",", ndmin=2)
    except FileNotFoundError:
        raise MotionFormatError(f"{path}: expected a joint-positions CSV, found no such file") from None
    except ValueError as exc:
        raise MotionFormatError(f"{path}: expected rows of {len(header)} numbers, found {exc}") from None
    if table.shape[0] < 2 or table.shape[1] != len(header):
        raise MotionFormatError(f"{path}: expected at least 2 rows of {len(header)} numbers, "
                                f"found {table.shape[0]} rows of {table.shape[1]}")
    step_s = np.diff(table[:, 0])
    if not np.all(step_s > 0):
        row = int(np.flatnonzero(~(step_s > 0))[0]) + 3
        raise MotionFormatError(f"{path}: line {row}: t_s: expected increasing times, found {table[row - 2, 0]:g}")
    skeleton = skeleton_beside(path)
    parents = read_skeleton(skeleton)["parents"] if skeleton.is_file() else np.full(len(joints), -1)
    if len(parents) != len(joints):
        raise MotionFormatError(f"{skeleton}: expected {len(joints)} joints as in {path.name}, found {len(parents)}")
    positions_m = table[:, 1:].reshape(len(table), len(joints), 3)
    return motion_from_positions(positions_m, joints, parents, 1.0 / float(np.median(step_s)), source=str(path))


def write_positions_csv(path: str | os.PathLike, motion: Motion) -> Path:
    """Write a :class:`Motion`'s joint positions as a joint-positions CSV (and its skeleton file)."""
    path = Path(path)
    rows = np.column_stack([motion.t_s, motion.positions_m.reshape(motion.n_frames, -1)])
    lines = [",".join(csv_header(motion.joint_names))] + [",".join(f"{v:.9g}" for v in r) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")
    write_json_atomic(skeleton_beside(path), {"joints": list(motion.joint_names),
                                              "parents": [int(p) for p in motion.parents]})
    return path
