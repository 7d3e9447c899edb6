"""The synthesized curves as files: the per-frame CSV and the Live Link Face CSV.

One writer for ``effortface synth``, the Synthesize stage's export and ``effortface demo``.
The CSV has the columns ``t_s,w_per_kg,p_per_kg,nhr,hr_bpm,vo2,resp_rate,epoc`` and one per
blendshape (:attr:`effortface.synth.runtime.FaceModel.columns`); the Live Link Face CSV is the one
Unreal's importer reads (``Timecode``, ``BlendShapeCount``, the 52 ARKit blendshapes in the app's
column order, then the nine head and eye rotations), with our blendshapes written under their ARKit
names and every other column 0. Beside the per-frame CSV, ``<name>.units.json`` gives each
column's unit (:data:`CURVE_UNITS`; the CSV's header line stays as it was, for existing readers).
An existing file is never replaced without ``force``.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError, not_text_error
from effortface.core.fileio import atomic_write, atomic_write_text, check_regular_file
from effortface.synth.runtime import FaceModel

#: the file formats of :func:`write_curves` out of the box (:func:`curve_formats` adds registered ones)
CURVE_FORMATS = ("csv", "livelink")
#: significant digits of the per-frame CSV's values
CSV_DIGITS = 10
#: unit of each column of the per-frame CSV (a blendshape's weight is a fraction, "1"), written to
#: the ``<name>.units.json`` sidecar
CURVE_UNITS = {"t_s": "s", "w_per_kg": "W/kg", "p_per_kg": "W/kg",
               "nhr": "1 (fraction of the heart-rate reserve, 0-1)", "hr_bpm": "beats/min",
               "vo2": "ml/kg/min", "resp_rate": "breaths/min", "epoc": "ml/kg"}
#: unit of a blendshape column
WEIGHT_UNIT = "1 (blendshape weight, 0-1)"

#: Live Link Face CSV columns after Timecode and BlendShapeCount: the 52 ARKit blendshapes in the
#: app's order, then head and eye rotations (BlendShapeCount = 61 counts all of them).
LIVELINK_BLENDSHAPES = (
    "EyeBlinkLeft", "EyeLookDownLeft", "EyeLookInLeft", "EyeLookOutLeft", "EyeLookUpLeft",
    "EyeSquintLeft", "EyeWideLeft", "EyeBlinkRight", "EyeLookDownRight", "EyeLookInRight",
    "EyeLookOutRight", "EyeLookUpRight", "EyeSquintRight", "EyeWideRight", "JawForward", "JawRight",
    "JawLeft", "JawOpen", "MouthClose", "MouthFunnel", "MouthPucker", "MouthRight", "MouthLeft",
    "MouthSmileLeft", "MouthSmileRight", "MouthFrownLeft", "MouthFrownRight", "MouthDimpleLeft",
    "MouthDimpleRight", "MouthStretchLeft", "MouthStretchRight", "MouthRollLower", "MouthRollUpper",
    "MouthShrugLower", "MouthShrugUpper", "MouthPressLeft", "MouthPressRight", "MouthLowerDownLeft",
    "MouthLowerDownRight", "MouthUpperUpLeft", "MouthUpperUpRight", "BrowDownLeft", "BrowDownRight",
    "BrowInnerUp", "BrowOuterUpLeft", "BrowOuterUpRight", "CheekPuff", "CheekSquintLeft",
    "CheekSquintRight", "NoseSneerLeft", "NoseSneerRight", "TongueOut",
)
LIVELINK_ROTATIONS = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch",
                      "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll")
#: Live Link Face timecode rate (frames per second of the HH:MM:SS:FF.fff stamp; the app's default).
LIVELINK_TIMECODE_FPS = 60


#: rows formatted by one %-operation in :func:`curves_csv` (fewer Python steps: 30 % faster than
#: one row at a time on 72,000 rows)
CSV_BLOCK_ROWS = 64


def curves_csv(curves: Mapping[str, np.ndarray], columns: Sequence[str], digits: int = CSV_DIGITS,
               header: bool = True) -> str:
    """The per-frame CSV text (header + one row per frame, values to ``digits`` significant digits;
    without the header line for a later piece of a clip written piece by piece)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    if header:
        writer.writerow(columns)
    values = np.column_stack([curves[c] for c in columns]).ravel().tolist()
    row_format = ",".join([f"%.{digits}g"] * len(columns)) + "\n"
    block, width = row_format * CSV_BLOCK_ROWS, len(columns) * CSV_BLOCK_ROWS
    whole = len(values) - len(values) % width
    buf.writelines(block % tuple(values[i:i + width]) for i in range(0, whole, width))
    buf.writelines(row_format % tuple(values[i:i + len(columns)]) for i in range(whole, len(values), len(columns)))
    return buf.getvalue()


