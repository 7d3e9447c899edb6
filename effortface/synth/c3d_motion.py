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
``cm``, ``m``, ``in``; mm when the parameter is absent) to metres; the lab frame is taken as Z up
(Vicon, Qualisys and Motion Analysis defaults; pass ``up_axis="y"`` otherwise). Subject prefixes
(``Matt:LASI``) are dropped; unlabelled trajectories (``*12``) and model outputs stored as points
(``POINT:ANGLES``, ``FORCES``, ``MOMENTS``, ``POWERS``) are left out. A point is **missing** in a
frame when its residual is negative (the C3D convention for an occluded marker), its position is all
zeros or not finite. **Occlusions** of at most :data:`MAX_GAP_S` (0.2 s) are filled by linear
interpolation; the frames before the last marker appears and after the first one disappears are cut;
a longer gap is refused in one line naming the point, its own missing frames and where the gap starts
(:func:`fill_gaps`). What was filled and cut is stated in :attr:`Motion.source`, which ``synth`` keeps
in the output's ``.units.json`` (``"motion"``). :func:`read_c3d` reads a file one of three ways:

* **Plug-in Gait**, when the file holds at least half of :data:`PLUG_IN_GAIT` or all of
  :data:`PIG_LOWER`: the markers become the joint centres below. The head is the centre of its
  four markers, or of three (the mid-point of the complete diagonal: 2.1 cm from the four-marker
  centre on the real Vicon file of the tests). A lower-body set (no trunk or arm marker) is refused
  in one line: the face's effort needs the trunk and arms.
* **The Qualisys sports marker set** (:data:`QUALISYS_SPORTS`): its labels stand for the Plug-in
  Gait markers of the same places (waist markers for the ASIS/PSIS, ``SpineThoracic2`` for C7,
  ``Chest`` for CLAV...), the head is the centroid of its head markers; same rules.
* **Labelled points**, otherwise: the points become joints named by their labels (a repeated or
  empty label gets its index), the first point the root (the sync jump is looked for in its
  height) and the others hanging from it: energies use positions only. Body segments are found
  from the labels like any skeleton's joints (joint-centre exports such as ``LeftUpLeg``), or from
  a mapping file (``--mapping``). Points missing in every frame are left out.

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
import os
import struct
import warnings
from pathlib import Path
from types import ModuleType

import numpy as np

from effortface.core.errors import UserError
from effortface.synth.motion import Motion, MotionFormatError, motion_from_positions

#: Plug-in Gait marker labels used (T10, STRN, SACR, the PSIS are optional helpers)
PLUG_IN_GAIT = ("LFHD", "RFHD", "LBHD", "RBHD", "C7", "CLAV", "LSHO", "RSHO", "LELB", "RELB",
                "LWRA", "LWRB", "RWRA", "RWRB", "LFIN", "RFIN", "LASI", "RASI", "LKNE", "RKNE",
                "LANK", "RANK", "LTOE", "RTOE")
#: Plug-in Gait modelled joint centres -> our joint names (used when present)
JOINT_CENTRES = {"LHJC": "LeftUpLeg", "RHJC": "RightUpLeg", "LKJC": "LeftLeg", "RKJC": "RightLeg",
                 "LAJC": "LeftFoot", "RAJC": "RightFoot", "LSJC": "LeftArm", "RSJC": "RightArm",
                 "LEJC": "LeftForeArm", "REJC": "RightForeArm", "LWJC": "LeftHand", "RWJC": "RightHand"}
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
#: the lower-body Plug-in Gait markers (a file with all of them and few others is a lower-body set)
PIG_LOWER = ("LASI", "RASI", "LKNE", "RKNE", "LANK", "RANK", "LTOE", "RTOE")
#: the ``c3d`` versions read (as pyproject.toml requires)
C3D_REQUIREMENT = "c3d>=0.5.2,<0.7"
#: the longest occlusion filled by linear interpolation, seconds **(choice)**: 0.2 s is a fraction of
#: a stride or a repetition, over which a marker's path is close to straight
MAX_GAP_S = 0.2
#: Plug-in Gait's head markers (a head from three of them: :func:`head_centre`)
HEAD_MARKERS = ("LFHD", "RFHD", "LBHD", "RBHD")
#: optional Plug-in Gait helpers used when present
PIG_HELPERS = ("SACR", "LPSI", "RPSI", "T10", "STRN")
#: markers of the trunk and arms: a set with none of them is lower-body only
UPPER_BODY = ("C7", "CLAV", "LSHO", "RSHO", "LELB", "RELB", "LWRA", "RWRA")
#: the Qualisys sports marker set (QTM's labels) as the Plug-in Gait markers the rules use:
#: ``PiG name -> label|alternative``; its head is the centroid of :data:`QUALISYS_HEAD`
QUALISYS_SPORTS = {
    "LASI": "WaistLFront", "RASI": "WaistRFront", "LPSI": "WaistLBack", "RPSI": "WaistRBack",
    "C7": "SpineThoracic2|BackTop", "CLAV": "Chest|ChestTop", "T10": "SpineThoracic12", "STRN": "Chest|ChestLow",
    **{f"{s}{pig}": "|".join(f"{s}{q}" for q in qs.split("|")) for s in ("L", "R") for pig, qs in {
        "SHO": "ShoulderTop", "ELB": "ElbowOut", "WRA": "WristOut", "WRB": "WristIn",
        "FIN": "HandOut|Hand2|HandIn", "KNE": "KneeOut", "ANK": "AnkleOut", "TOE": "Forefoot2|ToeTip|Forefoot5",
    }.items()}}
