"""C3D motion, the one reader: labelled points -> a :class:`~effortface.synth.motion.Motion`.

Read with the ``c3d`` package, imported only when a ``.c3d`` file is read (so
:func:`effortface.synth.motion.read_motion` and the runtime stay numpy and scipy only until then);
a file it refuses is read with ezc3d (the pyomeca C++ reader). Measured on 58 real files of BTKData
(c3d.org samples, Vicon, Motion Analysis, PhaseSpace, BKIN...), each through the same checks
(:func:`read_c3d_points`): the ``c3d`` package read 45 (with the old Motion Analysis header quirk
and analog-header mismatches relaxed: a header scale factor that disagrees with ``POINT:SCALE`` gives
way to the parameter, as the C3D specification says, and is stated in the provenance), ezc3d 41;
``c3d`` alone reads the big-endian SGI/MIPS files (ezc3d: "MIPS processor type not supported") and
files whose ``OFFSET`` parameter is not an integer, ezc3d alone the Vicon Nexus Plug-in Gait exports
with a duplicate ``BODYMASS`` parameter. Neither reads a superset, so both are kept, the one that
reads more first (it is also 1.8-2.5x faster on the files both read: 26 vs 46 ms, 31 vs 79 ms);
together they read 49 (the other 9: empty, one frame, no points, damaged parameter sections).

Points are converted from ``POINT:UNITS`` (one unit, or one per point, NUL-padded or not: ``mm``,
``cm``, ``m``, ``in``; mm when the parameter is absent; the caller's ``unit_m`` wins) to metres. The
file's **up axis** comes from ``POINT:Y_SCREEN``, checked against the head and foot markers, or from
the markers alone, and is turned to Z by a proper rotation (the caller's ``up`` wins:
:func:`~effortface.synth.c3d_marker_sets.decide_up`). Subject and rigid-body prefixes
(``Matt:LASI``, Motive's ``Skeleton:LShoulderTop`` / ``Skeleton_LShoulderTop``) are dropped for
matching; a point keeps its label as in the file when two would share a name
(:func:`point_names`), and messages name the label as in the file. Unlabelled trajectories
(``*12``) and model outputs stored as points (``POINT:ANGLES``, ``FORCES``, ``MOMENTS``,
``POWERS``) are left out. A point is **missing** in a frame when its residual is negative (the C3D
convention for an occluded marker), its position is all zeros or not finite. **Occlusions** of at
most :data:`MAX_GAP_S` (0.2 s) are filled by linear interpolation; the frames before the last
marker appears and after the first one disappears are cut; when a needed marker is missing over
more, the **longest window** where every needed marker is present is kept if it lasts at least
:data:`MIN_WINDOW_S` (1 s), else the file is refused in one line naming the point as in the file,
its missing frames and the longest window found (:func:`fill_gaps`). What was filled and cut is
stated in :attr:`Motion.source`, which ``synth`` keeps in the output's ``.units.json``
(``"motion"``), and in :attr:`Motion.reading` (``window``, with the unit, the up axis, the
producer and the marker set). :func:`read_c3d` reads a file one of four ways:

* **Plug-in Gait**, when the file holds at least half of :data:`PLUG_IN_GAIT` or all of
  :data:`PIG_LOWER`: the markers become the joint centres below. The head is the centre of its
  four markers, or of three (the mid-point of the complete diagonal: 2.1 cm from the four-marker
  centre on the real Vicon file of the tests). A lower-body set (no trunk or arm marker) is refused
  in one line: the face's effort needs the trunk and arms.
* **The Qualisys sports marker set** (:data:`QUALISYS_SPORTS`): its labels stand for the Plug-in
  Gait markers of the same places (waist markers for the ASIS/PSIS, ``SpineThoracic2`` for C7,
  ``Chest`` for CLAV...), the head is the centroid of its head markers; same rules.
* **CAST/ISB anatomical landmarks** (Qualisys PAF, Visual3D: ``L_IAS``, ``L_FLE``, ``CV7``...;
  :data:`~effortface.synth.c3d_marker_sets.CAST_ISB`): the same rules, with knee, ankle, elbow
  and wrist centres the mid-points of the lateral and medial landmarks.
* **Labelled points**, otherwise: the points become joints named by their labels, the first point
  the root (the sync jump is looked for in its height) and the others hanging from it: energies
  use positions only. Body segments are found from the labels like any skeleton's joints
  (joint-centre exports such as ``LeftUpLeg``), or from a mapping file (``--mapping``). Points
  missing in every frame are left out.

**The Plug-in Gait marker set** (:data:`PLUG_IN_GAIT`) gives the joints of the skeleton below,
named as the built-in CMU convention of :mod:`effortface.synth.segments` expects, so the 14
segments are found without a mapping file. Joint centres (a **documented simplification** of the
Plug-in Gait model, which needs subject measurements; widths are options of :class:`MarkerSetOptions`):

================  =========================================================================
joint             rule
================  =========================================================================
``Hips``          mid-point of the two hip joint centres
``LeftUpLeg``     hip joint centre, Bell et al. (1990): from the mid-ASIS point, with pelvic
                  width W = |LASI - RASI|: 0.19 W posterior, 0.30 W inferior, 0.36 W lateral,
                  in the pelvis frame (lateral LASI - RASI; forward from SACR or mid-PSIS
                  to mid-ASIS, made orthogonal to it; up = forward x lateral)
``LeftLeg``       knee centre: LKNE moved medially (along the pelvis lateral axis) by half the
                  knee width (default 0.10 m) plus the marker radius
``LeftFoot``      ankle centre: LANK moved medially by half the ankle width (default 0.07 m)
                  plus the marker radius
``LeftToeBase``   LTOE (second metatarsal head)
``Neck1``         mid-point of C7 and CLAV (the cervico-thoracic junction)
``Head_end``      the head markers' centroid (LFHD, RFHD, LBHD, RBHD) moved 0.08 m further along
                  the line from ``Neck1`` through it (the vertex)
``LeftArm``       shoulder centre: LSHO moved down the thorax axis (Neck1 from mid T10-STRN, or
                  from the hips) by the shoulder offset (default 0.05 m)
``LeftForeArm``   elbow centre: LELB moved medially (along the shoulders' lateral axis) by half
                  the elbow width (default 0.07 m) plus the marker radius
``LeftHand``      wrist centre: mid-point of LWRA and LWRB
``LeftHandIndex1`` LFIN
================  =========================================================================

(the right side alike, medial being the opposite direction). When the file also holds Plug-in
Gait's modelled joint centres (``LHJC``, ``LKJC``, ``LAJC``, ``LSJC``, ``LEJC``, ``LWJC`` and the
right side, as Vicon Nexus exports them), those are used instead of the rules.
"""