def livelink_timecode(t_s: float, fps: int = LIVELINK_TIMECODE_FPS) -> str:
    """``HH:MM:SS:FF.fff``: FF is the frame within the second at ``fps``, .fff the sub-frame."""
    frames = t_s * fps
    whole = int(np.floor(frames + 1e-9))
    sub = max(frames - whole, 0.0)
    seconds, ff = divmod(whole, fps)
    minutes, ss = divmod(seconds, 60)
    hh, mm = divmod(minutes, 60)
    return f"{hh:02d}:{mm:02d}:{ss:02d}:{ff:02d}.{int(round(sub * 1000)) % 1000:03d}"


def livelink_rows(curves: Mapping[str, np.ndarray], names: Sequence[str],
                  fps: int = LIVELINK_TIMECODE_FPS) -> dict[str, np.ndarray]:
    """``t_s`` and the curves ``names`` linearly resampled to one row per timecode frame at ``fps``
    (the frames from the first to the last motion frame): importers that key one row per frame then
    keep the motion's time (a 200 Hz clip gave 3.3 rows per frame before)."""
    t = np.asarray(curves["t_s"], dtype=float)
    if len(t) < 2:
        return {k: np.asarray(curves[k], dtype=float) for k in ("t_s", *names)}
    grid = np.arange(np.ceil(t[0] * fps - 1e-9), np.floor(t[-1] * fps + 1e-9) + 1) / fps
    return {"t_s": grid, **{k: np.interp(grid, t, np.asarray(curves[k], dtype=float)) for k in names}}


def livelink_csv(curves: Mapping[str, np.ndarray], blendshapes: BlendshapeSet, every_frame: bool = False,
                 header: bool = True) -> str:
    """A Live Link Face CSV: our blendshapes under their ARKit names, every other column 0; one row
    per frame of its 60 fps timecode (:func:`livelink_rows`), or per motion frame with ``every_frame``
    (rows already resampled, and no header line, for a later piece of a clip: ``header=False``)."""
    if not every_frame:
        curves = livelink_rows(curves, [shape.name for shape in blendshapes.shapes])
    n = len(curves["t_s"])
    values = {name: np.zeros(n) for name in LIVELINK_BLENDSHAPES + LIVELINK_ROTATIONS}
    for shape in blendshapes.shapes:
        for arkit in shape.arkit:
            column = arkit[:1].upper() + arkit[1:]
            if column not in values:
                raise UserError(f"blendshape {shape.name}: expected ARKit names, found {arkit!r}")
            values[column] = curves[shape.name]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    columns = ["Timecode", "BlendShapeCount", *LIVELINK_BLENDSHAPES, *LIVELINK_ROTATIONS]
    if header:
        writer.writerow(columns)
    count = len(LIVELINK_BLENDSHAPES) + len(LIVELINK_ROTATIONS)
    table = np.column_stack([values[c] for c in columns[2:]])
    for t, row in zip(curves["t_s"], table):
        writer.writerow([livelink_timecode(float(t)), count, *(f"{v:.6f}" for v in row)])
    return buf.getvalue()


def units_path(path: Path) -> Path:
    """The units sidecar of the per-frame CSV ``path``: ``face.csv`` -> ``face.units.json``."""
    return path.with_name(path.stem + ".units.json")


def units_json(columns: Sequence[str], motion: str | None = None,
               reading: Mapping[str, Any] | None = None) -> str:
    """The sidecar text: ``{"units": {column: unit}}`` for ``columns`` (blendshapes: a weight),
    ``"motion"``: where the motion came from and what was done to it (gaps filled...), and
    ``"reading"``: how it was read (``unit_m``, ``unit_from``, ``up_axis``, ``up_from``, the body the
    plausibility gate measured: :func:`effortface.synth.plausibility.reading_record`), when given."""
    units = {c: CURVE_UNITS.get(c, WEIGHT_UNIT) for c in columns}
    return json.dumps({"units": units, **({"motion": motion} if motion else {}),
                       **({"reading": dict(reading)} if reading else {})}, indent=2) + "\n"


def output_files(path: Path, fmt: str) -> list[Path]:
    """The files a curves output writes: ``path``, and its units sidecar for the ``csv`` format."""
    return [path, units_path(path)] if fmt == "csv" else [path]