QUALISYS_HEAD = ("HeadL", "HeadR", "HeadFront", "HeadTop")
#: POINT parameters that list model outputs stored as points (not markers)
NOT_MARKERS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "REACTIONS")


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
    """

    labels: tuple[str, ...]
    positions_m: np.ndarray
    missing: np.ndarray
    rate_hz: float
    notes: tuple[str, ...] = ()


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
    return _points(path, labels, xyz, residual, rate_hz, strings("UNITS"), other, ("read with ezc3d",))


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
        frames = np.array([points[:, :4] for _, points, _ in reader.read_frames()], dtype=float)
    if frames.ndim != 3:
        frames = np.zeros((len(frames), 0, 4))
    return _points(path, labels, frames[:, :, :3], frames[:, :, 3], rate_hz, unit_list, other, tuple(notes))


def _points(path: Path, labels: list[str], xyz: np.ndarray, residual: np.ndarray, rate_hz: float, units: list[str],
            other: dict[str, list[str]], notes: tuple[str, ...]) -> C3dPoints:
    """C3dPoints in metres from a reader's arrays, model outputs and unlabelled points (``*12``) left out."""
    if len(xyz) < 2:
        raise MotionFormatError(f"{path}: expected at least 2 frames of points, found {len(xyz)}")
    if xyz.shape[1] == 0:
        raise MotionFormatError(f"{path}: expected labelled points, found none")
    scale = units_per_point(path, units, xyz.shape[1])
    names = _unique([k.rsplit(":", 1)[-1] for k in (labels + [""] * xyz.shape[1])[:xyz.shape[1]]])  # "Matt:LASI"
    outputs = {k.rsplit(":", 1)[-1] for k in _modelled_outputs(other)}
    keep = [i for i, name in enumerate(names) if not name.startswith("*") and name not in outputs]
    if not keep:
        raise MotionFormatError(f"{path}: expected labelled markers, found only unlabelled points or model outputs")
    missing = (residual < 0) | ~np.isfinite(xyz).all(axis=2) | (xyz == 0).all(axis=2)
    xyz = np.where(missing[..., None], 0.0, xyz) * scale[None, :, None]
    return C3dPoints(tuple(names[i] for i in keep), xyz[:, keep], missing[:, keep], rate_hz, notes)


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
    """

    labels: tuple[str, ...]
    positions_m: np.ndarray
    first_frame: int
    note: str


def _runs(missing: np.ndarray) -> list[tuple[int, int]]:
    """``(start, length)`` of each run of True in a 1-D bool array."""
    edges = np.diff(np.concatenate([[0], missing.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b - a)) for a, b in zip(starts, ends)]


def fill_gaps(path: Path, points: C3dPoints, labels: list[str], max_gap_s: float | None = None) -> FilledPoints:
    """The points ``labels`` with gaps of at most ``max_gap_s`` (default :data:`MAX_GAP_S`) linearly
    interpolated, over the frames from the last first appearance to the first last disappearance.

    Raises
    ------
    MotionFormatError
        A point missing in every frame, or with a longer gap: one line naming the point, its own
        missing frames and the first frame of that gap.
    """
    max_gap_s = MAX_GAP_S if max_gap_s is None else max_gap_s
    max_frames = max(1, int(round(max_gap_s * points.rate_hz)))
    idx = [points.labels.index(k) for k in labels]
    miss = points.missing[:, idx]
    for j, k in enumerate(labels):
        if miss[:, j].all():
            raise MotionFormatError(f"{path}: point {k!r}: expected positions, found it missing in every frame")
    first = int(max(np.argmax(~miss[:, j]) for j in range(len(idx))))
    last = int(min(len(miss) - 1 - np.argmax(~miss[::-1, j]) for j in range(len(idx))))
    if last - first + 1 < max(2, len(miss) // 2):
        j = int(np.argmax(miss.sum(axis=0)))
        raise MotionFormatError(f"{path}: point {labels[j]!r}: expected it in most frames, found it missing in "
                                f"{int(miss[:, j].sum())} of {len(miss)} frames (first at frame "
                                f"{int(np.argmax(miss[:, j]))}); fill the gaps in the capture software")
    t = np.arange(first, last + 1)
    out = np.empty((len(t), len(idx), 3))
    filled = 0
    for j, (k, i) in enumerate(zip(labels, idx)):
        gap = miss[first:last + 1, j]
        long = [(a, n) for a, n in _runs(gap) if n > max_frames]
        if long:
            a, n = long[0]
            raise MotionFormatError(f"{path}: point {k!r}: expected gaps of at most {max_gap_s:g} s ({max_frames} "
                                    f"frames) to fill, found {int(gap.sum())} missing frames of its own, a gap of {n} "
                                    f"from frame {first + a}; fill the gaps in the capture software")
        xyz = points.positions_m[first:last + 1, i]
        ok = ~gap
        out[:, j] = np.column_stack([np.interp(t, t[ok], xyz[ok, c]) for c in range(3)])
        filled += int(gap.sum())
    cut = len(miss) - len(t)
    note = (f"gaps of at most {max_gap_s:g} s linearly interpolated ({filled} point-frames)"
            + (f"; {cut} frames cut at the ends where a marker had not appeared" if cut else ""))
    return FilledPoints(tuple(labels), out, first, note)


def _unique(labels: list[str]) -> list[str]:
    """Labels made unique (a repeated or empty label gets its index)."""
    seen: set[str] = set()
    out = []
    for i, label in enumerate(labels):
        name = label if label and label not in seen else f"{label or 'point'}_{i}"
        seen.add(name)
        out.append(name)
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    """``v`` divided by its length along the last axis."""
    unit: np.ndarray = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return unit


def _need(path: Path, markers: dict[str, np.ndarray], labels: tuple[str, ...]) -> None:
    missing = [m for m in labels if m not in markers]
    if missing:
        raise MotionFormatError(f"{path}: expected the Plug-in Gait markers {', '.join(missing)} "
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
        j[f"{name}Leg"] = m[f"{side}KNE"] - sign * lateral * (opts.knee_width_m / 2 + opts.marker_radius_m)
        j[f"{name}Foot"] = m[f"{side}ANK"] - sign * lateral * (opts.ankle_width_m / 2 + opts.marker_radius_m)
        j[f"{name}ToeBase"] = m[f"{side}TOE"]
        j[f"{name}Arm"] = m[f"{side}SHO"] - thorax_up * opts.shoulder_offset_m
        j[f"{name}ForeArm"] = m[f"{side}ELB"] - sign * shoulders_lat * (opts.elbow_width_m / 2 + opts.marker_radius_m)
        j[f"{name}Hand"] = (m[f"{side}WRA"] + m[f"{side}WRB"]) / 2
        j[f"{name}HandIndex1"] = m[f"{side}FIN"]
    for label, joint in JOINT_CENTRES.items():  # modelled centres win when the file has them
        if label in m:
            j[joint] = m[label]
    return j


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
    """``"plug-in-gait"``, ``"qualisys-sports"`` or ``"labelled"``: the built-in set the labels hold
    at least half of (:data:`PLUG_IN_GAIT`, :data:`QUALISYS_SPORTS`)."""
    if is_plug_in_gait(labels) or all(k in labels for k in PIG_LOWER):
        return "plug-in-gait"
    found = {k for k, alts in QUALISYS_SPORTS.items() if any(a in labels for a in alts.split("|"))}
    return "qualisys-sports" if len(found) >= len(QUALISYS_SPORTS) // 2 else "labelled"


def _pick_labels(path: Path, points: C3dPoints, kind: str) -> tuple[dict[str, str], list[str]]:
    """``Plug-in Gait name -> label in the file`` for a built-in set, and the head labels present.

    Raises
    ------
    MotionFormatError
        A lower-body set (no trunk or arm marker), or required markers absent (named).
    """
    labels = set(points.labels)
    if kind == "plug-in-gait":
        names = {k: k for k in (*PLUG_IN_GAIT, *PIG_HELPERS, *JOINT_CENTRES) if k in labels}
        head = [k for k in HEAD_MARKERS if k in labels]
    else:
        names = {}
        for k, alts in QUALISYS_SPORTS.items():
            found = next((a for a in alts.split("|") if a in labels), None)
            if found is not None:
                names[k] = found
        head = [k for k in QUALISYS_HEAD if k in labels]
    upper = [k for k in UPPER_BODY if k in names]
    if not upper:
        set_name = "Plug-in Gait" if kind == "plug-in-gait" else "Qualisys sports"
        raise MotionFormatError(f"{path}: expected a full-body {set_name} marker set, found the lower body only "
                                f"(no {', '.join(UPPER_BODY[:4])}...): the face's effort needs the trunk and arms")
    return names, head


def _fillable(path: Path, points: C3dPoints, label: str) -> bool:
    """Whether :func:`fill_gaps` accepts the point ``label`` on its own."""
    try:
        fill_gaps(path, points, [label])
    except MotionFormatError:
        return False
    return True


def _built_in(path: Path, points: C3dPoints, kind: str, options: MarkerSetOptions) -> Motion:
    """The joints of :data:`SKELETON` from a built-in marker set (gaps filled; see the module docstring)."""
    names, head = _pick_labels(path, points, kind)
    optional = {*PIG_HELPERS, *JOINT_CENTRES}
    body = list(dict.fromkeys(names[k] for k in names if k not in HEAD_MARKERS and k not in optional))
    fill_gaps(path, points, body)  # a body marker missing or with a long gap: named
    dropped: list[str] = []
    usable_head: list[str] = []
    for k in head:  # a head marker absent or with a long gap is left out while 3 remain
        (usable_head if _fillable(path, points, k) else dropped).append(k)
    helpers = [names[k] for k in names if k in optional and names[k] not in body]
    body += [k for k in dict.fromkeys(helpers) if _fillable(path, points, k)]
    required_head = 3
    if len(usable_head) < required_head:
        label = "LFHD, RFHD, LBHD, RBHD" if kind == "plug-in-gait" else ", ".join(QUALISYS_HEAD)
        raise MotionFormatError(f"{path}: expected at least {required_head} of the head markers {label} in most "
                                f"frames, found {', '.join(usable_head) or 'none'}")
    filled = fill_gaps(path, points, [*body, *usable_head])
    by_label = {k: filled.positions_m[:, i] for i, k in enumerate(filled.labels)}
    m = {pig: by_label[label] for pig, label in names.items() if label in by_label}
    hc = head_centre({k: by_label[k] for k in usable_head}, HEAD_MARKERS if kind == "plug-in-gait" else QUALISYS_HEAD)
    assert hc is not None
    m["HEAD"] = hc
    joints = joint_centres(m, options, path)
    order = [name for name, _ in SKELETON]
    parents = [order.index(parent) if parent else -1 for _, parent in SKELETON]
    positions_m = np.stack([joints[n] for n in order], axis=1)
    set_name = "Plug-in Gait" if kind == "plug-in-gait" else "Qualisys sports"
    head_note = f"; head from {', '.join(usable_head)}" + (f" ({', '.join(dropped)} left out)" if dropped else "") \
        if dropped or len(usable_head) < 4 else ""
    source = f"{path} ({set_name} markers, {'; '.join(points.notes)}; {filled.note}{head_note})"
    return motion_from_positions(positions_m, order, parents, points.rate_hz, source=source)


def read_c3d(path: str | os.PathLike[str], *, options: MarkerSetOptions = MarkerSetOptions(),
             up_axis: str = "z") -> Motion:
    """Read a C3D file as a :class:`Motion` (metres, Z up): built-in marker-set joint centres or labelled points.

    A file holding at least half of :data:`PLUG_IN_GAIT` or of :data:`QUALISYS_SPORTS`
    (:func:`marker_set`) gives the joints of :data:`SKELETON` by the joint-centre rules; any other
    gives its labelled markers as joints, the first the root. Either way gaps of at most
    :data:`MAX_GAP_S` are linearly interpolated and stated in :attr:`Motion.source` (see
    :func:`fill_gaps`).

    Parameters
    ----------
    path : path-like
        The ``.c3d`` file.
    options : MarkerSetOptions
        Subject widths and offsets of the joint-centre rules (built-in marker sets).
    up_axis : {"z", "y"}
        The lab frame's vertical axis (Y-up files are turned to Z up).

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
        ``up_axis`` not ``"z"`` or ``"y"``.
    """
    path = Path(path)
    if up_axis not in ("z", "y"):
        raise UserError(f"up_axis: expected 'z' or 'y', found {up_axis!r}")
    points = read_c3d_points(path)
    if up_axis == "y":
        points = dataclasses.replace(points, positions_m=points.positions_m[..., [2, 0, 1]])
    kind = marker_set(points.labels)
    if kind != "labelled":
        return _built_in(path, points, kind, options)
    present = [k for i, k in enumerate(points.labels) if not points.missing[:, i].all()]
    filled = fill_gaps(path, points, present)
    parents = [-1] + [0] * (len(filled.labels) - 1)
    absent = len(points.labels) - len(present)
    note = filled.note + (f"; {absent} points missing in every frame left out" if absent else "")
    return motion_from_positions(filled.positions_m, filled.labels, parents, points.rate_hz,
                                 source=f"{path} (labelled markers, {'; '.join(points.notes)}; {note})")


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