from __future__ import annotations

import dataclasses
import math
import os
import struct
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any, NoReturn

import numpy as np

from effortface.synth.c3d_marker_sets import (CAST_SET, FOOT_LIKE, HEAD_LIKE, HEAD_MARKERS, JOINT_CENTRES,
                                              OPTIONAL_ROLES, PIG_HELPERS, PIG_LOWER, PLUG_IN_GAIT, QUALISYS_HEAD,
                                              QUALISYS_SPORTS, REQUIRED_ROLES, UPPER_BODY, MarkerSet, choose_set,
                                              decide_up, markers_up, match_names, pick, up_rotation)
from effortface.synth.motion import Motion, MotionFormatError, motion_from_positions
from effortface.synth.read_options import check_unit_m, check_up

__all__ = ["C3dPoints", "FilledPoints", "HEAD_MARKERS", "JOINT_CENTRES", "MarkerSetOptions", "PIG_HELPERS", "PIG_LOWER",
           "PLUG_IN_GAIT", "QUALISYS_HEAD", "QUALISYS_SPORTS", "SKELETON", "UPPER_BODY", "complete_window",
           "fill_gaps", "fillable", "head_centre", "hip_centres", "is_plug_in_gait", "joint_centres", "marker_set",
           "pelvis_frame", "point_names", "producer", "read_c3d", "read_c3d_markers", "read_c3d_points",
           "units_per_point", "window_line", "write_c3d_markers"]

#: the skeleton built from the markers: (joint, parent)
SKELETON = (("Hips", ""), ("LeftUpLeg", "Hips"), ("LeftLeg", "LeftUpLeg"), ("LeftFoot", "LeftLeg"),
            ("LeftToeBase", "LeftFoot"), ("RightUpLeg", "Hips"), ("RightLeg", "RightUpLeg"),
            ("RightFoot", "RightLeg"), ("RightToeBase", "RightFoot"), ("Neck1", "Hips"),
            ("Head_end", "Neck1"), ("LeftArm", "Neck1"), ("LeftForeArm", "LeftArm"),
            ("LeftHand", "LeftForeArm"), ("LeftHandIndex1", "LeftHand"), ("RightArm", "Neck1"),
            ("RightForeArm", "RightArm"), ("RightHand", "RightForeArm"),
            ("RightHandIndex1", "RightHand"))
#: POINT:UNITS -> metres per unit (a file without the parameter is in mm)
C3D_UNITS_M = {"mm": 0.001, "cm": 0.01, "m": 1.0, "in": 0.0254, "meter": 1.0, "meters": 1.0, "metre": 1.0,
               "metres": 1.0, "mete": 1.0, "millimeters": 0.001, "millimetres": 0.001}
#: the ``c3d`` versions read (as pyproject.toml requires)
C3D_REQUIREMENT = "c3d>=0.5.2,<0.7"
#: the longest occlusion filled by linear interpolation, seconds **(choice)**: 0.2 s is a fraction of
#: a stride or a repetition, over which a marker's path is close to straight
MAX_GAP_S = 0.2
#: the shortest window of a trial kept when a needed marker is missing over the rest, seconds
#: **(choice)**: a walking stride lasts about 1 s, the least the effort's averages need
MIN_WINDOW_S = 1.0
#: POINT parameters that list model outputs stored as points (not markers)
NOT_MARKERS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "REACTIONS")
#: the parameters kept in :attr:`C3dPoints.params` (how to read the points, who wrote them)
READ_PARAMS = ("POINT:UNITS", "POINT:X_SCREEN", "POINT:Y_SCREEN", "MANUFACTURER:COMPANY", "MANUFACTURER:SOFTWARE",
               "MANUFACTURER:VERSION", "MANUFACTURER:VERSION_LABEL")


@dataclasses.dataclass(frozen=True)
class MarkerSetOptions:
    """Subject measurements of the joint-centre rules (metres)."""

    knee_width_m: float = 0.10
    ankle_width_m: float = 0.07
    elbow_width_m: float = 0.07
    marker_radius_m: float = 0.007
    shoulder_offset_m: float = 0.05
    head_top_offset_m: float = 0.08


@dataclasses.dataclass(frozen=True)
class C3dPoints:
    """The labelled points of a C3D file, as read (no gap filled).

    Attributes
    ----------
    labels : tuple of str
        One unique name per point (a repeated or empty label gets its index).
    positions_m : ndarray, shape (T, P, 3)
        Positions in metres, in the file's lab frame.
    missing : ndarray of bool, shape (T, P)
        Where a point is missing (see the module docstring).
    rate_hz : float
        Frames per second (``POINT:RATE``).
    notes : tuple of str
        What the reader did that the provenance should say (the reader used, a header quirk).
    file_labels : tuple of str
        Each point's label as it is in the file (prefix kept), for messages; empty: as ``labels``.
    params : dict of str to str
        The parameters that say how to read the points, as the file has them (absent ones left
        out): ``POINT:UNITS``, ``POINT:X_SCREEN``, ``POINT:Y_SCREEN``, ``MANUFACTURER:COMPANY``,
        ``MANUFACTURER:SOFTWARE``, ``MANUFACTURER:VERSION``.
    """

    labels: tuple[str, ...]
    positions_m: np.ndarray
    missing: np.ndarray
    rate_hz: float
    notes: tuple[str, ...] = ()
    file_labels: tuple[str, ...] = ()
    params: dict[str, str] = dataclasses.field(default_factory=dict)

    def file_label(self, name: str) -> str:
        """The label of the point ``name`` as it is in the file."""
        i = self.labels.index(name)
        return self.file_labels[i] if self.file_labels else name


