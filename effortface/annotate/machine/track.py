"""The machine rater's files in a session: ``machine/face_landmarker.csv`` and its JSON sidecar.

``face_landmarker.csv`` has one row per row of the session's ``video_frames.csv`` (same frame numbers
and times)::

    frame,t_s,face,mouth_stretch,mouth_open,eye_squint,brow_lower,_neutral,browDownLeft,...,noseSneerRight

``face`` is 1 when the rater found a face, else 0 and every weight and score cell is empty. The four
weights are our blendshapes (after the mapping and calibration the sidecar states, see
:mod:`effortface.annotate.machine.mapping`), the 52 scores MediaPipe's raw ARKit-named outputs.

``face_landmarker.json`` beside it: the model file and its sha256, the software versions, the
mapping and calibration, the frames without a face and the time taken.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from effortface.annotate.machine.landmarker import ARKIT_NAMES
from effortface.core import bounds
from effortface.core.errors import SessionFormatError, UserError, not_text_error
from effortface.core.fileio import atomic_write_together, check_regular_file, json_text, read_json
from effortface.core.session.folder import VIDEO_FRAMES_CSV, read_video_frames

MACHINE_DIR = "machine"
CSV_NAME = "face_landmarker.csv"
SIDECAR_NAME = "face_landmarker.json"
#: our four blendshapes, in the CSV's column order
FOUR = ("mouth_stretch", "mouth_open", "eye_squint", "brow_lower")
HEADER = ("frame", "t_s", "face", *FOUR, *ARKIT_NAMES)
#: largest difference (s) between a track's frame time and the session's video_frames.csv (the CSV
#: holds 4 decimals)
FRAME_TIME_TOLERANCE_S = 1e-3
#: the sidecar's ``format_version``: 2 since the effort mapping (a sidecar without one is version 1:
#: the four weights are the mean of the definition's ARKit scores); the CSV is the same in both
SIDECAR_VERSION = 2

__all__ = ["ARKIT_NAMES", "CSV_NAME", "FOUR", "MACHINE_DIR", "SIDECAR_NAME", "SIDECAR_VERSION", "MachineTrack",
           "read_machine_track", "write_machine_track", "machine_paths"]


@dataclasses.dataclass
class MachineTrack:
    """The machine rater's output for one session.

    Attributes
    ----------
    frame : numpy.ndarray
        (n,) int frame numbers, as in ``video_frames.csv``.
    t_s : numpy.ndarray
        (n,) float frame times in session seconds.
    face : numpy.ndarray
        (n,) bool, True where a face was found.
    weights : numpy.ndarray
        (n, 4) float, our four blendshapes in :data:`FOUR` order, NaN where no face.
    scores : numpy.ndarray
        (n, 52) float, MediaPipe's scores in :data:`ARKIT_NAMES` order, NaN where no face.
    sidecar : dict
        The JSON sidecar (model, versions, mapping, calibration, frames without a face, time taken).
    """

    frame: np.ndarray
    t_s: np.ndarray
    face: np.ndarray
    weights: np.ndarray
    scores: np.ndarray
    sidecar: dict[str, Any]

    def __post_init__(self) -> None:
        n = len(self.frame)
        if (len(self.t_s), len(self.face), self.weights.shape, self.scores.shape) != (n, n, (n, 4), (n, 52)):
            raise ValueError(f"MachineTrack: expected {n} frames in every array with 4 weights and 52 scores, found "
                             f"t_s {len(self.t_s)}, face {len(self.face)}, weights {self.weights.shape}, "
                             f"scores {self.scores.shape}")


def machine_paths(session_dir: Path) -> tuple[Path, Path]:
    """``(csv, sidecar)`` paths of a session's machine rating."""
    folder = Path(session_dir) / MACHINE_DIR
    return folder / CSV_NAME, folder / SIDECAR_NAME


def _cell(value: float) -> str:
    return "" if math.isnan(value) else f"{value:.6g}"


def _csv_text(track: MachineTrack) -> str:
    out = io.StringIO()
    out.write(",".join(HEADER) + "\n")
    for i in range(len(track.frame)):
        face = bool(track.face[i])
        cells = [str(int(track.frame[i])), f"{float(track.t_s[i]):.4f}", "1" if face else "0"]
        if face:
            cells += [_cell(float(v)) for v in track.weights[i]] + [_cell(float(v)) for v in track.scores[i]]
        else:
            cells += [""] * (len(FOUR) + len(ARKIT_NAMES))
        out.write(",".join(cells) + "\n")
    return out.getvalue()


def write_machine_track(session_dir: Path, track: MachineTrack, *, force: bool = False) -> Path:
    """Write ``machine/face_landmarker.csv`` and its sidecar atomically; return the CSV path.

    Both are written whole to temporary files first, then renamed into place together, the CSV
    last (:func:`~effortface.core.fileio.atomic_write_together`): a full disk or a stop leaves the
    previous pair (or none), never a new sidecar beside an old CSV.

    Raises
    ------
    UserError
        When the CSV exists and ``force`` is false (nothing is written).
    """
    csv_path, sidecar_path = machine_paths(session_dir)
    if csv_path.exists() and not force:
        raise UserError(f"{csv_path}: expected no machine rating yet, found one exists (use --force to replace it)")
    csv_path.parent.mkdir(exist_ok=True)
    atomic_write_together({sidecar_path: json_text(track.sidecar), csv_path: _csv_text(track)})
    return csv_path