def check_output(path: Path, force: bool, fmt: str = "livelink") -> None:
    """Raise a UserError naming ``--out`` unless ``path`` can be (re)written as a file.

    Parameters
    ----------
    path : Path
        The ``--out`` file.
    force : bool
        Whether an existing file may be replaced.
    fmt : {"csv", "livelink"}
        The format: a ``csv`` also writes its units sidecar (:func:`units_path`), checked too.
    """
    if path.is_dir():
        raise UserError(f"--out {path}: expected a file path, found a folder")
    existing = [t for t in output_files(path, fmt) if t.exists()]
    if existing and not force:
        raise UserError(f"--out {path}: expected a new file, found an existing {existing[0]} "
                        "(use --force to replace it)")
    if not path.parent.is_dir():
        raise UserError(f"--out {path}: expected an existing folder, found no {path.parent}")


def write_output(path: Path, text: str, force: bool) -> None:
    """Write an output file atomically; refuse an existing file unless ``force`` (UserError).

    Parameters
    ----------
    path : Path
        The ``--out`` file.
    text : str
        The file's content.
    force : bool
        Whether an existing file may be replaced.

    Raises
    ------
    UserError
        A folder, an existing file without ``force``, a missing folder or a failed write (one
        line naming ``--out``).
    """
    check_output(path, force)
    try:
        atomic_write_text(path, text)
    except OSError as exc:
        raise UserError(f"--out {path}: expected a writable file, found {exc.strerror or exc}") from None


#: a curve format: (curves, model, digits) -> the file's text
CurveFormat = Callable[[Mapping[str, np.ndarray], FaceModel, int], str]
_FORMATS: dict[str, CurveFormat] = {}


def register_curve_format(name: str, to_text: CurveFormat) -> None:
    """Make :func:`write_curves` (``fmt=name``) write another file format.

    Parameters
    ----------
    name : str
        The format's name (lower case, no spaces), e.g. ``"json"``; registering a name again
        replaces its writer.
    to_text : callable
        ``to_text(curves, model, digits) -> str``: ``curves`` maps each column of
        ``model.columns`` (``t_s``, work, power, heart rate..., then the blendshapes) to one
        value per frame.

    Raises
    ------
    ValueError
        If ``name`` is empty or holds anything but lower-case letters, digits, ``_`` and ``-``.
    """
    if not (isinstance(name, str) and name and all(c.islower() or c.isdigit() or c in "_-" for c in name)):
        raise ValueError(f"name: expected a lower-case format name such as 'json', found {name!r}")
    _FORMATS[name] = to_text


def curve_formats() -> tuple[str, ...]:
    """The formats :func:`write_curves` writes now: :data:`CURVE_FORMATS` and the registered ones."""
    return tuple(_FORMATS)


def curves_text(curves: Mapping[str, np.ndarray], model: FaceModel, fmt: str = "csv",
                digits: int = CSV_DIGITS, every_frame: bool = False) -> str:
    """The curves of ``model`` as the text of a ``fmt`` file.

    Parameters
    ----------
    curves : mapping of str to array
        From :meth:`FaceModel.synthesize` or :meth:`FaceModel.curves_from_work`.
    model : FaceModel
        The model that made them (its columns and blendshapes).
    fmt : str
        One of :func:`curve_formats`: ``"csv"`` (the per-frame CSV), ``"livelink"`` (a Live Link
        Face CSV) or a registered one.
    digits : int
        Significant digits of the per-frame CSV.
    every_frame : bool
        Live Link: one row per motion frame instead of per timecode frame (60 fps).

    Returns
    -------
    str

    Raises
    ------
    UserError
        An unknown format, or a blendshape whose ARKit names Live Link does not know.
    """
    to_text = _FORMATS.get(fmt)
    if to_text is None:
        raise UserError(f"format: expected one of {', '.join(curve_formats())}, found {fmt!r}")
    if fmt == "livelink" and every_frame:
        return livelink_csv(curves, model.blendshapes, every_frame=True)
    return to_text(curves, model, digits)


