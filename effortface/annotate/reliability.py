"""The reliability round's files: the pose set and the blind ratings (pure Python + numpy).

- ``poses.csv``: ``pose_id,session_id,frame,t_s`` - the representative frames every rater keys;
- ``ratings.csv``: long format ``pose_id,rater,blendshape,weight`` (the ``--ratings`` format of
  ``effortface agreement``).

:func:`mean_abs_disagreement_pct` is the paper's agreement figure (11 % for 3 raters, 18 poses):
the mean, over poses, blendshapes and rater pairs, of ``|w_a - w_b|`` in % of the weight range
[0, 1]. The full statistics (ICC, Krippendorff's alpha) belong to the agreement module.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from effortface.core import bounds
from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import SessionFormatError, UserError, not_text_error
from effortface.core.fileio import atomic_write_text, refuse_overwrite

POSES_HEADER = ("pose_id", "session_id", "frame", "t_s")
RATINGS_HEADER = ("pose_id", "rater", "blendshape", "weight")
CORRECTIONS_HEADER = ("time_utc", "pose_id", "blendshape", "old", "new", "reason")
#: largest difference (s) between a pose's t_s and its frame's time in the session's video_frames.csv
POSE_TIME_TOLERANCE_S = 1e-3


@dataclasses.dataclass(frozen=True)
class Pose:
    """One representative frame: ``pose_id``, its ``session_id``, video ``frame`` and time ``t_s``."""

    pose_id: str
    session_id: str
    frame: int
    t_s: float


@dataclasses.dataclass(frozen=True)
class Rating:
    """One rater's weight in [0, 1] for one blendshape of one pose."""

    pose_id: str
    rater: str
    blendshape: str
    weight: float


@dataclasses.dataclass(frozen=True)
class Correction:
    """One rating corrected after the blind round: when (ISO 8601 UTC), what, old and new weight, why."""

    time_utc: str
    pose_id: str
    blendshape: str
    old: float
    new: float
    reason: str


def read_corrections(path: str | os.PathLike) -> list[Correction]:
    """Read a ``corrections_<rater>.csv`` log (empty list if it does not exist).

    Raises
    ------
    SessionFormatError
        On missing columns or a weight that is not a number; the message names the file and the line.
    """
    path = Path(path)
    if not path.is_file():
        return []
    out: list[Correction] = []
    for line, row in enumerate(_read_csv(path, CORRECTIONS_HEADER), start=2):
        try:
            out.append(Correction(row["time_utc"], row["pose_id"], row["blendshape"], float(row["old"]),
                                  float(row["new"]), row["reason"]))
        except (TypeError, ValueError):
            raise SessionFormatError(f"{path}:{line}: expected numbers in old,new, found {row}") from None
    return out


def append_correction(path: str | os.PathLike, change: Correction) -> Path:
    """Add one correction to the log, rewriting it whole through a temporary file (atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, corrections_text([*read_corrections(path), change]))


def corrections_text(corrections: Iterable[Correction]) -> str:
    """A whole ``corrections_<rater>.csv`` (header and rows), to write atomically."""
    return _csv_text(CORRECTIONS_HEADER, ((c.time_utc, c.pose_id, c.blendshape, f"{c.old:.4f}", f"{c.new:.4f}",
                                           c.reason) for c in corrections))


def ratings_text(ratings: Iterable[Rating]) -> str:
    """A whole long-format ratings CSV (header and rows), to write atomically."""
    return _csv_text(RATINGS_HEADER, _rating_rows(ratings))


def _rating_rows(ratings: Iterable[Rating]) -> Iterable[tuple[str, str, str, str]]:
    return ((r.pose_id, r.rater, r.blendshape, f"{r.weight:.4f}") for r in ratings)


def _csv_text(header: tuple[str, ...], rows: Iterable[tuple]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return out.getvalue()


def _write_csv(path: Path, header: tuple[str, ...], rows: Iterable[tuple], overwrite: bool) -> Path:
    refuse_overwrite(path, overwrite=overwrite)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)
    return path


def _read_csv(path: Path, header: tuple[str, ...]) -> list[dict[str, str]]:
    """Rows of a CSV whose header must hold ``header``; SessionFormatError otherwise."""
    reader = None
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            found = tuple(reader.fieldnames or ())
            if not set(header) <= set(found):
                raise SessionFormatError(
                    f"{path}: expected columns {','.join(header)}, found {','.join(found) or 'none'}"
                )
            return list(reader)
    except (UnicodeDecodeError, csv.Error) as exc:  # csv.Error: a field over the csv module's limit
        raise not_text_error(path, exc, reader.line_num if reader is not None else None) from None
    except OSError as exc:
        raise SessionFormatError(f"{path}: expected a readable CSV file, found {exc}") from None


def write_poses(path: str | os.PathLike, poses: Iterable[Pose], *, overwrite: bool = False) -> Path:
    """Write ``poses.csv``; FileExistsError if it exists and ``overwrite`` is False."""
    rows = ((p.pose_id, p.session_id, p.frame, f"{p.t_s:.6f}") for p in poses)
    return _write_csv(Path(path), POSES_HEADER, rows, overwrite)


def read_poses(path: str | os.PathLike,
               frames_by_session: Mapping[str, Sequence[float]] | None = None) -> list[Pose]:
    """Read ``poses.csv``.

    Parameters
    ----------
    path : path-like
        The file.
    frames_by_session : mapping, optional
        ``session_id -> frame times (s)`` of the sessions at hand (their ``video_frames.csv``): a pose
        of one of them must name one of its frames, at that frame's time (within
        :data:`POSE_TIME_TOLERANCE_S`). Poses of other sessions are not checked against frames.

    Raises
    ------
    SessionFormatError
        On missing columns, a non-integer frame (or one beyond :data:`effortface.core.bounds.BOUNDS`),
        a non-numeric time, a duplicated pose id, or a pose that contradicts its session's frames;
        the message names the file and the line.
    """
    path = Path(path)
    poses: list[Pose] = []
    for line, row in enumerate(_read_csv(path, POSES_HEADER), start=2):
        try:
            pose = Pose(row["pose_id"], row["session_id"], int(row["frame"]), float(row["t_s"]))
        except (TypeError, ValueError):
            raise SessionFormatError(
                f"{path}:{line}: expected pose_id,session_id,<int frame>,<float t_s>, found {row}"
            ) from None
        if not pose.pose_id or pose.frame < 0 or any(p.pose_id == pose.pose_id for p in poses):
            raise SessionFormatError(
                f"{path}:{line}: expected a unique pose_id and frame >= 0, found {pose}"
            )
        try:
            bounds.check("frame", pose.frame, f"{path}:{line}: frame")
            bounds.check("t_s", pose.t_s, f"{path}:{line}: t_s")
        except UserError as exc:
            raise SessionFormatError(str(exc)) from None
        if frames_by_session is not None and pose.session_id in frames_by_session:
            _check_pose_frame(path, line, pose, frames_by_session[pose.session_id])
        poses.append(pose)
    return poses


def _check_pose_frame(path: Path, line: int, pose: Pose, frame_times_s: Sequence[float]) -> None:
    """SessionFormatError unless ``pose`` names a frame of its session at that frame's time."""
    if not frame_times_s:
        raise SessionFormatError(f"{path}:{line}: session_id: expected a session with video frames, found "
                                 f"{pose.session_id} without video_frames.csv")
    if pose.frame >= len(frame_times_s):
        raise SessionFormatError(f"{path}:{line}: frame: expected a frame of session {pose.session_id} (0 to "
                                 f"{len(frame_times_s) - 1}), found {pose.frame}")
    t_s = frame_times_s[pose.frame]
    if abs(t_s - pose.t_s) > POSE_TIME_TOLERANCE_S:
        raise SessionFormatError(f"{path}:{line}: t_s: expected {t_s:.6f} s, the time of frame {pose.frame} in "
                                 f"session {pose.session_id}'s video_frames.csv, found {pose.t_s:.6f} s")