def import_c3d(path: str | os.PathLike[str]) -> ModuleType:
    """The ``c3d`` package, imported now (the one place that imports it); an error naming ``path``
    and the requirement if it is not installed (the numpy/scipy-only runtime does not bring it)."""
    try:
        import c3d
    except ImportError:
        raise MotionFormatError(f"{path}: expected the 'c3d' package to read C3D files, found it not "
                                f"installed (pip install '{C3D_REQUIREMENT}')") from None
    module: ModuleType = c3d
    return module


def _clean(text: object) -> str:
    """A C3D string parameter value without its NUL and space padding."""
    return str(text).replace("\x00", " ").strip()


def units_per_point(path: Path, units: list[str], n_points: int) -> np.ndarray:
    """Metres per unit of each point from ``POINT:UNITS``: one unit for all, or one per point
    (``mm  mm  mm ...``, NUL-padded or not); mm when absent.

    Raises
    ------
    MotionFormatError
        A unit not in :data:`C3D_UNITS_M`, naming it.
    """
    units = [u for u in (_clean(u) for u in units) if u] or ["mm"]
    if len(units) == 1 and " " in units[0]:
        units = units[0].split()
    for unit in units:
        if unit.lower() not in C3D_UNITS_M:
            raise MotionFormatError(f"{path}: POINT:UNITS: expected one of {', '.join(C3D_UNITS_M)}, found {unit!r}")
    scale = [C3D_UNITS_M[u.lower()] for u in units]
    return np.array((scale * n_points)[:n_points] if len(scale) == 1 else (scale + scale[-1:] * n_points)[:n_points])


def _modelled_outputs(params: dict[str, list[str]]) -> set[str]:
    """Labels of points that are model outputs, not markers (``POINT:ANGLES``, ``FORCES``...)."""
    return {_clean(v) for key in NOT_MARKERS for v in params.get(key, [])}


def _read_ezc3d(path: Path) -> C3dPoints:
    """Read with ezc3d (the pyomeca C++ reader: files the ``c3d`` package refuses); its exceptions propagate."""
    import ezc3d

    doc = ezc3d.c3d(str(path))
    params = doc["parameters"]["POINT"]
    def strings(key: str) -> list[str]:
        return [str(v) for v in params[key]["value"]] if key in params else []
    labels = [_clean(v) for key in ("LABELS", *(f"LABELS{i}" for i in range(2, 10))) for v in strings(key)]
    pts = np.asarray(doc["data"]["points"], dtype=float)               # (4, P, T)
    xyz = np.transpose(pts[:3], (2, 1, 0))
    residual = np.asarray(doc["data"]["meta_points"]["residuals"], dtype=float)[0].T if pts.shape[1] else \
        np.zeros(xyz.shape[:2])
    rate_hz = float(np.asarray(params["RATE"]["value"]).ravel()[0])
    other = {k: strings(k) for k in NOT_MARKERS}
    stated = {}
    for key in READ_PARAMS:
        group, name = key.split(":")
        value = doc["parameters"].get(group, {}).get(name, {}).get("value")
        if value is not None and len(value):
            stated[key] = _param_text(value)
    return _points(path, labels, xyz, residual, rate_hz, strings("UNITS"), other, ("read with ezc3d",), stated)


def _read_c3d_package(path: Path) -> C3dPoints:
    """Read with the ``c3d`` package (the old Motion Analysis header quirk relaxed); its exceptions propagate."""
    import c3d  # an ImportError lets ezc3d try

    notes = ["read with the c3d package"]

    class Lenient(c3d.Reader):  # type: ignore[misc,unused-ignore]
        """Motion Analysis wrote a header scale factor that disagrees with POINT:SCALE: the
        parameter wins (the C3D specification: parameters take precedence over the header)."""

        def _check_metadata(self) -> None:
            if self._header.scale_factor != self.point_scale:
                notes.append(f"header scale factor {self._header.scale_factor:.6g} ignored for POINT:SCALE "
                             f"{self.point_scale:.6g}")
                self._header.scale_factor = self.point_scale
            try:
                super()._check_metadata()
            except AssertionError as exc:
                if "analog" not in str(exc):
                    raise
                notes.append(f"analog header ignored ({exc})")

    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file." is not our concern
        reader = Lenient(fh)
        labels = [_clean(label) for label in reader.point_labels]
        rate_hz = float(reader.point_rate)
        units = reader.get("POINT:UNITS")
        unit_list = list(units.string_array) if units is not None and units.dimensions and len(units.dimensions) > 1 \
            else ([units.string_value] if units is not None else [])
        other = {}
        for key in NOT_MARKERS:
            param = reader.get(f"POINT:{key}")
            try:
                other[key] = [str(v) for v in param.string_array] if param is not None else []
            except (AttributeError, ValueError, TypeError):
                other[key] = []
        stated = {key: text for key in READ_PARAMS if (text := _c3d_param_text(reader.get(key)))}
        frames = np.array([points[:, :4] for _, points, _ in reader.read_frames()], dtype=float)
    if frames.ndim != 3:
        frames = np.zeros((len(frames), 0, 4))
    return _points(path, labels, frames[:, :, :3], frames[:, :, 3], rate_hz, unit_list, other, tuple(notes), stated)


def _param_text(value: object) -> str:
    """A parameter's value as text: strings joined by spaces, numbers by dots (``2.17.3720``)."""
    items = list(np.asarray(value).ravel()) if not isinstance(value, str) else [value]
    if items and all(isinstance(v, (int, float, np.integer, np.floating)) for v in items):
        return ".".join(f"{v:g}" for v in items)
    return " ".join(t for t in (_clean(v) for v in items) if t)


def _c3d_param_text(param: object) -> str:
    """A ``c3d`` package parameter as text (see :func:`_param_text`); empty when absent or unreadable."""
    if param is None:
        return ""
    try:
        if getattr(param, "bytes_per_element", 0) == -1:
            dims = getattr(param, "dimensions", [])
            return _param_text(list(param.string_array) if len(dims) > 1 else param.string_value)  # type: ignore[attr-defined]
        return _param_text(param.int16_array if getattr(param, "bytes_per_element", 0) == 2  # type: ignore[attr-defined]
                           else param.float_array)  # type: ignore[attr-defined]
    except (AttributeError, ValueError, TypeError, struct.error):
        return ""