def _float(text: str, path: Path, line: int, column: str, bound: str) -> float:
    """A cell as a number within ``bounds.BOUNDS[bound]``; SessionFormatError naming the line and column."""
    try:
        value = float(text)
    except ValueError:
        raise SessionFormatError(f"{path}: line {line}: column {column}: expected a number, found {text!r}") from None
    try:
        return bounds.check(bound, value, f"{path}: line {line}: column {column}")
    except UserError as exc:
        raise SessionFormatError(str(exc)) from None


def _parse_row(row: list[str], path: Path, line: int, index: int) -> tuple[int, float, bool, list[float]]:
    """Data row ``index`` (0-based) -> (frame, t_s, face, 56 values with NaN for empty cells); its frame
    must be ``index`` (video_frames.csv's numbering), its weights and scores in [0, 1]."""
    if len(row) != len(HEADER):
        raise SessionFormatError(f"{path}: line {line}: expected {len(HEADER)} columns, found {len(row)}")
    if row[0].strip() != str(index):
        raise SessionFormatError(f"{path}: line {line}: column frame: expected frame {index} (frames 0, 1, 2... "
                                 f"as in {VIDEO_FRAMES_CSV}), found {row[0][:40]!r}")
    frame = index
    t_s = _float(row[1], path, line, "t_s", "t_s")
    if row[2] not in ("0", "1"):
        raise SessionFormatError(f"{path}: line {line}: column face: expected 1 or 0, found {row[2]!r}")
    face = row[2] == "1"
    cells = row[3:]
    if not face and any(cells):
        raise SessionFormatError(f"{path}: line {line}: expected empty weights and scores where face is 0, "
                                 f"found values")
    values = [_float(c, path, line, HEADER[3 + j], "blendshape_weight") if face else math.nan
              for j, c in enumerate(cells)]
    return frame, t_s, face, values


def read_machine_track(session_dir: Path) -> MachineTrack | None:
    """Read a session's machine rating; None when it has none.

    The track must be this session's: one row per frame of ``video_frames.csv`` with its times
    (within :data:`FRAME_TIME_TOLERANCE_S`), weights and scores in [0, 1] and, when the sidecar
    counts them, as many frames as it says.

    Raises
    ------
    SessionFormatError
        Naming the file (and line and column), when the CSV or its sidecar is damaged or the track
        does not fit the session's frames (a track copied from another session).
    """
    csv_path, sidecar_path = machine_paths(session_dir)
    if not csv_path.exists():
        return None
    check_regular_file(csv_path, "a CSV file", SessionFormatError)
    try:
        with open(csv_path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            if header is None or tuple(header) != HEADER:
                raise SessionFormatError(f"{csv_path}: expected header {','.join(HEADER[:8])},...,"
                                         f"{HEADER[-1]} ({len(HEADER)} columns), found "
                                         f"{','.join((header or [])[:8])!r}")
            rows = [_parse_row(row, csv_path, reader.line_num, i) for i, row in enumerate(r for r in reader if r)]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise not_text_error(csv_path, exc) from None
    sidecar = read_json(sidecar_path, "the machine rating's JSON sidecar", SessionFormatError) \
        if sidecar_path.exists() else {}
    if not isinstance(sidecar, dict):
        raise SessionFormatError(f"{sidecar_path}: expected a JSON object, found {type(sidecar).__name__}")
    _check_fits_session(Path(session_dir), csv_path, [r[1] for r in rows], sidecar)
    values = np.array([r[3] for r in rows], dtype=float).reshape(len(rows), len(FOUR) + len(ARKIT_NAMES))
    return MachineTrack(frame=np.array([r[0] for r in rows], dtype=int),
                        t_s=np.array([r[1] for r in rows], dtype=float),
                        face=np.array([r[2] for r in rows], dtype=bool),
                        weights=values[:, :len(FOUR)].copy(), scores=values[:, len(FOUR):].copy(),
                        sidecar=sidecar)


def _check_fits_session(session_dir: Path, csv_path: Path, t_s: list[float], sidecar: dict[str, Any]) -> None:
    """SessionFormatError unless the track's frames are the session's (``video_frames.csv``, when the
    session has one) and as many as its sidecar's ``frames`` count."""
    counted = sidecar.get("frames")
    if isinstance(counted, int) and not isinstance(counted, bool) and counted != len(t_s):
        raise SessionFormatError(f"{csv_path}: expected the {counted} frames its sidecar "
                                 f"{SIDECAR_NAME} counts, found {len(t_s)}")
    frames_csv = session_dir / VIDEO_FRAMES_CSV
    if not frames_csv.is_file():
        return
    video = read_video_frames(frames_csv)
    if len(video) != len(t_s):
        raise SessionFormatError(f"{csv_path}: expected the {len(video)} frames of this session's "
                                 f"{VIDEO_FRAMES_CSV}, found {len(t_s)} (a track of another session's video?)")
    off = np.flatnonzero(np.abs(np.asarray(t_s) - np.asarray(video)) > FRAME_TIME_TOLERANCE_S)
    if off.size:
        k = int(off[0])
        raise SessionFormatError(f"{csv_path}: line {k + 2}: column t_s: expected frame {k} at {video[k]:.4f} s as "
                                 f"in this session's {VIDEO_FRAMES_CSV}, found {t_s[k]:.4f} s (a track of another "
                                 f"session's video?)")