def write_ratings(path: str | os.PathLike, ratings: Iterable[Rating], *,
                  overwrite: bool = False) -> Path:
    """Write long-format ``ratings.csv``; FileExistsError if it exists and ``overwrite`` is False."""
    return _write_csv(Path(path), RATINGS_HEADER, _rating_rows(ratings), overwrite)


def read_ratings(path: str | os.PathLike, blendshapes: BlendshapeSet | None = None) -> list[Rating]:
    """Read long-format ratings ``pose_id,rater,blendshape,weight``.

    Parameters
    ----------
    path : path-like
        The file.
    blendshapes : BlendshapeSet or None
        The set every ``blendshape`` must belong to (the agreement command passes the paper's,
        :data:`effortface.core.blendshapes.DEFAULT_SET`); None (default) accepts any name.

    Raises
    ------
    SessionFormatError
        On missing columns, a weight that is not a number in [0, 1], a blendshape outside the set, or
        the same (pose, rater, blendshape) twice; the message names the file and the line.
    """
    path = Path(path)
    out: list[Rating] = []
    seen: set[tuple[str, str, str]] = set()
    for line, row in enumerate(_read_csv(path, RATINGS_HEADER), start=2):
        try:
            weight = float(row["weight"])
        except (TypeError, ValueError):
            weight = math.nan
        if not 0.0 <= weight <= 1.0:
            raise SessionFormatError(f"{path}:{line}: expected a weight in [0, 1], found {row['weight']!r}")
        key = (row["pose_id"], row["rater"], row["blendshape"])
        if key in seen or not all(key):
            raise SessionFormatError(
                f"{path}:{line}: expected one non-empty pose_id,rater,blendshape, found {key} again"
            )
        if blendshapes is not None and key[2] not in blendshapes.names:
            raise SessionFormatError(f"{path}:{line}: blendshape: expected one of {', '.join(blendshapes.names)}, "
                                     f"found {key[2]!r:.60}")
        seen.add(key)
        out.append(Rating(*key, weight))
    return out


def mean_abs_disagreement_pct(ratings: Iterable[Rating]) -> float:
    """Mean absolute pairwise difference between raters, in % of the weight range [0, 1].

    For every (pose, blendshape) rated by two or more raters, average ``|w_a - w_b|`` over all rater
    pairs; then average over those items (each item weighs the same).

    Parameters
    ----------
    ratings : iterable of Rating

    Returns
    -------
    float
        Disagreement in percent (0 = identical ratings, 100 = always opposite ends).

    Raises
    ------
    ValueError
        If no pose and blendshape has at least two raters.
    """
    items: dict[tuple[str, str], list[float]] = {}
    for r in ratings:
        items.setdefault((r.pose_id, r.blendshape), []).append(r.weight)
    per_item = [
        sum(abs(a - b) for a, b in pairs) / len(pairs)
        for weights in items.values()
        if (pairs := list(itertools.combinations(weights, 2)))
    ]
    if not per_item:
        raise ValueError("ratings: expected at least one pose and blendshape rated by two raters, found none")
    return 100.0 * sum(per_item) / len(per_item)