def _points(path: Path, labels: list[str], xyz: np.ndarray, residual: np.ndarray, rate_hz: float, units: list[str],
            other: dict[str, list[str]], notes: tuple[str, ...], stated: dict[str, str] | None = None) -> C3dPoints:
    """C3dPoints in metres from a reader's arrays, model outputs and unlabelled points (``*12``) left out."""
    if len(xyz) < 2:
        raise MotionFormatError(f"{path}: expected at least 2 frames of points, found {len(xyz)}")
    if xyz.shape[1] == 0:
        raise MotionFormatError(f"{path}: expected labelled points, found none")
    scale = units_per_point(path, units, xyz.shape[1])
    file_labels = (labels + [""] * xyz.shape[1])[:xyz.shape[1]]
    names = point_names(file_labels)
    outputs = {k.rsplit(":", 1)[-1] for k in _modelled_outputs(other)}
    keep = [i for i, label in enumerate(file_labels)
            if not label.rsplit(":", 1)[-1].startswith("*") and label.rsplit(":", 1)[-1] not in outputs]
    if not keep:
        raise MotionFormatError(f"{path}: expected labelled markers, found only unlabelled points or model outputs")
    missing = (residual < 0) | ~np.isfinite(xyz).all(axis=2) | (xyz == 0).all(axis=2)
    xyz = np.where(missing[..., None], 0.0, xyz) * scale[None, :, None]
    stated = dict(stated or {})
    if units and "POINT:UNITS" not in stated:
        stated["POINT:UNITS"] = " ".join(dict.fromkeys(u for u in (_clean(u) for u in units) if u))
    return C3dPoints(tuple(names[i] for i in keep), xyz[:, keep], missing[:, keep], rate_hz, notes,
                     tuple(file_labels[i] or names[i] for i in keep), stated)


def read_c3d_points(path: str | os.PathLike[str]) -> C3dPoints:
    """Read the labelled markers of a C3D file in metres, marking the missing ones.

    The ``c3d`` package reads it (it read more of the real files, see the module docstring); a file
    it refuses (Vicon Nexus exports with a duplicate parameter) is read with ezc3d. Points listed in ``POINT:ANGLES``, ``FORCES``, ``MOMENTS``, ``POWERS`` (model
    outputs) and unlabelled trajectories (``*12``) are left out.

    Raises
    ------
    MotionFormatError
        Neither reader can read it, an unknown unit, no markers, fewer than 2 frames.
    """
    path = Path(path)
    if not path.is_file():
        raise MotionFormatError(f"{path}: expected a C3D file, found {'a folder' if path.is_dir() else 'no such file'}")
    errors, missing = [], 0
    for name, reader in (("c3d", _read_c3d_package), ("ezc3d", _read_ezc3d)):
        try:
            return reader(path)
        except MotionFormatError:
            raise
        except ImportError:
            errors.append(f"{name} not installed")
            missing += 1
            if missing == 2:
                import_c3d(path)  # says what to install
        except Exception as exc:  # both readers raise bare or C++ exceptions on a damaged file
            errors.append(f"{name}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:160])
    raise MotionFormatError(f"{path}: expected a C3D file, found one neither reader reads ({'; '.join(errors)})")


def read_c3d_markers(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], float]:
    """Labelled points of a C3D file in metres (short gaps filled), and the point rate.

    Returns
    -------
    dict of ndarray (T, 3), float
        ``label -> positions_m`` (frames every point covers) and frames per second.

    Raises
    ------
    MotionFormatError
        As :func:`read_c3d_points` and :func:`fill_gaps`.
    """
    points = read_c3d_points(path)
    filled = fill_gaps(Path(path), points, list(points.labels))
    return {k: filled.positions_m[:, i] for i, k in enumerate(filled.labels)}, points.rate_hz


def is_plug_in_gait(labels: tuple[str, ...] | list[str]) -> bool:
    """Whether point labels hold at least half of the Plug-in Gait markers (:data:`PLUG_IN_GAIT`)."""
    return len(set(PLUG_IN_GAIT) & set(labels)) >= len(PLUG_IN_GAIT) // 2


@dataclasses.dataclass(frozen=True)
class FilledPoints:
    """Points with their short gaps filled, over the frames they all cover.

    Attributes
    ----------
    labels : tuple of str
    positions_m : ndarray, shape (T', P, 3)
    first_frame : int
        The file's frame that is frame 0 here (leading frames where a point had not appeared are cut).
    note : str
        What was filled and cut, for the provenance.
    window : dict
        ``first_frame``, ``n_frames``, ``of_frames`` and ``why`` (:attr:`Motion.reading`'s ``window``).
    """

    labels: tuple[str, ...]
    positions_m: np.ndarray
    first_frame: int
    note: str
    window: dict[str, int | str] = dataclasses.field(default_factory=dict)


def _runs(missing: np.ndarray) -> list[tuple[int, int]]:
    """``(start, length)`` of each run of True in a 1-D bool array."""
    edges = np.diff(np.concatenate([[0], missing.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b - a)) for a, b in zip(starts, ends)]


def fillable(missing: np.ndarray, max_frames: int) -> np.ndarray:
    """Where each point is present or inside a gap of at most ``max_frames`` with the point on both
    sides (a gap linear interpolation can fill), shape as ``missing`` (T, P)."""
    ok = ~missing
    for j in range(missing.shape[1]):
        for a, n in _runs(missing[:, j]):
            if n <= max_frames and a > 0 and a + n < len(missing):
                ok[a:a + n, j] = True
    return ok


def complete_window(ok: np.ndarray) -> tuple[int, int]:
    """``(first_frame, n_frames)`` of the longest run of frames where every point is ``ok`` (T, P);
    ``(0, 0)`` when there is none (the first such run on a tie)."""
    runs = _runs(np.asarray(ok.all(axis=1), dtype=bool))
    return max(runs, key=lambda r: (r[1], -r[0])) if runs else (0, 0)