def write_curves(path: str | Path, curves: Mapping[str, np.ndarray], model: FaceModel, *,
                 fmt: str = "csv", force: bool = False, digits: int = CSV_DIGITS,
                 provenance: str | None = None, every_frame: bool = False,
                 reading: Mapping[str, Any] | None = None) -> Path:
    """Write the curves of ``model`` as a ``fmt`` file (atomically; see :func:`curves_text`).

    Parameters
    ----------
    path : path-like
        The file to write.
    curves, model, fmt, digits
        As for :func:`curves_text`.
    force : bool
        Replace an existing file (and, for ``csv``, its units sidecar).
    provenance : str, optional
        The motion's :attr:`~effortface.synth.motion.Motion.source`, kept in the units sidecar.
    every_frame : bool
        Live Link: keep every motion frame (see :func:`livelink_csv`).
    reading : mapping, optional
        How the motion was read (unit, up axis, body figures), kept in the units sidecar.

    Returns
    -------
    Path
        ``path`` (a ``csv`` also writes :func:`units_path` of it).

    Raises
    ------
    UserError
        As :func:`curves_text` and :func:`write_output`.
    """
    write_curve_chunks(path, [curves], model, fmt=fmt, force=force, digits=digits, provenance=provenance,
                       every_frame=every_frame, reading=reading)  # one writer for whole and streamed curves
    return Path(path)


