"""C3D motion: labelled markers -> joint centres -> a :class:`~effortface.train.motion.Motion`.

Read with the ``c3d`` package, imported only when a ``.c3d`` file is read (the runtime stays numpy
and scipy only). Points are converted from ``POINT:UNITS`` (mm by default) to metres; the lab frame
is taken as Z up (Vicon, Qualisys and Motion Analysis defaults; pass ``up_axis="y"`` otherwise).
Frames where a marker is missing (residual < 0, or all zeros) are filled by linear interpolation
over time; a marker missing in every frame is an error naming it.

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

import numpy as np

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
_UNITS_M = {"mm": 0.001, "cm": 0.01, "m": 1.0, "in": 0.0254}


@dataclasses.dataclass(frozen=True)
class MarkerSetOptions:
    """Subject measurements of the joint-centre rules (metres)."""

    knee_width_m: float = 0.10
    ankle_width_m: float = 0.07
    elbow_width_m: float = 0.07
    marker_radius_m: float = 0.007
    shoulder_offset_m: float = 0.05
    head_top_offset_m: float = 0.08


def read_c3d_markers(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], float]:
    """Labelled points of a C3D file in metres (gaps filled), and the point rate.

    Returns
    -------
    dict of ndarray (T, 3), float
        ``label -> positions_m`` and frames per second.

    Raises
    ------
    MotionFormatError
        Unreadable file, no frames, unknown units, a point missing in every frame.
    """
    import c3d  # lazy: only C3D readers pay for it

    path = Path(path)
    try:
        with open(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found in file."
            reader = c3d.Reader(fh)
            labels = [str(label).strip() for label in reader.point_labels]
            rate_hz = float(reader.point_rate)
            units = reader.get("POINT:UNITS")
            unit = units.string_value.strip() if units is not None else "mm"
            frames = np.array([pts[:, :4] for _, pts, _ in reader.read_frames()], dtype=float)
    except FileNotFoundError:
        raise MotionFormatError(f"{path}: expected a C3D file, found no such file") from None
    except (OSError, ValueError, AssertionError, struct.error, IndexError, KeyError) as exc:
        raise MotionFormatError(f"{path}: expected a C3D file, found {type(exc).__name__}: {exc}") from None
    if unit.lower() not in _UNITS_M:
        raise MotionFormatError(f"{path}: POINT:UNITS: expected one of {', '.join(_UNITS_M)}, found {unit!r}")
    if frames.ndim != 3 or len(frames) < 2:
        raise MotionFormatError(f"{path}: expected at least 2 frames of points, found {len(frames)}")
    scale = _UNITS_M[unit.lower()]
    return {label: _filled(path, label, frames[:, i]) * scale for i, label in enumerate(labels)}, rate_hz


def _filled(path: Path, label: str, xyzr: np.ndarray) -> np.ndarray:
    """A point's (T, 3) positions with missing frames linearly interpolated."""
    valid = (xyzr[:, 3] >= 0) & np.any(xyzr[:, :3] != 0, axis=1) & np.all(np.isfinite(xyzr[:, :3]), axis=1)
    if not valid.any():
        raise MotionFormatError(f"{path}: point {label}: expected positions, found it missing in every frame")
    t = np.arange(len(xyzr))
    return np.column_stack([np.interp(t, t[valid], xyzr[valid, k]) for k in range(3)])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


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
                  source: str | os.PathLike = "markers") -> dict[str, np.ndarray]:
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


def read_c3d(path: str | os.PathLike, *, options: MarkerSetOptions = MarkerSetOptions(),
             up_axis: str = "z") -> Motion:
    """Read a C3D file with the Plug-in Gait marker set as a :class:`Motion` (metres, Z up).

    Parameters
    ----------
    path : path-like
        The ``.c3d`` file.
    options : MarkerSetOptions
        Subject widths and offsets of the joint-centre rules.
    up_axis : {"z", "y"}
        The lab frame's vertical axis (Y-up files are turned to Z up).

    Returns
    -------
    Motion
        The joints of :data:`SKELETON`, without rotations.

    Raises
    ------
    MotionFormatError
        Unreadable file, missing markers (named), bad units.
    """
    path = Path(path)
    markers, rate_hz = read_c3d_markers(path)
    if up_axis == "y":
        markers = {k: v[:, [2, 0, 1]] for k, v in markers.items()}
    elif up_axis != "z":
        raise MotionFormatError(f"{path}: up_axis: expected 'z' or 'y', found {up_axis!r}")
    joints = joint_centres(markers, options, path)
    names = [name for name, _ in SKELETON]
    parents = [names.index(parent) if parent else -1 for _, parent in SKELETON]
    positions_m = np.stack([joints[n] for n in names], axis=1)
    return motion_from_positions(positions_m, names, parents, rate_hz, source=str(path))


def write_c3d_markers(path: str | os.PathLike, markers: dict[str, np.ndarray], rate_hz: float) -> Path:
    """Write labelled points (metres, (T, 3) each) as a C3D file in millimetres (tests, tools).

    Written atomically through :func:`effortface.core.fileio.atomic_write`.
    """
    import c3d

    from effortface.core.fileio import atomic_write

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