def _span(missing: np.ndarray) -> tuple[int, int]:
    """``(first, last)``: from the last first appearance to the first last disappearance of the points."""
    present = ~missing
    first = int(max(np.argmax(present[:, j]) for j in range(present.shape[1])))
    last = int(min(len(present) - 1 - np.argmax(present[::-1, j]) for j in range(present.shape[1])))
    return first, last


def fill_gaps(path: Path, points: C3dPoints, labels: list[str], max_gap_s: float | None = None) -> FilledPoints:
    """The points ``labels`` over the longest window where all are present, their gaps of at most
    ``max_gap_s`` (default :data:`MAX_GAP_S`) linearly interpolated.

    The window is the whole file when every point covers it; the frames at the ends before a point
    appears or after one disappears are cut while at least half the frames remain (as before the
    window existed); otherwise the longest window where every point is present (after the filling)
    is kept if it lasts at least :data:`MIN_WINDOW_S` (a trial trimmed to a walkway), and stated
    (:attr:`FilledPoints.window`).

    Raises
    ------
    MotionFormatError
        A point missing in every frame, or no window long enough: one line naming the file, the
        point as it is in the file (the one missing most), its missing frames and the longest window.
    """
    max_gap_s = MAX_GAP_S if max_gap_s is None else max_gap_s
    max_frames = max(1, int(round(max_gap_s * points.rate_hz)))
    idx = [points.labels.index(k) for k in labels]
    miss = points.missing[:, idx]
    n_all = len(miss)
    for j, k in enumerate(labels):
        if miss[:, j].all():
            raise MotionFormatError(f"{path}: point {points.file_label(k)!r}: expected positions, found it missing "
                                    "in every frame")
    ok = fillable(miss, max_frames)
    first, n = complete_window(ok)
    span_first, span_last = _span(miss)
    min_frames = int(math.ceil(MIN_WINDOW_S * points.rate_hz))
    ends_only = (first, n) == (span_first, span_last - span_first + 1) and n >= max(2, n_all // 2)
    if n < 2 or (n < min_frames and not ends_only):
        _refuse_window(path, points, labels, miss, ok, (first, n), max_gap_s, max_frames)
    t = np.arange(n_all)
    window = t[first:first + n]
    out = np.empty((n, len(idx), 3))
    for j, i in enumerate(idx):
        present = ~miss[:, j]
        xyz = points.positions_m[:, i]
        out[:, j] = np.column_stack([np.interp(window, t[present], xyz[present, c]) for c in range(3)])
    filled = int(miss[first:first + n].sum())
    cut = n_all - n
    note = f"gaps of at most {max_gap_s:g} s linearly interpolated ({filled} point-frames)"
    why = ""
    if cut and ends_only:
        why = "frames cut at the ends where a marker had not appeared"
        note += f"; {cut} {why}"
    elif cut:
        worst = int(np.argmax((~ok).sum(axis=0)))
        why = (f"the longest window where every needed marker is present: {points.file_label(labels[worst])!r} "
               f"is missing or in a gap over {max_gap_s:g} s in {int((~ok[:, worst]).sum())} of {n_all} frames")
        note += (f"; kept frames {first}-{first + n - 1} of {n_all} ({n / points.rate_hz:.2f} s of "
                 f"{n_all / points.rate_hz:.2f} s), {why}")
    return FilledPoints(tuple(labels), out, first, note, {"first_frame": first, "n_frames": n, "of_frames": n_all,
                                                          "why": why or "every needed marker present"})


def _refuse_window(path: Path, points: C3dPoints, labels: list[str], miss: np.ndarray, ok: np.ndarray,
                   window: tuple[int, int], max_gap_s: float, max_frames: int) -> NoReturn:
    """Raise the one-line refusal of a trial without a long enough complete window (:func:`fill_gaps`)."""
    worst = int(np.argmax((~ok).sum(axis=0)))
    label = points.file_label(labels[worst])
    first, n = window
    gaps = [(a, m) for a, m in _runs(miss[:, worst]) if m > max_frames]
    gap = f", a gap of {gaps[0][1]} frames from frame {gaps[0][0]}" if gaps else ""
    raise MotionFormatError(
        f"{path}: point {label!r}: expected every needed marker present (gaps up to {max_gap_s:g} s filled) over "
        f"at least {MIN_WINDOW_S:g} s, found {label!r} missing in {int(miss[:, worst].sum())} of {len(miss)} frames"
        f"{gap}; the longest complete window is {n} frames ({n / points.rate_hz:.2f} s"
        + (f" from frame {first})" if n else ")") + "; fill the gaps in the capture software")


def point_names(labels: list[str]) -> list[str]:
    """One unique name per point, taken from the file's labels: the label without its prefix
    (``Matt:LASI`` -> ``LASI``) when no other point has that name, else the label as it is in the
    file (``ForearmL:Marker3``, ``ForearmR:Marker3``); a label repeated whole gets the point's number
    (``LASI (point 12)``), an empty one is ``point 12`` (numbers from 1)."""
    short = [label.rsplit(":", 1)[-1] for label in labels]
    counts = {k: short.count(k) for k in short}
    out: list[str] = []
    for i, (label, name) in enumerate(zip(labels, short)):
        name = name if counts[name] == 1 else label
        if not name or name in out or labels.count(label) > 1:
            name = f"{label} (point {i + 1})" if label else f"point {i + 1}"
        out.append(name)
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    """``v`` divided by its length along the last axis."""
    unit: np.ndarray = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return unit


def _need(path: Path, markers: dict[str, np.ndarray], labels: tuple[str, ...], set_name: str = "Plug-in Gait") -> None:
    missing = [m for m in labels if m not in markers]
    if missing:
        raise MotionFormatError(f"{path}: expected the {set_name} markers {', '.join(missing)} "
                                f"(see docs: effortface.synth.c3d_motion), found "
                                f"{', '.join(sorted(markers)) or 'no points'}")


def pelvis_frame(m: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit lateral (right to left), forward and up axes of the pelvis, each (T, 3)."""
    lateral = _unit(m["LASI"] - m["RASI"])
    mid_asis = (m["LASI"] + m["RASI"]) / 2
    back = m["SACR"] if "SACR" in m else (m["LPSI"] + m["RPSI"]) / 2 if "LPSI" in m and "RPSI" in m else None
    if back is None:  # no posterior marker: forward is horizontal, perpendicular to the ASIS line
        forward = np.cross(lateral, np.array([0.0, 0.0, 1.0]))
    else:
        forward = mid_asis - back
    forward = _unit(forward - np.sum(forward * lateral, -1, keepdims=True) * lateral)
    return lateral, forward, _unit(np.cross(forward, lateral))


def hip_centres(m: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Left and right hip joint centres by Bell et al. (1990), each (T, 3)."""
    lateral, forward, up = pelvis_frame(m)
    width = np.linalg.norm(m["LASI"] - m["RASI"], axis=-1, keepdims=True)
    mid = (m["LASI"] + m["RASI"]) / 2
    base = mid - 0.19 * width * forward - 0.30 * width * up
    return base + 0.36 * width * lateral, base - 0.36 * width * lateral


def joint_centres(m: dict[str, np.ndarray], opts: MarkerSetOptions = MarkerSetOptions(),
                  source: str | os.PathLike[str] = "markers") -> dict[str, np.ndarray]:
    """The joints of :data:`SKELETON` from Plug-in Gait markers (rules in the module docstring)."""
    _need(Path(source), m, tuple(k for k in PLUG_IN_GAIT if k not in HEAD_MARKERS or "HEAD" not in m))
    lateral, _, _ = pelvis_frame(m)
    j: dict[str, np.ndarray] = {}
    j["LeftUpLeg"], j["RightUpLeg"] = hip_centres(m)
    shoulders_lat = _unit(m["LSHO"] - m["RSHO"])
    j["Neck1"] = (m["C7"] + m["CLAV"]) / 2
    head = m["HEAD"] if "HEAD" in m else (m["LFHD"] + m["RFHD"] + m["LBHD"] + m["RBHD"]) / 4
    j["Head_end"] = head + opts.head_top_offset_m * _unit(head - j["Neck1"])
    j["Hips"] = (j["LeftUpLeg"] + j["RightUpLeg"]) / 2
    low = (m["T10"] + m["STRN"]) / 2 if "T10" in m and "STRN" in m else j["Hips"]
    thorax_up = _unit(j["Neck1"] - low)
    for side, sign, name in (("L", 1.0, "Left"), ("R", -1.0, "Right")):
        j[f"{name}Leg"] = _centre(m, f"{side}KNE", -sign * lateral, opts.knee_width_m / 2 + opts.marker_radius_m)
        j[f"{name}Foot"] = _centre(m, f"{side}ANK", -sign * lateral, opts.ankle_width_m / 2 + opts.marker_radius_m)
        j[f"{name}ToeBase"] = m[f"{side}TOE"]
        j[f"{name}Arm"] = m[f"{side}SHO"] - thorax_up * opts.shoulder_offset_m
        j[f"{name}ForeArm"] = _centre(m, f"{side}ELB", -sign * shoulders_lat,
                                      opts.elbow_width_m / 2 + opts.marker_radius_m)
        j[f"{name}Hand"] = (m[f"{side}WRA"] + m[f"{side}WRB"]) / 2
        j[f"{name}HandIndex1"] = m[f"{side}FIN"]
    for label, joint in JOINT_CENTRES.items():  # modelled centres win when the file has them
        if label in m:
            j[joint] = m[label]
    return j


def _centre(m: dict[str, np.ndarray], role: str, medial: np.ndarray, depth_m: float) -> np.ndarray:
    """A joint centre: the mid-point of the lateral and medial landmarks when both are there
    (``LKNE`` and ``LKNEM``), else the lateral marker moved ``depth_m`` along ``medial``."""
    centre: np.ndarray = (m[role] + m[role + "M"]) / 2 if role + "M" in m else m[role] + medial * depth_m
    return centre


def head_centre(markers: dict[str, np.ndarray], head: tuple[str, ...] = HEAD_MARKERS) -> np.ndarray | None:
    """The head markers' centre from those present: all four, or three of Plug-in Gait's four (the
    mid-point of the diagonal that is complete, the markers lying on a near-parallelogram); None
    with fewer."""
    have = [k for k in head if k in markers]
    if len(have) == len(head):
        return sum(markers[k] for k in head) / len(head)  # type: ignore[return-value]
    if head == HEAD_MARKERS and len(have) == 3:
        for a, b in (("LFHD", "RBHD"), ("RFHD", "LBHD")):
            if a in markers and b in markers:
                mid: np.ndarray = (markers[a] + markers[b]) / 2
                return mid
    if head != HEAD_MARKERS and len(have) >= 3:
        return sum(markers[k] for k in have) / len(have)  # type: ignore[return-value]
    return None


def marker_set(labels: tuple[str, ...] | list[str]) -> str:
    """``"plug-in-gait"``, ``"qualisys-sports"``, ``"cast-isb"`` or ``"labelled"``: the built-in set
    the labels hold at least half of (:func:`~effortface.synth.c3d_marker_sets.choose_set`)."""
    mset = choose_set(labels)
    return "labelled" if mset is None else mset.key


@dataclasses.dataclass(frozen=True)
class _Picked:
    """A built-in set's markers found in a file: ``role -> point names`` (two for a mid-point) and
    ``head marker -> point name``."""

    roles: dict[str, list[str]]
    head: dict[str, str]

    def body(self) -> list[str]:
        """The point names of the required roles."""
        return list(dict.fromkeys(n for r in REQUIRED_ROLES for n in self.roles[r]))

    def helpers(self) -> list[str]:
        """The point names of the optional roles present (not already in :meth:`body`)."""
        body = set(self.body())
        return list(dict.fromkeys(n for r in OPTIONAL_ROLES if r in self.roles for n in self.roles[r] if n not in body))


def _pick_labels(path: Path, points: C3dPoints, mset: MarkerSet) -> _Picked:
    """The markers of ``mset`` in the file (prefixes dropped, :func:`match_names`).

    Raises
    ------
    MotionFormatError
        A lower-body set (no trunk or arm marker), or required markers absent (named).
    """
    found = match_names(points.labels)
    roles = {r: names for r, alts in mset.roles.items() if (names := pick(alts, found)) is not None}
    if not any(k in roles for k in UPPER_BODY):
        raise MotionFormatError(f"{path}: expected a full-body {mset.name} marker set, found the lower body only "
                                f"(no {', '.join(mset.roles[k].split('|')[0] for k in UPPER_BODY[:4])}...): the "
                                "face's effort needs the trunk and arms")
    absent = [mset.roles[r].split("|")[0] for r in REQUIRED_ROLES if r not in roles]
    if absent:
        raise MotionFormatError(f"{path}: expected the {mset.name} markers {', '.join(absent)} (see docs: "
                                f"effortface.synth.c3d_marker_sets), found {_some(points.file_labels)}")
    head = {k: found[k] for k in mset.head if k in found and not points.missing[:, points.labels.index(found[k])].all()}
    return _Picked(roles, head)


def _some(labels: tuple[str, ...], n: int = 12) -> str:
    """The first ``n`` labels, and how many in all when there are more."""
    return ", ".join(labels[:n]) + (f"... ({len(labels)} points)" if len(labels) > n else "") if labels else "none"


def _window_frames(points: C3dPoints, names: list[str]) -> int:
    """The length of the longest complete window of the points ``names`` (:func:`fill_gaps`)."""
    max_frames = max(1, int(round(MAX_GAP_S * points.rate_hz)))
    idx = [points.labels.index(k) for k in names]
    return complete_window(fillable(points.missing[:, idx], max_frames))[1]


def _choose_head(path: Path, points: C3dPoints, body: list[str], head: dict[str, str], set_name: str,
                 head_names: tuple[str, ...]) -> list[str]:
    """The head markers kept (set names): the subset of at least three, all or all but one, that
    leaves the longest complete window with the body markers (the larger subset on a tie).

    Raises
    ------
    MotionFormatError
        Fewer than three head markers with positions.
    """
    if len(head) < 3:
        raise MotionFormatError(f"{path}: expected at least 3 of the head markers {', '.join(head_names[:4])} "
                                f"in most frames, found {', '.join(points.file_label(n) for n in head.values()) or 'none'}"
                                + ("" if set_name == "Plug-in Gait" or len(head_names) <= 4
                                   else f" (or {', '.join(head_names[4:])})"))
    keys = list(head)
    subsets = [keys] + ([[k for k in keys if k != out] for out in keys] if len(keys) > 3 else [])
    return max(subsets, key=lambda sub: (_window_frames(points, body + [head[k] for k in sub]), len(sub)))


def _built_in(path: Path, points: C3dPoints, mset: MarkerSet, options: MarkerSetOptions) -> Motion:
    """The joints of :data:`SKELETON` from a built-in marker set (gaps filled; see the module docstring)."""
    picked = _pick_labels(path, points, mset)
    body = picked.body()
    kept_head = _choose_head(path, points, body, picked.head, mset.name, mset.head)
    needed = body + [picked.head[k] for k in kept_head]
    best = _window_frames(points, needed)
    helpers = [n for n in picked.helpers() if _window_frames(points, needed + [n]) >= best]
    filled = fill_gaps(path, points, needed + helpers)
    by_name = {k: filled.positions_m[:, i] for i, k in enumerate(filled.labels)}
    m: dict[str, np.ndarray] = {role: np.mean([by_name[n] for n in names], axis=0)
                                for role, names in picked.roles.items() if all(n in by_name for n in names)}
    hc = head_centre({k: by_name[picked.head[k]] for k in kept_head}, mset.head)
    assert hc is not None
    m["HEAD"] = hc
    joints = joint_centres(m, options, path)
    order = [name for name, _ in SKELETON]
    parents = [order.index(parent) if parent else -1 for _, parent in SKELETON]
    positions_m = np.stack([joints[n] for n in order], axis=1)
    found = match_names(points.labels)
    dropped = [k for k in mset.head if k in found and k not in kept_head]
    head_note = f"; head from {', '.join(kept_head)}" + (f" ({', '.join(dropped)} left out)" if dropped else "") \
        if dropped or len(kept_head) < 4 else ""
    source = f"{path} ({mset.name} markers, {'; '.join(points.notes)}; {filled.note}{head_note})"
    motion = motion_from_positions(positions_m, order, parents, points.rate_hz, source=source)
    motion.reading["window"] = filled.window
    motion.reading["marker_set"] = f"{mset.key}: {mset.name} markers to joint centres" + (
        " (hip centres by Bell et al. 1990; knee, ankle, elbow, wrist centres mid-points of the epicondyles, "
        "malleoli and styloids)" if mset is CAST_SET else "")
    return motion


def _labelled(path: Path, points: C3dPoints) -> Motion:
    """Labelled points as joints (the first the root), over their longest complete window."""
    present = [k for i, k in enumerate(points.labels) if not points.missing[:, i].all()]
    filled = fill_gaps(path, points, present)
    parents = [-1] + [0] * (len(filled.labels) - 1)
    absent = len(points.labels) - len(present)
    note = filled.note + (f"; {absent} points missing in every frame left out" if absent else "")
    motion = motion_from_positions(filled.positions_m, filled.labels, parents, points.rate_hz,
                                   source=f"{path} (labelled markers, {'; '.join(points.notes)}; {note})")
    motion.reading["window"] = filled.window
    motion.reading["marker_set"] = "labelled: the points as joints, named by their labels"
    return motion


def _up_markers(points: C3dPoints, mset: MarkerSet | None) -> tuple[list[int], list[int]]:
    """Indices of the head-like and foot-like points: the set's head markers and ankles and toes,
    or labels that look like them (:data:`HEAD_LIKE`, :data:`FOOT_LIKE`)."""
    found = match_names(points.labels)
    if mset is not None:
        head = [found[k] for k in mset.head if k in found]
        feet = [n for r in ("LANK", "RANK", "LTOE", "RTOE") for n in (pick(mset.roles[r], found) or [])]
    else:
        head = [n for k, n in found.items() if HEAD_LIKE.search(k)]
        feet = [n for k, n in found.items() if FOOT_LIKE.search(k)]
    return [points.labels.index(n) for n in dict.fromkeys(head)], [points.labels.index(n) for n in dict.fromkeys(feet)]


def producer(params: dict[str, str]) -> str:
    """``MANUFACTURER:COMPANY SOFTWARE VERSION`` as the file has them, or ``""``."""
    version = params.get("MANUFACTURER:VERSION_LABEL") or params.get("MANUFACTURER:VERSION", "")
    return " ".join(v for v in (params.get("MANUFACTURER:COMPANY", ""), params.get("MANUFACTURER:SOFTWARE", ""),
                                version) if v)


def _to_z_up(points: C3dPoints, mset: MarkerSet | None, up: str | None) -> tuple[C3dPoints, dict[str, str]]:
    """The points turned to Z up (:func:`decide_up`, :func:`up_rotation`) and the reading's up keys."""
    head, feet = _up_markers(points, mset)
    axis, how = decide_up(up, points.params.get("POINT:Y_SCREEN", ""),
                          markers_up(points.positions_m, points.missing, head, feet))
    if axis != "z":
        points = dataclasses.replace(points, positions_m=points.positions_m @ up_rotation(axis).T)
    return points, {"up_axis": axis, "up_from": how}


def _with_unit(path: Path, points: C3dPoints, unit_m: float | None) -> tuple[C3dPoints, dict[str, Any]]:
    """The points in metres by the caller's ``unit_m`` (else as ``POINT:UNITS`` said) and the reading's unit keys."""
    units = points.params.get("POINT:UNITS", "").split() or ["mm"]
    stated = " ".join(dict.fromkeys(points.params.get("POINT:UNITS", "").split()))
    if unit_m is not None:
        scale = unit_m / np.array([C3D_UNITS_M.get(u.lower(), 1.0) for u in (units * len(points.labels))[
            :len(points.labels)]]) if len(units) > 1 else unit_m / C3D_UNITS_M.get(units[0].lower(), 1.0)
        return (dataclasses.replace(points, positions_m=points.positions_m * np.reshape(scale, (1, -1, 1))),
                {"unit_m": float(unit_m), "unit_from": "--unit-m" + (f" (POINT:UNITS {stated} ignored)" if stated else "")})
    file_unit = C3D_UNITS_M[units[0].lower()]
    how = f"POINT:UNITS {stated}" if stated else "no POINT:UNITS: mm, the C3D default"
    return points, {"unit_m": file_unit, "unit_from": how + (" (per point)" if len(set(units)) > 1 else "")}


def read_c3d(path: str | os.PathLike[str], *, options: MarkerSetOptions = MarkerSetOptions(),
             up: str | None = None, unit_m: float | None = None, up_axis: str | None = None) -> Motion:
    """Read a C3D file as a :class:`Motion` (metres, Z up): built-in marker-set joint centres or labelled points.

    A file holding at least half of a built-in set (Plug-in Gait, Qualisys sports, CAST/ISB:
    :func:`~effortface.synth.c3d_marker_sets.choose_set`) gives the joints of :data:`SKELETON` by the
    joint-centre rules; any other gives its labelled markers as joints, the first the root. Either
    way gaps of at most :data:`MAX_GAP_S` are linearly interpolated and the longest window where
    every needed marker is present is kept (:func:`fill_gaps`), stated in :attr:`Motion.source`. The
    file's up axis is turned to Z (:func:`~effortface.synth.c3d_marker_sets.decide_up`).
    :attr:`Motion.reading` says how: ``unit_m``/``unit_from``, ``up_axis``/``up_from``,
    ``producer``, ``marker_set``, ``window``.

    Parameters
    ----------
    path : path-like
        The ``.c3d`` file.
    options : MarkerSetOptions
        Subject widths and offsets of the joint-centre rules (built-in marker sets).
    up : str or None
        The file's up axis, one of :data:`~effortface.synth.read_options.UP_AXES` (None: from the
        file's ``POINT:Y_SCREEN`` and the markers).
    unit_m : float or None
        Metres per file unit, instead of ``POINT:UNITS`` (None: the file's).
    up_axis : str or None
        The former name of ``up`` (kept for callers of 0.x).

    Returns
    -------
    Motion
        Without rotations.

    Raises
    ------
    MotionFormatError
        As :func:`read_c3d_points` and :func:`fill_gaps`; a lower-body-only set; required markers
        absent (named).
    UserError
        ``up`` not one of the up axes, ``unit_m`` not a length.
    """
    path = Path(path)
    up = check_up(up if up is not None else up_axis, "up")
    unit_m = check_unit_m(unit_m, "unit_m")
    points = read_c3d_points(path)
    points, unit_keys = _with_unit(path, points, unit_m)
    mset = choose_set(points.labels)
    points, up_keys = _to_z_up(points, mset, up)
    motion = _labelled(path, points) if mset is None else _built_in(path, points, mset, options)
    motion.reading.update(unit_keys, **up_keys)
    if producer(points.params):
        motion.reading["producer"] = producer(points.params)
    return motion


def window_line(reading: dict[str, Any], source: str | os.PathLike[str]) -> str:
    """The line saying a clip was read over a window of its frames (``Motion.reading["window"]``),
    or ``""`` when it was read whole."""
    w = reading.get("window") or {}
    if not w or w.get("n_frames") == w.get("of_frames"):
        return ""
    first, n = int(w["first_frame"]), int(w["n_frames"])
    return f"{source}: read frames {first}-{first + n - 1} of {w['of_frames']}: {w['why']}"


def write_c3d_markers(path: str | os.PathLike[str], markers: dict[str, np.ndarray], rate_hz: float) -> Path:
    """Write labelled points (metres, (T, 3) each) as a C3D file in millimetres (tests, tools).

    Written atomically through :func:`effortface.core.fileio.atomic_write`.
    """
    from effortface.core.fileio import atomic_write

    c3d = import_c3d(path)
    labels = list(markers)
    stacked_mm = np.stack([markers[k] for k in labels], axis=1) * 1000.0      # (T, P, 3)
    writer = c3d.Writer(point_rate=float(rate_hz), analog_rate=0.0, point_units="mm  ")
    writer.set_point_labels(labels)
    no_analog = np.zeros((0, 0), np.float32)
    frames = []
    for frame in stacked_mm:
        pts = np.zeros((len(labels), 5), np.float32)
        pts[:, :3] = frame
        frames.append((pts, no_analog))
    writer.add_frames(frames)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file."
        return atomic_write(path, writer.write)
