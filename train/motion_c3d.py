"""C3D motion files (points labelled by joint or marker name) through the ``c3d`` package.

Kept out of :mod:`effortface.train.motion` so the runtime (numpy and scipy only) never imports it;
:func:`effortface.train.motion.read_motion` calls :func:`read_c3d` for a ``.c3d`` suffix.

The points become joints named by their labels, in metres with Z up (C3D labs record Z up; the
``POINT:UNITS`` parameter gives the length unit). The first point is the root (the sync jump is
looked for in its height) and the others hang from it: energies use positions only. Body segments are
found from the labels like any skeleton's joints (joint-centre exports such as ``LeftUpLeg``), or from
a mapping file. A point missing in a frame (negative residual, the C3D convention for an occluded
marker) is refused naming the point and frame: fill gaps in the capture software first.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from effortface.train.motion import Motion, MotionFormatError, motion_from_positions

#: POINT:UNITS -> metres per unit
C3D_UNITS_M = {"mm": 0.001, "cm": 0.01, "m": 1.0}


def read_c3d(path: str | Path) -> Motion:
    """Read the labelled points of a C3D file as a :class:`~effortface.train.motion.Motion`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Motion
        Without rotations; joints named by the point labels.

    Raises
    ------
    MotionFormatError
        The ``c3d`` package missing, a file it cannot read, an unknown unit, no points, or an
        occluded point (named with its frame).
    """
    path = Path(path)
    try:
        import c3d
    except ImportError:
        raise MotionFormatError(f"{path}: expected the 'c3d' package to read C3D files, found it not "
                                f"installed (pip install 'c3d>=0.5,<0.7')") from None
    try:
        with open(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found in file." is not our concern
            reader = c3d.Reader(fh)
            labels = [str(label).strip() for label in reader.point_labels]
            unit = reader.get("POINT:UNITS").string_value.strip().lower()
            frames = np.array([points for _, points, _ in reader.read_frames()], dtype=float)
            fps = float(reader.point_rate)
    except (OSError, ValueError, KeyError, AttributeError, AssertionError, IndexError) as exc:
        raise MotionFormatError(f"{path}: expected a readable C3D file, found {type(exc).__name__}: {exc}") from None
    if unit not in C3D_UNITS_M:
        raise MotionFormatError(f"{path}: POINT:UNITS: expected one of {', '.join(C3D_UNITS_M)}, found {unit!r}")
    if frames.ndim != 3 or frames.shape[1] == 0 or not labels:
        raise MotionFormatError(f"{path}: expected labelled points in every frame, found none")
    _check_visible(path, labels, frames)
    names = _unique(labels)
    parents = [-1] + [0] * (len(names) - 1)
    return motion_from_positions(frames[:, :, :3] * C3D_UNITS_M[unit], names, parents, fps, source=str(path))


def _check_visible(path: Path, labels: list[str], frames: np.ndarray) -> None:
    """MotionFormatError naming the first occluded point (residual < 0) and its frame."""
    hidden = frames[:, :, 3] < 0
    if hidden.any():
        frame, point = (int(i) for i in np.argwhere(hidden)[0])
        raise MotionFormatError(f"{path}: point {labels[point]!r}: expected a position in every frame, found "
                                f"it occluded in {int(hidden.sum())} point-frames (first at frame {frame}); "
                                f"fill the gaps in the capture software")


def _unique(labels: list[str]) -> list[str]:
    """Labels made unique (a repeated or empty label gets its index)."""
    seen: set[str] = set()
    out = []
    for i, label in enumerate(labels):
        name = label if label and label not in seen else f"{label or 'point'}_{i}"
        seen.add(name)
        out.append(name)
    return out
