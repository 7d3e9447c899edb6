"""C3D motion, the one reader: labelled points -> a :class:`~effortface.train.motion.Motion`.

Read with the ``c3d`` package, imported only by :func:`import_c3d`, when a ``.c3d`` file is read or
written (so :func:`effortface.train.motion.read_motion` and the runtime stay numpy and scipy only
until then). Points are converted from ``POINT:UNITS`` (``mm``, ``cm``, ``m``, ``in``; mm when the
parameter is absent) to metres; the lab frame is taken as Z up (Vicon, Qualisys and Motion
Analysis defaults; pass ``up_axis="y"`` otherwise). A point is **missing** in a frame when its
residual is negative (the C3D convention for an occluded marker), its position is all zeros or not
finite. :func:`read_c3d` reads a file one of two ways:

* **Plug-in Gait**, when the file holds at least half of :data:`PLUG_IN_GAIT`: the markers become
  the joint centres below (a missing Plug-in Gait marker is then named). Frames where a marker is
  missing are filled by linear interpolation over time; a point missing in every frame is an error
  naming it.
* **Labelled points**, otherwise: the points become joints named by their labels (a repeated or
  empty label gets its index), the first point the root (the sync jump is looked for in its
  height) and the others hanging from it: energies use positions only. Body segments are found
  from the labels like any skeleton's joints (joint-centre exports such as ``LeftUpLeg``), or from
  a mapping file. A point missing in a frame is refused naming the point and frame: fill the gaps
  in the capture software first.

**The Plug-in Gait marker set** (:data:`PLUG_IN_GAIT`) gives the joints of the skeleton below,
named as the built-in CMU convention of :mod:`effortface.train.segments` expects, so the 14
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
from effortface.train.motion import Motion, MotionFormatError, motion_from_positions

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
C3D_UNITS_M = {"mm": 0.001, "cm": 0.01, "m": 1.0, "in": 0.0254}
#: the ``c3d`` versions read (as pyproject.toml requires)
C3D_REQUIREMENT = "c3d>=0.5.2,<0.7"


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
    """

    labels: tuple[str, ...]
    positions_m: np.ndarray
    missing: np.ndarray
    rate_hz: float


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


def read_c3d_points(path: str | os.PathLike[str]) -> C3dPoints:
    """Read the labelled points of a C3D file in metres, marking the missing ones.

    Parameters
    ----------
    path : path-like
        The ``.c3d`` file.

    Returns
    -------
    C3dPoints

    Raises
    ------
    MotionFormatError
        The ``c3d`` package missing, a file it cannot read, an unknown unit, no points, fewer than
        2 frames.
    """
    path = Path(path)
    c3d = import_c3d(path)
    try:
        with open(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found in file." is not our concern
            reader = c3d.Reader(fh)
            labels = [str(label).strip() for label in reader.point_labels]
            rate_hz = float(reader.point_rate)
            units = reader.get("POINT:UNITS")
            unit = units.string_value.strip() if units is not None else "mm"
            frames = np.array([points[:, :4] for _, points, _ in reader.read_frames()], dtype=float)
    except FileNotFoundError:
        raise MotionFormatError(f"{path}: expected a C3D file, found no such file") from None
    except (OSError, ValueError, AssertionError, struct.error, IndexError, KeyError, AttributeError) as exc:
        raise MotionFormatError(f"{path}: expected a C3D file, found {type(exc).__name__}: {exc}") from None
    if unit.lower() not in C3D_UNITS_M:
        raise MotionFormatError(f"{path}: POINT:UNITS: expected one of {', '.join(C3D_UNITS_M)}, found {unit!r}")
    if frames.ndim != 3 or len(frames) < 2:
        raise MotionFormatError(f"{path}: expected at least 2 frames of points, found {len(frames)}")
    if frames.shape[1] == 0:
        raise MotionFormatError(f"{path}: expected labelled points, found none")
    xyz = frames[:, :, :3]
    missing = (frames[:, :, 3] < 0) | ~np.isfinite(xyz).all(axis=2) | (xyz == 0).all(axis=2)
    names = _unique((labels + [""] * frames.shape[1])[:frames.shape[1]])
    return C3dPoints(tuple(names), xyz * C3D_UNITS_M[unit.lower()], missing, rate_hz)


def read_c3d_markers(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], float]:
    """Labelled points of a C3D file in metres (gaps filled), and the point rate.

    Returns
    -------
    dict of ndarray (T, 3), float
        ``label -> positions_m`` and frames per second.

    Raises
    ------
    MotionFormatError
        As :func:`read_c3d_points`, and a point missing in every frame.
    """
    points = read_c3d_points(path)
    return _filled_markers(Path(path), points), points.rate_hz