class LivelinkResampler:
    """:func:`livelink_rows` on a clip given piece by piece (the same rows: a timecode frame is
    interpolated between the two motion frames around it, the last frame of a piece is kept for
    the next)."""

    def __init__(self, names: Sequence[str], fps: int = LIVELINK_TIMECODE_FPS) -> None:
        self.names, self.fps = tuple(names), fps
        self._last: dict[str, np.ndarray] | None = None
        self._next: float | None = None  # the next timecode frame's number

    def push(self, curves: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The rows of the timecode frames up to the last motion frame of ``curves``."""
        keys = ("t_s", *self.names)
        piece = {k: np.asarray(curves[k], dtype=float) for k in keys}
        if not len(piece["t_s"]):
            return {k: np.zeros(0) for k in keys}
        if self._next is None:
            self._next = float(np.ceil(piece["t_s"][0] * self.fps - 1e-9))
        held = piece if self._last is None else {k: np.concatenate([self._last[k], piece[k]]) for k in keys}
        stop = float(np.floor(piece["t_s"][-1] * self.fps + 1e-9))
        grid = np.arange(self._next, stop + 1) / self.fps
        self._next = max(self._next, stop + 1)
        self._last = {k: held[k][-1:] for k in keys}
        if len(held["t_s"]) < 2:  # a one-frame clip: its frame, as livelink_rows gives it
            return dict(held)
        return {"t_s": grid, **{k: np.interp(grid, held["t_s"], held[k]) for k in self.names}}


def write_curve_chunks(path: str | Path, chunks: Iterable[Mapping[str, np.ndarray]], model: FaceModel, *,
                       fmt: str = "csv", force: bool = False, digits: int = CSV_DIGITS,
                       provenance: str | None = None, every_frame: bool = False,
                       reading: Mapping[str, Any] | None = None) -> tuple[int, float]:
    """:func:`write_curves` for curves given piece by piece (e.g.
    :func:`effortface.synth.chunked.synthesize_chunks`): each piece is written as it comes.

    The file is written atomically (a temporary file beside ``path``, renamed at the end, removed
    if a piece fails), and holds the same text as :func:`write_curves` on the whole curves. The
    two CSV formats are written piece by piece; a registered format
    (:func:`register_curve_format`) turns the whole curves into text at once, so for it the
    pieces are joined first (the curves only: 8 + B float64 per frame, 41 MB for an hour at
    120 Hz with 4 blendshapes, besides its text).

    Returns
    -------
    (int, float)
        Frames written and the clip's duration in seconds (last frame's time minus the first's).

    Raises
    ------
    UserError
        As :func:`write_curves`.
    """
    out = Path(path)
    check_output(out, force, fmt)
    if fmt not in _FORMATS:
        raise UserError(f"format: expected one of {', '.join(curve_formats())}, found {fmt!r}")
    seen = {"frames": 0, "first": 0.0, "last": 0.0}

    def counted() -> Iterator[Mapping[str, np.ndarray]]:
        for piece in chunks:
            t = np.asarray(piece["t_s"])
            if len(t):
                seen["first"] = float(t[0]) if not seen["frames"] else seen["first"]
                seen["last"] = float(t[-1])
                seen["frames"] += len(t)
            yield piece

    def write(fh: IO[bytes]) -> None:
        for text in _chunk_texts(counted(), model, fmt, digits, every_frame):
            fh.write(text.encode("utf-8"))

    try:
        atomic_write(out, write)
    except OSError as exc:
        raise UserError(f"--out {out}: expected a writable file, found {exc.strerror or exc}") from None
    if fmt == "csv":
        write_output(units_path(out), units_json(model.columns, provenance, reading), force=True)
    return int(seen["frames"]), seen["last"] - seen["first"]


def _chunk_texts(chunks: Iterable[Mapping[str, np.ndarray]], model: FaceModel, fmt: str, digits: int,
                 every_frame: bool) -> Iterator[str]:
    """The text of a curves file, piece by piece (see :func:`write_curve_chunks`)."""
    piecewise = _FORMATS.get(fmt) is _PIECEWISE.get(fmt)
    if fmt == "csv" and piecewise:
        for k, piece in enumerate(chunks):
            yield curves_csv(piece, model.columns, digits, header=k == 0)
    elif fmt == "livelink" and piecewise:
        resampler = LivelinkResampler([shape.name for shape in model.blendshapes.shapes])
        for k, piece in enumerate(chunks):
            rows = piece if every_frame else resampler.push(piece)
            yield livelink_csv(rows, model.blendshapes, every_frame=True, header=k == 0)
    else:
        pieces = list(chunks)
        whole = {c: np.concatenate([np.asarray(p[c]) for p in pieces]) for c in model.columns}
        yield curves_text(whole, model, fmt, digits, every_frame)


# --------------------------------------------------------------------------- reading back

def read_curves(path: str | Path) -> dict[str, np.ndarray]:
    """Read a curves file written by :func:`write_curves`: the per-frame CSV or a Live Link Face CSV.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict of ndarray, each (T,)
        ``t_s`` (from the first row; a Live Link file's timecodes at :data:`LIVELINK_TIMECODE_FPS`)
        and every other column; a Live Link file's blendshape columns under their ARKit names
        (``JawOpen`` -> ``jawOpen``), its rotations left out.

    Raises
    ------
    UserError
        One line naming the file, the expected header or value and what was found.
    """
    path = check_regular_file(path, "a curves CSV (effortface synth)")
    with path.open(encoding="utf-8", errors="replace", newline="") as f:
        reader = csv.reader(f)
        try:
            rows = list(reader)
        except csv.Error as exc:  # a field over the csv module's limit
            raise UserError(str(not_text_error(path, exc, reader.line_num))) from None
    header = rows[0] if rows else []
    livelink = bool(header) and header[0] == "Timecode"
    if not livelink and (not header or header[0] != "t_s"):
        raise UserError(f"{path}: expected a header starting with t_s (per-frame CSV) or Timecode "
                        f"(Live Link Face CSV), found {','.join(header)[:60]!r}")
    if len(rows) < 2:
        raise UserError(f"{path}: expected at least one row of values, found none")
    if livelink:
        keep = [i for i, c in enumerate(header) if c in LIVELINK_BLENDSHAPES]
        times = [_timecode_s(path, n + 2, r[0] if r else "") for n, r in enumerate(rows[1:])]
        names = [header[i][:1].lower() + header[i][1:] for i in keep]
        values = _values(path, [[r[i] if i < len(r) else "" for i in keep] for r in rows[1:]], names)
        t = np.asarray(times)
        return {"t_s": t - t[0], **{n: values[:, k] for k, n in enumerate(names)}}
    values = _values(path, rows[1:], header)
    return {c: values[:, k] for k, c in enumerate(header)}


def _values(path: Path, rows: list[list[str]], names: Sequence[str]) -> np.ndarray:
    """The rows as a (T, C) float table; the first bad cell named."""
    for n, row in enumerate(rows):
        if len(row) != len(names):
            raise UserError(f"{path}: line {n + 2}: expected {len(names)} values, found {len(row)}")
    try:
        return np.array(rows, dtype=float).reshape(len(rows), len(names))
    except ValueError:
        for n, row in enumerate(rows):
            for name, cell in zip(names, row):
                try:
                    float(cell)
                except ValueError:
                    raise UserError(f"{path}: line {n + 2}, column {name}: expected a number, "
                                    f"found {cell!r}") from None
        raise


def _timecode_s(path: Path, line: int, text: str) -> float:
    """Seconds of a Live Link ``HH:MM:SS:FF.fff`` timecode (:func:`livelink_timecode`)."""
    try:
        hh, mm, ss, ff = text.split(":")
        return (int(hh) * 60 + int(mm)) * 60 + int(ss) + float(ff) / LIVELINK_TIMECODE_FPS
    except ValueError:
        raise UserError(f"{path}: line {line}: expected a timecode HH:MM:SS:FF.fff, found {text!r}") from None


register_curve_format("csv", lambda curves, model, digits: curves_csv(curves, model.columns, digits))
register_curve_format("livelink", lambda curves, model, digits: livelink_csv(curves, model.blendshapes))
#: the formats :func:`write_curve_chunks` writes piece by piece (while their writers are these)
_PIECEWISE = {name: _FORMATS[name] for name in CURVE_FORMATS}