def is_plug_in_gait(labels: tuple[str, ...] | list[str]) -> bool:
    """Whether point labels hold at least half of the Plug-in Gait markers (:data:`PLUG_IN_GAIT`)."""
    return len(set(PLUG_IN_GAIT) & set(labels)) >= len(PLUG_IN_GAIT) // 2


def _filled_markers(path: Path, points: C3dPoints) -> dict[str, np.ndarray]:
    """``label -> (T, 3)`` positions with the missing frames linearly interpolated."""
    t = np.arange(len(points.positions_m))
    markers = {}
    for i, label in enumerate(points.labels):
        valid = ~points.missing[:, i]
        if not valid.any():
            raise MotionFormatError(f"{path}: point {label}: expected positions, found it missing in every frame")
        xyz = points.positions_m[:, i]
        markers[label] = np.column_stack([np.interp(t, t[valid], xyz[valid, k]) for k in range(3)])
    return markers


def _check_visible(path: Path, points: C3dPoints) -> None:
    """MotionFormatError naming the first missing point (by frame) and its frame."""
    if points.missing.any():
        frame, point = (int(i) for i in np.argwhere(points.missing)[0])
        raise MotionFormatError(f"{path}: point {points.labels[point]!r}: expected a position in every frame, "
                                f"found it occluded in {int(points.missing.sum())} point-frames (first at frame "
                                f"{frame}); fill the gaps in the capture software")


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
                                f"(see docs: effortface.train.interop.c3d_motion), found "
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
    _need(Path(source), m, PLUG_IN_GAIT)
    lateral, _, _ = pelvis_frame(m)
    j: dict[str, np.ndarray] = {}
    j["LeftUpLeg"], j["RightUpLeg"] = hip_centres(m)
    shoulders_lat = _unit(m["LSHO"] - m["RSHO"])
    j["Neck1"] = (m["C7"] + m["CLAV"]) / 2
    head = (m["LFHD"] + m["RFHD"] + m["LBHD"] + m["RBHD"]) / 4
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


def read_c3d(path: str | os.PathLike[str], *, options: MarkerSetOptions = MarkerSetOptions(),
             up_axis: str = "z") -> Motion:
    """Read a C3D file as a :class:`Motion` (metres, Z up): Plug-in Gait joint centres or labelled points.

    A file with at least half of :data:`PLUG_IN_GAIT` (:func:`is_plug_in_gait`) gives the joints of
    :data:`SKELETON` by the joint-centre rules, its gaps filled; any other gives its labelled points
    as joints, the first the root, and refuses a missing point (see the module docstring).

    Parameters
    ----------
    path : path-like
        The ``.c3d`` file.
    options : MarkerSetOptions
        Subject widths and offsets of the joint-centre rules (Plug-in Gait files).
    up_axis : {"z", "y"}
        The lab frame's vertical axis (Y-up files are turned to Z up).

    Returns
    -------
    Motion
        Without rotations.

    Raises
    ------
    MotionFormatError
        As :func:`read_c3d_points`; a Plug-in Gait marker absent (named) or missing in every frame;
        a labelled point missing in a frame (named with the frame).
    UserError
        ``up_axis`` not ``"z"`` or ``"y"``.
    """
    path = Path(path)
    if up_axis not in ("z", "y"):
        raise UserError(f"up_axis: expected 'z' or 'y', found {up_axis!r}")
    points = read_c3d_points(path)
    if up_axis == "y":
        points = dataclasses.replace(points, positions_m=points.positions_m[..., [2, 0, 1]])
    if not is_plug_in_gait(points.labels):
        _check_visible(path, points)
        parents = [-1] + [0] * (len(points.labels) - 1)
        return motion_from_positions(points.positions_m, points.labels, parents, points.rate_hz, source=str(path))
    joints = joint_centres(_filled_markers(path, points), options, path)
    names = [name for name, _ in SKELETON]
    parents = [names.index(parent) if parent else -1 for _, parent in SKELETON]
    positions_m = np.stack([joints[n] for n in names], axis=1)
    return motion_from_positions(positions_m, names, parents, points.rate_hz, source=str(path))


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
