"""Motion input: BVH, retargeted ``.npz`` clips and plain joint positions, as one :class:`Motion`.

Every reader returns world joint positions in **metres with Z up** (and, when the source has them,
the world rotation of every joint's frame), so segments and energies never see file conventions.

This module imports numpy only (besides the standard library and the project's own error types):
``effortface/synth/runtime.py`` loads motion through it, and the runtime may use numpy and scipy only. That is
why the BVH reader is hand-written instead of using a third-party BVH package.
"""

from __future__ import annotations

import dataclasses
import inspect
import itertools
import math
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn, TextIO

import numpy as np

from effortface.core import bounds
from effortface.core.bounds import BOUNDS
from effortface.core.bounds import is_number
from effortface.core.errors import UserError
from effortface.core.fileio import check_regular_file
from effortface.synth.npzio import load_npz

#: CMU cgspeed ("MotionBuilder-friendly") BVH length unit: 1 unit = 1/0.45 inch = 0.05644 m.
CMU_UNIT_M = 0.05644

#: Candidate BVH length units, tried in this order by :func:`detect_bvh_unit_m`.
BVH_UNITS_M: tuple[tuple[str, float], ...] = (
    ("metre", 1.0),
    ("CMU cgspeed unit", CMU_UNIT_M),
    ("inch", 0.0254),
    ("centimetre", 0.01),
    ("millimetre", 0.001),
)

#: Rest-pose height range (m) that a unit must produce to be chosen. The ranges in units do not
#: overlap for the candidates above (CMU 19.5-40.8, inch 43.3-90.6, cm 110-230 ...).
STATURE_RANGE_M = (1.1, 2.3)

#: End sites added to the AMP humanoid bodies (offset in the body's frame, metres), taken from the
#: geoms of ``amp_humanoid.xml``: head sphere top (0.175 + 0.095), hand = de Leva wrist-to-MET3
#: length, foot box heel and toe at the box's mid-height.
AMP_END_SITES_M: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "head": (("head_end", (0.0, 0.0, 0.27)),),
    "left_hand": (("left_hand_end", (0.0, 0.0, -0.086)),),
    "right_hand": (("right_hand_end", (0.0, 0.0, -0.086)),),
    "left_foot": (("left_foot_heel", (-0.0435, 0.0, -0.0225)), ("left_foot_toe", (0.1335, 0.0, -0.0225))),
    "right_foot": (
        ("right_foot_heel", (-0.0435, 0.0, -0.0225)),
        ("right_foot_toe", (0.1335, 0.0, -0.0225)),
    ),
}

#: Frames a BVH reader parses and poses at a time (about 50 MB of work arrays for 38 joints).
BVH_CHUNK_FRAMES = 8192
#: Clips with more frames (10 min at 120 Hz) are held in float32 by :func:`read_bvh` (choice:
#: float32 keeps 0.1 mm on a 10 m stage, far below mocap noise).
FLOAT32_ABOVE_FRAMES = 72_000

#: a file's up axis (one of x, y, z, -x, -y, -z) -> the rotation turning its coordinates to Z up:
#: ``p_z_up = UP_TO_Z_UP[up] @ p_file``. Each is a proper rotation (determinant 1, handedness kept)
#: and a signed permutation of the axes; Y up is x' = z, y' = x, z' = y (the cyclic turn).
UP_TO_Z_UP: dict[str, np.ndarray] = {
    "z": np.eye(3),
    "y": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    "x": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
    "-z": np.diag([1.0, -1.0, -1.0]),
    "-y": np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
    "-x": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]]),
}
#: words in joint names that mark the head and the feet, for the direction of gravity over a clip
HEAD_WORDS = ("head",)
FOOT_WORDS = ("foot", "toe", "ankle", "heel")


#: what :attr:`Motion.reading` may hold (every key optional):
#: ``unit_m`` (float, metres per file unit), ``unit_from`` (str, how it was decided: the file's
#: declaration, the rest pose's height, an option), ``up_axis`` (the file's up: one of x, y, z, -x,
#: -y, -z), ``up_from`` (str, how it was decided), ``producer`` (str, e.g. a C3D's MANUFACTURER),
#: ``marker_set`` / ``convention`` (str, what named the joints), ``window`` (dict: ``first_frame``,
#: ``n_frames``, ``of_frames``, why a sub-window of the file was kept).
READING_KEYS = ("unit_m", "unit_from", "up_axis", "up_from", "producer", "marker_set", "convention", "window")


class MotionFormatError(UserError):
    """A motion file does not follow its format; the message names the file (and line)."""


def _named(joint_names: Sequence[str], words: Sequence[str]) -> list[int]:
    """The joints whose name holds one of ``words`` (case-insensitive)."""
    return [j for j, n in enumerate(joint_names) if any(w in n.lower() for w in words)]


def _axis_name(vector: np.ndarray) -> str:
    """The signed axis (x, -y, ...) along which ``vector`` (3,) is longest."""
    a = int(np.argmax(np.abs(vector)))
    return ("-" if vector[a] < 0 else "") + "xyz"[a]


#: the format's up axis is kept when the head is above the feet along it in this share of the frames ...
CONVENTION_KEPT_SHARE = 0.7
#: ... and the median rise along it is at least this fraction of the median head-feet distance (the
#: head 9 degrees above the feet: a push-up's 15-25 degrees keeps it, a body standing along another
#: axis does not)
CONVENTION_KEPT_RISE = 0.15


def _along(vectors: np.ndarray, axis: str) -> np.ndarray:
    """The components of ``vectors`` (..., 3) along a signed axis (``'-y'``)."""
    return (-1.0 if axis.startswith("-") else 1.0) * vectors[..., "xyz".index(axis[-1])]


def detect_up_axis(positions: np.ndarray, joint_names: Sequence[str], default: str,
                   rest_positions: np.ndarray | None = None) -> tuple[str, str]:
    """A clip's up axis in its file's coordinates, from gravity over the clip, and how it was decided.

    Gravity: the head stays above the feet. With joints named like a head (:data:`HEAD_WORDS`) and
    like feet (:data:`FOOT_WORDS`), the format's convention ``default`` is kept when the head is
    above the feet along it in most frames (:data:`CONVENTION_KEPT_SHARE`, by at least
    :data:`CONVENTION_KEPT_RISE` of their distance: a push-up or a sit-up keeps it); otherwise the up
    axis is the signed axis of the median head-minus-feet vector over the frames. Without them, ``default`` (the format's convention: a clip's extent does
    not tell up from sideways, a T-pose is as wide as it is tall). The rest
    pose (when given) is only reported: a rest pose need not be upright (a body lying along x, a
    T-pose whose arm span equals its height).

    Parameters
    ----------
    positions : ndarray, shape (T, J, 3)
        World joint positions in the file's axes (any unit), e.g. a clip's reference frames.
    joint_names : sequence of str
        J joint names.
    default : str
        The format's convention (``"y"`` for BVH, ``"z"`` for a positions CSV).
    rest_positions : ndarray, shape (J, 3), optional
        The rest pose, to say whether it agrees.

    Returns
    -------
    up : str
        One of x, y, z, -x, -y, -z.
    how : str
        E.g. ``'gravity over the clip: the head above the feet along y in 100% of frames; the rest
        pose agrees'``.
    """
    pos = np.asarray(positions, dtype=float)
    head, feet = _named(joint_names, HEAD_WORDS), _named(joint_names, FOOT_WORDS)
    if head and feet and pos.size:
        with np.errstate(all="ignore"):  # absurd values: refused by check_positions after this
            rise = pos[:, head].mean(axis=1) - pos[:, feet].mean(axis=1)
        rise = np.nan_to_num(rise, nan=0.0, posinf=0.0, neginf=0.0)
        median = np.median(rise, axis=0)
        along_default = _along(rise, default)
        if np.mean(along_default > 0) >= CONVENTION_KEPT_SHARE and \
                np.median(along_default) >= CONVENTION_KEPT_RISE * float(np.linalg.norm(median)):
            up, note = default, "the format's convention"  # a push-up lies mostly along x, its head still up y
        else:
            up, note = _axis_name(median), f"not the format's {default}"
        share = float(np.mean(_along(rise, up) > 0))
        how = f"gravity over the clip: the head above the feet along {up} in {share:.0%} of frames ({note})"
    else:
        up = default
        how = f"the format's convention ({default} up): no head and feet named to check it against"
    if rest_positions is not None and len(rest_positions):
        rest = np.asarray(rest_positions, dtype=float)
        rest_up = _axis_name(rest[head].mean(axis=0) - rest[feet].mean(axis=0)) if head and feet else \
            "xyz"[int(np.argmax(np.ptp(rest, axis=0)))]
        how += "; the rest pose agrees" if rest_up.lstrip("-") == up.lstrip("-") else \
            f"; the rest pose lies along {rest_up.lstrip('-')} (not upright: not used)"
    return up, how


def check_parents(parents: np.ndarray, source: str | Path) -> np.ndarray:
    """Check that ``parents`` is a skeleton tree listed parents first; return it as int array.

    Parameters
    ----------
    parents : ndarray, shape (J,)
        Parent index of every joint, -1 for a root.
    source : str or Path
        File (or description) named in the error message.

    Returns
    -------
    ndarray of int, shape (J,)

    Raises
    ------
    MotionFormatError
        A parent index that is not -1 or the index of an earlier joint (out of range, the joint
        itself or a later joint, so cycles are impossible), or a non-integer parent index.
    """
    par = np.asarray(parents)
    if par.ndim != 1 or (par.size and par.dtype.kind not in "iu"):
        raise MotionFormatError(
            f"{source}: parent_indices: expected a 1-D array of integers, found {par.dtype} shape {par.shape}")
    par = par.astype(int)
    bad = np.flatnonzero((par < -1) | (par >= np.arange(par.size)))
    if bad.size:
        j = int(bad[0])
        raise MotionFormatError(
            f"{source}: parent_indices: expected -1 or the index of an earlier joint (a tree, parents "
            f"first), found joint {j} with parent {int(par[j])}")
    return par


def check_finite(source: str | Path, name: str, values: np.ndarray, frame_axis: bool = True) -> None:
    """Raise naming ``source``, ``name`` and the first bad frame if ``values`` has NaN or inf.

    Parameters
    ----------
    source : str or Path
        File (or description) named in the error message.
    name : str
        Field named in the message.
    values : ndarray
        Per-frame values (frames along axis 0) or, with ``frame_axis=False``, static values.
    frame_axis : bool
        Whether axis 0 counts frames (then the first bad frame, 0-based, is named).
    """
    ok = np.isfinite(values)
    if ok.all():
        return
    if frame_axis and values.ndim >= 1:
        frame = int(np.flatnonzero(~ok.reshape(ok.shape[0], -1).all(axis=1))[0])
        found = values[frame][~ok[frame]].flat[0]
        raise MotionFormatError(f"{source}: {name}: expected finite numbers, found {found} at frame {frame}")
    raise MotionFormatError(f"{source}: {name}: expected finite numbers, found {values[~ok].flat[0]}")


#: frames checked at a time by :func:`check_positions` (its working memory does not grow with the clip)
_CHECK_CHUNK_FRAMES = 4096


def check_positions(source: str | Path, positions_m: np.ndarray, joint_names: Sequence[str],
                    first_frame: int = 0) -> None:
    """Raise naming ``source``, the frame and the joint if a world position is not finite or absurd.

    The one check every motion reader ends with (issue 29): a frame of huge finite values (1e308 in a
    BVH, 1e200 in a CSV) would make NaN energies and weights downstream. The bound is
    ``BOUNDS["position_m"]`` (:mod:`effortface.core.bounds`). ``first_frame``: the clip's frame
    number of ``positions_m[0]`` (a block of a streamed clip).

    Raises
    ------
    MotionFormatError
        ``'<source>: positions_m: expected <bound>, found 1e+200 at frame 12, joint 'LeftHand''``.
    """
    bound = BOUNDS["position_m"]
    for start in range(0, len(positions_m), _CHECK_CHUNK_FRAMES):
        chunk = positions_m[start:start + _CHECK_CHUNK_FRAMES]
        with np.errstate(invalid="ignore"):
            bad = ~((chunk >= bound.low) & (chunk <= bound.high))
        if bad.any():
            frame, joint, axis = (int(i[0]) for i in np.nonzero(bad))
            name = joint_names[joint] if joint < len(joint_names) else str(joint)
            raise MotionFormatError(f"{source}: positions_m: expected {bound.describe()}, found "
                                    f"{float(chunk[frame, joint, axis]):g} at frame {first_frame + start + frame}, "
                                    f"joint {name!r}")


@dataclasses.dataclass(frozen=True)
class Motion:
    """A skeleton's motion in world coordinates (metres, Z up).

    Parameters
    ----------
    joint_names : tuple of str
        One name per joint (BVH end sites are named ``<parent>_end``).
    parents : ndarray, shape (J,)
        Index of each joint's parent, -1 for the root. Parents come before children.
    positions_m : ndarray, shape (T, J, 3)
        World joint positions in metres, Z up.
    rotations : ndarray, shape (T, J, 3, 3), or None
        World rotation of each joint's frame (columns are the frame's axes), when the source has them.
    fps : float
        Frames per second.
    source : str
        Where the motion came from (a file path or a description).
    reading : dict
        How the file was read, for ``effortface motion inspect``, ``.units.json`` and BIDS (keys
        :data:`READING_KEYS`; a reader fills what it knows): the length unit and how it was decided,
        the file's up axis and how, the producer, the frame window kept.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    positions_m: np.ndarray
    rotations: np.ndarray | None
    fps: float
    source: str = ""
    reading: dict[str, Any] = dataclasses.field(default_factory=dict, compare=False)

    @property
    def t_s(self) -> np.ndarray:
        """Time of every frame in seconds from the first frame, shape (T,)."""
        return np.arange(self.n_frames) / self.fps

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions_m.shape[0])

    def decimate(self, factor: int) -> Motion:
        """Keep every ``factor``-th frame (frames 0, factor, 2 factor, ...); fps is divided by it.

        Parameters
        ----------
        factor : int
            Positive integer decimation factor.

        Returns
        -------
        Motion
            The decimated motion (no anti-alias filter: energies low-pass the joints anyway).
        """
        if int(factor) != factor or factor < 1:
            raise UserError(f"decimation factor: expected a positive integer, got {factor!r}")
        rot = None if self.rotations is None else self.rotations[::factor]
        return dataclasses.replace(
            self, positions_m=self.positions_m[::factor], rotations=rot, fps=self.fps / factor
        )

    def slice_s(self, start_s: float, stop_s: float) -> Motion:
        """The frames with ``start_s <= t_s < stop_s`` (times from this motion's first frame)."""
        keep = slice(int(math.ceil(start_s * self.fps - 1e-9)), int(math.ceil(stop_s * self.fps - 1e-9)))
        rot = None if self.rotations is None else self.rotations[keep]
        return dataclasses.replace(self, positions_m=self.positions_m[keep], rotations=rot)


# --------------------------------------------------------------------------------------------
# plain positions and dispatch


def motion_from_positions(
    positions_m: np.ndarray,
    joint_names: Sequence[str],
    parents: Sequence[int] | np.ndarray,
    fps: float,
    *,
    source: str = "positions",
) -> Motion:
    """Wrap plain joint positions (metres, Z up) as a :class:`Motion` without rotations.

    Parameters
    ----------
    positions_m : array_like, shape (T, J, 3)
        World joint positions in metres with Z up.
    joint_names : sequence of str
        J joint names.
    parents : sequence of int
        J parent indices, -1 for the root.
    fps : float
        Frames per second (> 0).
    source : str
        Description kept in :attr:`Motion.source`.

    Returns
    -------
    Motion

    Raises
    ------
    UserError
        If the shapes disagree or fps is not positive.
    """
    pos = np.asarray(positions_m, dtype=float)
    names = tuple(str(n) for n in joint_names)
    par = np.asarray(parents, dtype=int)
    if pos.ndim != 3 or pos.shape[0] < 1 or pos.shape[2] != 3 or pos.shape[1] != len(names) \
            or par.shape != (len(names),):
        raise UserError(
            f"positions_m: expected shape (T >= 1, {len(names)}, 3) with {len(names)} parents, "
            f"got {pos.shape} and {par.shape[0]} parents"
        )
    if not (isinstance(fps, (int, float, np.number)) and math.isfinite(fps) and fps > 0):
        raise UserError(f"fps: expected a positive number, got {fps!r}")
    par = check_parents(par, source)
    check_finite(source, "positions_m", pos)
    check_positions(source, pos, names)
    return Motion(names, par, pos, None, float(fps), source)


#: motion file suffixes :func:`read_motion` reads out of the box (:func:`motion_suffixes` adds registered ones)
MOTION_SUFFIXES = (".bvh", ".npz", ".c3d", ".csv")
#: a motion reader: (path, unit_m) -> Motion or (path, unit_m, up) -> Motion; ``unit_m`` is the
#: caller's length unit and ``up`` the file's up axis (None: the file's own)
MotionReader = Callable[..., Motion]
_READERS: dict[str, MotionReader] = {}


def register_motion_reader(suffix: str, reader: MotionReader) -> None:
    """Make :func:`read_motion` (and so ``effortface synth``, the runtime, the Synthesize stage) read a format.

    Parameters
    ----------
    suffix : str
        The file suffix, with its dot (``".trc"``); compared without case. A suffix registered
        again gets the new reader.
    reader : callable
        ``reader(path, unit_m) -> Motion``, or ``reader(path, unit_m, up) -> Motion`` to take the
        caller's up axis (one of x, y, z, -x, -y, -z, or None): raise :class:`MotionFormatError` naming the file, what
        was expected and what was found for a file it cannot read (:func:`motion_from_positions`
        builds a checked Motion from joint positions).

    Raises
    ------
    ValueError
        If ``suffix`` is not a dot and at least one character.
    """
    if not (isinstance(suffix, str) and suffix.startswith(".") and len(suffix) > 1 and suffix.strip() == suffix):
        raise ValueError(f"suffix: expected a file suffix such as '.trc', found {suffix!r}")
    _READERS[suffix.lower()] = reader


def motion_suffixes() -> tuple[str, ...]:
    """The suffixes :func:`read_motion` reads now: :data:`MOTION_SUFFIXES` and the registered ones."""
    return tuple(_READERS)


def read_motion(path: str | Path, *, unit_m: float | None = None, up: str | None = None) -> Motion:
    """Read a motion file, choosing the reader by suffix (:func:`motion_suffixes`, :func:`register_motion_reader`).

    ``.bvh`` (:func:`read_bvh`), ``.npz`` (:func:`read_npz_motion`), ``.csv`` joint positions in
    either dialect (``<joint>_x_m`` or ``<joint>_x`` columns:
    :func:`effortface.synth.motion_csv.read_positions_csv`) and ``.c3d`` (Plug-in Gait markers to
    joint centres, or other labelled points as joints:
    :func:`effortface.synth.c3d_motion.read_c3d`). Both modules are imported only when such
    a file is read, and the C3D reader imports the ``c3d`` package only then, so the runtime stays
    numpy and scipy only.

    Parameters
    ----------
    path : str or Path
        The motion file.
    unit_m : float, optional
        Metres per file length unit; None: from the file (C3D ``POINT:UNITS``, ``.npz`` metres, CSV
        ``<joint>_x_m`` columns) or the skeleton's size (BVH, CSV ``<joint>_x`` columns). Given, it
        replaces the file's declaration.
    up : str, optional
        The file's up axis, one of x, y, z, -x, -y, -z; None: from the file (C3D ``X_SCREEN`` /
        ``Y_SCREEN``) or gravity over the clip (BVH, CSV: :func:`detect_up_axis`).

    Returns
    -------
    Motion
        Metres, Z up; :attr:`Motion.reading` says how the unit and the up axis were decided.

    Raises
    ------
    MotionFormatError
        Unknown suffix, missing file or malformed content.
    UserError
        A bad ``unit_m`` or ``up``, or an ``up`` given to a registered reader that takes none.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    reader = _READERS.get(suffix)
    if reader is None:
        raise MotionFormatError(f"{path}: expected a motion file ending in {', '.join(motion_suffixes())}, "
                                f"got suffix {suffix!r}")
    if path.exists():  # a FIFO or device would block or read forever
        check_regular_file(path, f"a motion file ({suffix})", MotionFormatError)
    up = _check_up_axis(up)
    if _takes_up(reader):
        return reader(path, unit_m, up)
    if up is not None:
        raise UserError(f"{path}: --up: the reader registered for {suffix} takes no up axis (it reads the "
                        f"file's own), found --up {up}")
    return reader(path, unit_m)


def _takes_up(reader: MotionReader) -> bool:
    """Whether a registered reader takes the caller's up axis (a third argument or ``up``)."""
    try:
        params = list(inspect.signature(reader).parameters.values())
    except (TypeError, ValueError):
        return False
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 3 or any(p.kind is p.VAR_POSITIONAL for p in params)


def _read_bvh(path: Path, unit_m: float | None, up: str | None = None) -> Motion:
    return read_bvh(path, unit_m=unit_m, up_axis=up)


def _read_npz(path: Path, unit_m: float | None, up: str | None = None) -> Motion:
    motion = read_npz_motion(path)
    if up not in (None, "z"):
        raise UserError(f"{path}: --up: a retargeted .npz clip is Z up by its format, found --up {up}")
    return _given_unit(motion, unit_m)


def _given_unit(motion: Motion, unit_m: float | None) -> Motion:
    """A clip read in the unit its file declares (:attr:`Motion.reading` ``unit_m``) rescaled to the
    caller's ``unit_m`` (``--unit-m`` overrides the declaration); refused if the reader said none."""
    if unit_m is None:
        return motion
    declared = motion.reading.get("unit_m")
    if not declared:
        raise UserError(f"{motion.source}: --unit-m: expected a reader that says the unit it read, found "
                        f"none to replace; leave --unit-m out (the file's own unit is used)")
    pos = np.asarray(motion.positions_m) * (_checked_unit_m(unit_m) / float(declared))
    check_positions(motion.source, pos, motion.joint_names)
    reading = {**motion.reading, "unit_m": float(unit_m),
               "unit_from": f"given (--unit-m; the file says {float(declared):g} m)"}
    return dataclasses.replace(motion, positions_m=pos, reading=reading)


def _read_csv(path: Path, unit_m: float | None, up: str | None = None) -> Motion:
    return _csv_unit_and_up(read_positions_csv(path), unit_m, up)


def _read_c3d(path: Path, unit_m: float | None, up: str | None = None) -> Motion:
    from effortface.synth.c3d_motion import read_c3d  # imports the c3d package when called

    return read_c3d(path, up=up, unit_m=unit_m)  # the file's POINT:UNITS and axes unless given


def _csv_unit_and_up(motion: Motion, unit_m: float | None, up: str | None) -> Motion:
    """A positions CSV turned to its up axis (given, or :func:`detect_up_axis` with the format's Z
    up as the default) and scaled by its unit (given; ``<joint>_x`` columns: detected from the body's
    size when it is not a human size in metres)."""
    reading = dict(motion.reading)
    pos = np.array(motion.positions_m, dtype=float)
    sample = pos[::max(1, motion.n_frames // UP_FRAMES)]
    if up is None:
        up, reading["up_from"] = detect_up_axis(sample, motion.joint_names, "z")
    else:
        reading["up_from"] = "given (--up)"
    reading["up_axis"] = up
    to_z_up(pos, None, up)
    if unit_m is not None:
        reading["unit_m"], reading["unit_from"] = _checked_unit_m(unit_m), "given (--unit-m)"
    elif not str(reading.get("unit_from", "")).startswith("the column names"):
        size = float(np.median(np.ptp(pos[::max(1, motion.n_frames // UP_FRAMES), :, 2], axis=1)))
        lo, hi = STATURE_RANGE_M
        if not lo <= size <= hi:
            try:
                name, reading["unit_m"] = detect_bvh_unit_m(size)
                reading["unit_from"] = f"body {size:.4g} units tall (median over the clip) -> {name}"
            except UserError:
                pass  # left in metres: the plausibility gate names the height
    pos *= reading["unit_m"]
    check_positions(motion.source, pos, motion.joint_names)
    return dataclasses.replace(motion, positions_m=pos, reading=reading)


for _suffix, _reader in zip(MOTION_SUFFIXES, (_read_bvh, _read_npz, _read_c3d, _read_csv)):
    register_motion_reader(_suffix, _reader)


def read_positions_csv(path: str | Path) -> Motion:
    """Thin alias of :func:`effortface.synth.motion_csv.read_positions_csv` (the one joint-positions
    CSV reader, both dialects), kept for code that imports it from here."""
    from effortface.synth.motion_csv import read_positions_csv as read  # imports this module

    return read(path)


# --------------------------------------------------------------------------------------------
# rotations


def axis_rotations(axis: str, angle_rad: np.ndarray) -> np.ndarray:
    """Rotation matrices about ``axis`` ('X', 'Y' or 'Z') for an array of angles, shape (..., 3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    one, zero = np.ones_like(c), np.zeros_like(c)
    rows = {
        "X": ((one, zero, zero), (zero, c, -s), (zero, s, c)),
        "Y": ((c, zero, s), (zero, one, zero), (-s, zero, c)),
        "Z": ((c, -s, zero), (s, c, zero), (zero, zero, one)),
    }[axis]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def quaternions_xyzw_to_matrices(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w), shape (..., 4), to rotation matrices, shape (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    rows = (
        (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def forward_kinematics(
    parents: np.ndarray,
    offsets: np.ndarray,
    local_rotations: np.ndarray,
    root_positions: np.ndarray,
    local_translations: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """World positions and rotations from local ones, vectorised over frames.

    Parameters
    ----------
    parents : ndarray, shape (J,)
        Parent indices, parents before children, -1 for the root(s).
    offsets : ndarray, shape (J, 3)
        Each joint's offset in its parent's frame.
    local_rotations : ndarray, shape (T, J, 3, 3)
        Each joint's rotation relative to its parent's frame.
    root_positions : ndarray, shape (T, 3)
        World position of the root(s).
    local_translations : ndarray, shape (T, J, 3), optional
        Per-frame translations added to the offsets (BVH position channels of non-root joints).

    Returns
    -------
    positions : ndarray, shape (T, J, 3)
    rotations : ndarray, shape (T, J, 3, 3)
    """
    local = np.ascontiguousarray(np.moveaxis(np.asarray(local_rotations, dtype=float), 0, -1))
    trans = None if local_translations is None else \
        np.ascontiguousarray(np.moveaxis(np.asarray(local_translations, dtype=float), 0, -1))
    offsets = np.asarray(offsets, dtype=float)
    pos, rot = _pose_components(parents, offsets, list(local),
                                np.ascontiguousarray(np.asarray(root_positions, dtype=float).T),
                                [None] * len(parents) if trans is None else
                                [offsets[j][:, None] + t for j, t in enumerate(trans)])
    return np.ascontiguousarray(np.moveaxis(pos, -1, 0)), np.ascontiguousarray(np.moveaxis(rot, -1, 0))


def _pose_components(parents: np.ndarray, offsets: np.ndarray, local: Sequence[np.ndarray | None],
                     root: np.ndarray, trans: Sequence[np.ndarray | None]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`forward_kinematics` with frames last: local rotations (3, 3, T) per joint (None: the
    identity), root positions (3, T), per-frame local translations (3, T) per joint that REPLACE its
    offset (BVH position channels; None: the offset) -> positions (J, 3, T) and rotations (J, 3, 3, T).

    Frames last, every product is a few whole-array operations per joint (a batched 3 x 3 ``@``
    over frames runs one tiny product per frame, about 8x slower).
    """
    n_frames = root.shape[-1]
    pos = np.empty((len(parents), 3, n_frames))
    rot = np.empty((len(parents), 3, 3, n_frames))
    for j, p in enumerate(parents):
        if p < 0:
            pos[j] = root
            rot[j] = np.eye(3)[:, :, None] if local[j] is None else local[j]
            continue
        t_j = trans[j]
        arm = np.einsum("ikt,k->it", rot[p], offsets[j]) if t_j is None else \
            np.einsum("ikt,kt->it", rot[p], t_j)
        np.add(pos[p], arm, out=pos[j])
        local_j = local[j]
        if local_j is None:
            rot[j] = rot[p]
        else:
            np.einsum("ikt,kjt->ijt", rot[p], local_j, out=rot[j])
    return pos, rot


# --------------------------------------------------------------------------------------------
# BVH


@dataclasses.dataclass
class _BvhJoint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]
    first_channel: int


class _Tokens:
    """Whitespace tokens of a text file with their 1-based line numbers."""

    def __init__(self, path: Path, lines: list[str]) -> None:
        self.path = path
        self.items = [(tok, n) for n, line in enumerate(lines, 1) for tok in line.split()]
        self.i = 0

    def line(self) -> int:
        """Line of the next token (or the last line at the end)."""
        return self.items[min(self.i, len(self.items) - 1)][1] if self.items else 1

    def error(self, expected: str, found: str | None = None) -> MotionFormatError:
        """A MotionFormatError naming the file, the line, what was expected and what was found."""
        if found is None:
            found = repr(self.items[self.i][0]) if self.i < len(self.items) else "end of file"
        return MotionFormatError(f"{self.path}: line {self.line()}: expected {expected}, found {found}")

    def next(self, expected: str) -> str:
        """The next token; raise naming ``expected`` at the end of the file."""
        if self.i >= len(self.items):
            raise self.error(expected)
        tok = self.items[self.i][0]
        self.i += 1
        return tok

    def expect(self, word: str) -> None:
        """Consume ``word`` (case-insensitive) or raise."""
        if self.i >= len(self.items) or self.items[self.i][0].upper() != word.upper():
            raise self.error(repr(word))
        self.i += 1

    def number(self, expected: str) -> float:
        """The next token as a float or raise."""
        if self.i < len(self.items):
            try:
                value = float(self.items[self.i][0])
            except ValueError:
                raise self.error(expected) from None
            if not math.isfinite(value):
                raise self.error(f"{expected} (finite)")
            self.i += 1
            return value
        raise self.error(expected)


_CHANNELS = {f"{a}{kind}" for a in "XYZ" for kind in ("position", "rotation")}


#: the deepest joint nesting a BVH may have (a body is about 10 deep; a hand's finger adds 4)
MAX_BVH_DEPTH = 200


def _parse_joint(tok: _Tokens, joints: list[_BvhJoint], parent: int, n_channels: int, depth: int = 1) -> int:
    """Parse ``name { OFFSET .. CHANNELS .. children }`` after ROOT/JOINT; return channel count."""
    if depth > MAX_BVH_DEPTH:
        raise tok.error(f"joints nested at most {MAX_BVH_DEPTH} deep", "a deeper joint")
    name = tok.next("a joint name")
    tok.expect("{")
    tok.expect("OFFSET")
    offset = np.array([tok.number("an OFFSET number") for _ in range(3)])
    tok.expect("CHANNELS")
    count = tok.number("a channel count")
    if count != int(count) or not 0 <= count <= 9:
        raise tok.error("a channel count from 0 to 9", repr(count))
    channels = []
    for _ in range(int(count)):
        ch = tok.next("a channel name").capitalize()  # 'XROTATION' -> 'Xrotation'
        if ch not in _CHANNELS:
            tok.i -= 1
            raise tok.error("a channel name such as Zrotation or Xposition")
        channels.append(ch)
    index = len(joints)
    joints.append(_BvhJoint(name, parent, offset, channels, n_channels))
    n_channels += len(channels)
    return _parse_children(tok, joints, index, n_channels, depth)


def _parse_children(tok: _Tokens, joints: list[_BvhJoint], index: int, n_channels: int, depth: int = 1) -> int:
    """Parse the JOINT / End Site children of joint ``index`` up to its closing brace."""
    while True:
        word = tok.next("JOINT, End Site or '}'")
        if word == "}":
            return n_channels
        if word.upper() == "JOINT":
            n_channels = _parse_joint(tok, joints, index, n_channels, depth + 1)
        elif word.upper() == "END":
            tok.expect("Site")
            tok.expect("{")
            tok.expect("OFFSET")
            offset = np.array([tok.number("an End Site OFFSET number") for _ in range(3)])
            tok.expect("}")
            joints.append(_BvhJoint(f"{joints[index].name}_end", index, offset, [], n_channels))
        else:
            tok.i -= 1
            raise tok.error("JOINT, End Site or '}'")


def _parse_hierarchy(path: Path, lines: list[str]) -> tuple[list[_BvhJoint], int, int]:
    """Parse the HIERARCHY section; return the joints, the channel count and the MOTION line index."""
    motion_at = next((i for i, line in enumerate(lines) if line.strip().upper() == "MOTION"), None)
    if motion_at is None:
        raise MotionFormatError(f"{path}: line {len(lines)}: expected a MOTION section, found end of file")
    tok = _Tokens(path, lines[:motion_at])
    tok.expect("HIERARCHY")
    joints: list[_BvhJoint] = []
    n_channels = 0
    while tok.i < len(tok.items):
        tok.expect("ROOT")
        n_channels = _parse_joint(tok, joints, -1, n_channels)
    if not joints:
        raise tok.error("a ROOT joint")
    return joints, n_channels, motion_at


def _parse_header_value(path: Path, lines: list[str], i: int, label: str) -> float:
    """The number after ``label`` on line ``i`` (0-based) or raise naming the line."""
    line = lines[i] if i < len(lines) else ""
    head, _, value = line.partition(":")
    try:
        if " ".join(head.split()).lower() != label.lower() or not math.isfinite(float(value)):
            raise ValueError
        return float(value)
    except ValueError:
        raise MotionFormatError(
            f"{path}: line {i + 1}: expected '{label}: <number>', found {line.strip()!r}"
        ) from None


def _parse_motion_header(path: Path, lines: list[str], motion_at: int) -> tuple[int, float]:
    """The frame count and the frame time in seconds (the two lines after MOTION)."""
    n_frames = _parse_header_value(path, lines, motion_at + 1, "Frames")
    frame_time_s = _parse_header_value(path, lines, motion_at + 2, "Frame Time")
    if n_frames != int(n_frames) or n_frames < 1:
        raise MotionFormatError(
            f"{path}: line {motion_at + 2}: expected a positive frame count, found {n_frames}")
    if not frame_time_s > 0:
        raise MotionFormatError(
            f"{path}: line {motion_at + 3}: expected a positive frame time, found {frame_time_s}")
    bounds.check("frame_time_s", frame_time_s, f"{path}: line {motion_at + 3}: Frame Time")
    return int(n_frames), frame_time_s


def _check_frames_fit(path: Path, line: int, n_frames: int, n_channels: int) -> None:
    """Refuse a ``Frames:`` count the file is too small to hold (before allocating for it).

    Each frame line holds ``n_channels`` numbers of at least one character and a separator.
    """
    size = path.stat().st_size
    most = size // max(1, 2 * n_channels)
    if n_frames > most:
        raise MotionFormatError(f"{path}: line {line}: Frames: expected at most {most} frames for a file of "
                                f"{size} bytes with {n_channels} channels, found {n_frames}")


def _read_bvh_header(f: TextIO) -> list[str]:
    """Lines up to the MOTION line and the two after it (Frames, Frame Time), or the whole file."""
    lines: list[str] = []
    motion_at = -1
    for line in f:
        lines.append(line.rstrip("\r\n"))
        if motion_at < 0 and line.strip().upper() == "MOTION":
            motion_at = len(lines) - 1
        if motion_at >= 0 and len(lines) >= motion_at + 3:
            break
    return lines


def _frame_chunks(f: TextIO) -> Iterator[list[str]]:
    """The remaining lines of ``f``, about :data:`BVH_CHUNK_FRAMES` at a time, without the file's
    trailing blank lines (a blank line between frames stays, to be reported)."""
    held: list[str] = []  # blank lines at a chunk's end: frames may still follow them
    while True:
        lines = list(itertools.islice(f, BVH_CHUNK_FRAMES))
        if not lines:
            return
        end = len(lines)
        while end and not lines[end - 1].strip():
            end -= 1
        if end:
            yield held + lines[:end] if held or end < len(lines) else lines
            held = []
        held.extend(lines[end:])


def _parse_chunk(path: Path, rows: list[str], first: int, n_channels: int) -> np.ndarray:
    """(len(rows), channels) values of some frame lines (``first``: 0-based line of the first)."""
    try:  # numpy's C parser, about 4x faster than float() on split fields (same values)
        frames = np.loadtxt(rows, dtype=float, comments=None, ndmin=2)
    except ValueError:
        frames = None
    if frames is None or frames.shape != (len(rows), n_channels):
        _raise_bad_frame(path, rows, first, n_channels)
    assert frames is not None
    _check_finite_frames(path, frames, first)
    return frames


def _check_finite_frames(path: Path, frames: np.ndarray, first: int) -> None:
    """Raise naming the file, line and frame of the first frame with a NaN or infinite value."""
    bad = np.flatnonzero(~np.isfinite(frames).all(axis=1))
    if bad.size:
        k = int(bad[0])
        value = frames[k][~np.isfinite(frames[k])][0]
        raise MotionFormatError(
            f"{path}: line {first + k + 1}: expected finite numbers in frame {k}, found {value}")


def _raise_bad_frame(path: Path, rows: list[str], first: int, n_channels: int) -> NoReturn:
    """Find the first frame line that is not ``n_channels`` numbers and raise naming it."""
    for k, row in enumerate(rows):
        fields = row.split()
        try:
            [float(f) for f in fields]
        except ValueError:
            bad = next(f for f in fields if not is_number(f))
            raise MotionFormatError(
                f"{path}: line {first + k + 1}: expected {n_channels} numbers, found {bad!r}"
            ) from None
        if len(fields) != n_channels:
            raise MotionFormatError(
                f"{path}: line {first + k + 1}: expected {n_channels} numbers, found {len(fields)}"
            )
    raise MotionFormatError(f"{path}: expected {n_channels} numbers per frame")  # pragma: no cover



#: the pair of columns a rotation about each axis mixes: (R @ R_axis(a))[:, i] = c R[:, i] + s R[:, k]
#: and [:, k] = c R[:, k] - s R[:, i] for (i, k) = _MIXED_COLUMNS[axis]
_MIXED_COLUMNS = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}


def _local_rotations(
    joints: list[_BvhJoint], channels: np.ndarray
) -> tuple[list[np.ndarray | None], list[np.ndarray | None]]:
    """Per joint, frames last: local rotation (3, 3, T) (None without rotation channels) and local
    translation (3, T) (None without position channels), from the channel values (channels, T).

    Position channels REPLACE the joint's OFFSET, as in Blender's importer and the BVH convention
    (root and child joints alike: a file with 6 channels on every joint gives each bone's vector in
    every frame); a component without a channel keeps the OFFSET's value.
    """
    n_frames = channels.shape[1]
    rotations: list[np.ndarray | None] = []
    translations: list[np.ndarray | None] = []
    for joint in joints:
        rot, trans = None, None
        for k, ch in enumerate(joint.channels):
            column = channels[joint.first_channel + k]
            if ch.endswith("rotation"):
                # BVH: rotations apply in the order listed, so R = R_first @ R_second @ ...
                if rot is None:
                    rot = np.broadcast_to(np.eye(3)[:, :, None], (3, 3, n_frames)).copy()
                angle = np.radians(column)
                _rotate_columns(rot, _MIXED_COLUMNS[ch[0]], np.cos(angle), np.sin(angle))
            else:
                if trans is None:
                    trans = np.repeat(joint.offset[:, None], n_frames, axis=1)
                trans["XYZ".index(ch[0])] = column
        rotations.append(rot)
        translations.append(trans)
    return rotations, translations


def _rotate_columns(rot: np.ndarray, columns: tuple[int, int], cos: np.ndarray, sin: np.ndarray) -> None:
    """In place: ``rot @ R_axis(angle)`` for rotations (3, 3, T), the axis given by the columns it mixes."""
    i, k = columns
    first = rot[:, i].copy()
    rot[:, i] = cos * first + sin * rot[:, k]
    rot[:, k] = cos * rot[:, k] - sin * first


def detect_bvh_unit_m(rest_height_units: float) -> tuple[str, float]:
    """Choose a BVH length unit from the rest-pose height in file units.

    The rule: the first unit of :data:`BVH_UNITS_M` (metre, CMU cgspeed 0.05644 m, inch,
    centimetre, millimetre) that makes the rest-pose height (all joints and end sites, zero
    rotations, along the up axis) fall in :data:`STATURE_RANGE_M` (1.1-2.3 m). The ranges do not
    overlap, so a CMU cgspeed skeleton (about 30 units tall) is recognised as such.

    Parameters
    ----------
    rest_height_units : float
        Height of the skeleton in its rest pose, in file units.

    Returns
    -------
    name : str
    unit_m : float

    Raises
    ------
    UserError
        If no candidate gives a human height (pass ``unit_m`` explicitly then).
    """
    lo, hi = STATURE_RANGE_M
    for name, unit_m in BVH_UNITS_M:
        if lo <= rest_height_units * unit_m <= hi:
            return name, unit_m
    raise UserError(
        f"unit_m: cannot tell the BVH length unit from a rest-pose height of {rest_height_units:.4g} units "
        f"(no unit among {', '.join(n for n, _ in BVH_UNITS_M)} gives {lo}-{hi} m); pass unit_m explicitly"
    )


#: a BVH's up axis is detected on every ``max(1, n_frames // UP_FRAMES)``-th frame (the whole-clip
#: and the streamed readers detect it on the same frames)
UP_FRAMES = 600


def _bvh_up(up_axis: str | None, positions: np.ndarray, names: Sequence[str], offsets: np.ndarray,
            parents: np.ndarray) -> tuple[str, str]:
    """The file's up axis and how it was decided: ``up_axis`` if given, else :func:`detect_up_axis`
    on posed frames in the file's axes (BVH's convention, y, when no head and feet are named)."""
    if up_axis is not None:
        return up_axis, "given (--up)"
    return detect_up_axis(positions, names, "y", rest_pose(offsets, parents))


def _check_up_axis(up_axis: str | None) -> str | None:
    """``up_axis`` checked (one of :data:`effortface.synth.read_options.UP_AXES`, or None)."""
    from effortface.synth.read_options import check_up  # the one check of an up axis

    return check_up(up_axis, "up_axis")


def read_bvh(path: str | Path, *, unit_m: float | None = None, up_axis: str | None = None,
             dtype: Any = None) -> Motion:
    """Read a BVH file into a :class:`Motion` (metres, Z up), any joint names and channel orders.

    A hand-written parser (numpy only, so the numpy/scipy-only runtime can read BVH). End sites
    become joints named ``<parent>_end``. Forward kinematics is vectorised over frames.

    Parameters
    ----------
    path : str or Path
        The ``.bvh`` file.
    unit_m : float, optional
        Length of one file unit in metres. When omitted it is detected from the rest pose's size
        along its longest axis by :func:`detect_bvh_unit_m` (CMU cgspeed files: 0.05644 m per unit).
    up_axis : {'x', 'y', 'z', '-x', '-y', '-z'}, optional
        The file's up axis. When omitted it is detected from gravity over the clip
        (:func:`detect_up_axis`; BVH's convention, y, when no head and feet are named). The
        positions come out Z up whatever it is.
    dtype : numpy dtype, optional
        Of the positions and rotations. Default: float64, and float32 for clips longer than
        :data:`FLOAT32_ABOVE_FRAMES` (a 1 h 120 Hz clip then holds 0.8 GB instead of 1.6 GB).
        The frames are parsed and posed :data:`BVH_CHUNK_FRAMES` at a time, so the reader's
        working memory does not grow with the clip.

    Returns
    -------
    Motion
        With :attr:`Motion.reading` ``unit_m``, ``unit_from``, ``up_axis``, ``up_from``.

    Raises
    ------
    MotionFormatError
        Missing file or malformed content; the message names the file and the line number.
    UserError
        Bad ``unit_m`` / ``up_axis``, or a unit that cannot be detected.

    Notes
    -----
    Position channels replace the joint's OFFSET (root and child joints alike), as Blender's
    importer does; a component without a channel keeps the OFFSET's.
    """
    path = Path(path)
    up_axis = _check_up_axis(up_axis)
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            lines = _read_bvh_header(f)
            joints, n_channels, motion_at = _parse_hierarchy(path, lines)
            n_frames, frame_time_s = _parse_motion_header(path, lines, motion_at)
            _check_frames_fit(path, motion_at + 2, n_frames, n_channels)
            parents = check_parents(np.array([j.parent for j in joints]), path)
            offsets = np.array([j.offset for j in joints])
            out_dtype = np.dtype(dtype) if dtype is not None else \
                np.dtype(np.float32 if n_frames > FLOAT32_ABOVE_FRAMES else np.float64)
            pos = np.empty((n_frames, len(joints), 3), dtype=out_dtype)
            rot = np.empty((n_frames, len(joints), 3, 3), dtype=out_dtype)
            _pose_frames(path, f, motion_at + 3, joints, parents, offsets, n_channels, (pos, rot))
    except OSError as exc:
        raise MotionFormatError(f"{path}: expected a readable BVH file, got {exc.strerror}") from None
    scale, unit_from = _bvh_scale(path, offsets, parents, unit_m)
    names = tuple(j.name for j in joints)
    up, up_from = _bvh_up(up_axis, pos[::max(1, n_frames // UP_FRAMES)], names, offsets, parents)
    to_z_up(pos, rot, up)
    pos *= scale
    check_positions(path, pos, names)
    return Motion(names, parents, pos, rot, _fps_from_frame_time(frame_time_s), str(path),
                  reading={"unit_m": scale, "unit_from": unit_from, "up_axis": up, "up_from": up_from})


def _pose_frames(path: Path, f: TextIO, first: int, joints: list[_BvhJoint], parents: np.ndarray,
                 offsets: np.ndarray, n_channels: int, out: tuple[np.ndarray, np.ndarray]) -> None:
    """Parse and pose the frame lines of ``f`` about :data:`BVH_CHUNK_FRAMES` at a time into ``out``
    (positions in file units and axes; rotations), so the working memory does not grow with the clip."""
    pos_out, rot_out = out
    done = 0
    for pos, rot in _posed_blocks(path, f, first, joints, parents, offsets, n_channels, len(pos_out)):
        pos_out[done:done + len(pos)] = pos
        rot_out[done:done + len(pos)] = rot
        done += len(pos)


def _posed_blocks(path: Path, f: TextIO, first: int, joints: list[_BvhJoint], parents: np.ndarray,
                  offsets: np.ndarray, n_channels: int,
                  n_frames: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The frame lines of ``f`` parsed and posed about :data:`BVH_CHUNK_FRAMES` at a time: positions
    (T, J, 3) in file units and axes, and rotations (T, J, 3, 3), float64 views; the frame count is
    checked against ``n_frames`` (the ``Frames:`` line)."""
    done = 0
    chunks = _frame_chunks(f)
    for chunk in chunks:
        if done + len(chunk) > n_frames:
            _check_frame_count(path, first, n_frames, done + len(chunk) + sum(len(c) for c in chunks))
        try:
            frames = _parse_chunk(path, chunk, first + done, n_channels)
        except MotionFormatError:
            _check_frame_count(path, first, n_frames, done + len(chunk) + sum(len(c) for c in chunks))
            raise
        pos, rot = _pose_chunk(joints, parents, offsets, frames)
        yield pos.transpose(2, 0, 1), rot.transpose(3, 0, 1, 2)
        done += len(chunk)
    _check_frame_count(path, first, n_frames, done)


@dataclasses.dataclass(frozen=True)
class MotionBlocks:
    """A clip read block by block (:func:`read_motion_blocks`): memory bounded by a block, not the clip.

    Attributes
    ----------
    skeleton : Motion
        Joint names, parents, fps and source; its frames are the clip's reference frames (every
        ``step``-th frame, ``step = max(1, n_frames // reference_frames)``, at most about twice
        ``reference_frames`` of them), for bone lengths.
    n_frames : int
        Frames of the whole clip.
    blocks : callable
        ``blocks()`` -> an iterator over consecutive (positions_m (T, J, 3), rotations (T, J, 3, 3)
        or None) blocks of the clip, in metres, Z up, as :func:`read_motion` gives them (same dtype
        and values); each call reads the clip again from its start.
    """

    skeleton: Motion
    n_frames: int
    blocks: Callable[[], Iterator[tuple[np.ndarray, np.ndarray | None]]]


def read_motion_blocks(path: str | Path, *, unit_m: float | None = None, up: str | None = None,
                       reference_frames: int = UP_FRAMES) -> MotionBlocks:
    """A motion file as :class:`MotionBlocks`: BVH streamed from the file, other formats read whole.

    A BVH file is read twice: a first pass counts the frame lines and poses the reference frames
    only, and every call of ``blocks()`` parses and poses :data:`BVH_CHUNK_FRAMES` at a time, so an
    hour at 120 Hz (432,000 frames, 0.8 GB as float32 positions and rotations) never sits in memory.
    The values are :func:`read_bvh`'s (float32 above :data:`FLOAT32_ABOVE_FRAMES`, the same scaling).
    The other formats (.npz, .csv, .c3d, registered readers, a registered ``.bvh`` reader) are read whole by :func:`read_motion`
    and handed out in slices: their readers hold the clip. ``unit_m`` and ``up`` are
    :func:`read_motion`'s; the skeleton's :attr:`Motion.reading` says how the clip was read (a BVH's
    up axis is detected on its reference frames, the frames :func:`read_bvh` uses with the default
    ``reference_frames``).

    Raises
    ------
    MotionFormatError, UserError
        As :func:`read_motion` (a bad frame line of a BVH may be raised by ``blocks()``).
    """
    path = Path(path)
    if path.suffix.lower() != ".bvh" or _READERS.get(".bvh") is not _read_bvh:  # not ours: read whole
        motion = read_motion(path, unit_m=unit_m, up=up)
        return _blocks_of(motion, reference_frames)
    if path.exists():
        check_regular_file(path, "a motion file (.bvh)", MotionFormatError)
    up = _check_up_axis(up)
    header = _bvh_stream_header(path, unit_m)
    step = max(1, header.n_frames // reference_frames)
    ref_pos, ref_rot = _bvh_reference_frames(path, header, step)
    up, up_from = _bvh_up(up, ref_pos, header.names, header.offsets, header.parents)
    header = dataclasses.replace(header, up_axis=up)
    ref_pos, ref_rot = _scaled(header, ref_pos, ref_rot)
    reading = {"unit_m": header.scale, "unit_from": header.unit_from, "up_axis": up, "up_from": up_from}
    skeleton = Motion(header.names, header.parents, ref_pos, ref_rot, header.fps, str(path), reading)
    return MotionBlocks(skeleton, header.n_frames, lambda: _bvh_blocks(path, header))


def _blocks_of(motion: Motion, reference_frames: int) -> MotionBlocks:
    """A motion already in memory as :class:`MotionBlocks` (slices of :data:`BVH_CHUNK_FRAMES`)."""
    step = max(1, motion.n_frames // reference_frames)
    rot = None if motion.rotations is None else motion.rotations[::step]
    skeleton = dataclasses.replace(motion, positions_m=motion.positions_m[::step], rotations=rot)

    def blocks() -> Iterator[tuple[np.ndarray, np.ndarray | None]]:
        for at in range(0, motion.n_frames, BVH_CHUNK_FRAMES):
            keep = slice(at, at + BVH_CHUNK_FRAMES)
            yield motion.positions_m[keep], None if motion.rotations is None else motion.rotations[keep]

    return MotionBlocks(skeleton, motion.n_frames, blocks)


@dataclasses.dataclass(frozen=True)
class _BvhHeader:
    """What a streamed BVH read needs from the file's header."""

    joints: list[_BvhJoint]
    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    n_channels: int
    first: int          # 0-based line of the first frame
    n_frames: int
    fps: float
    dtype: np.dtype
    scale: float
    unit_from: str
    up_axis: str = "z"  # until detected from the reference frames


def _bvh_stream_header(path: Path, unit_m: float | None) -> _BvhHeader:
    """Parse the hierarchy and motion header of a BVH file (as :func:`read_bvh`)."""
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            lines = _read_bvh_header(f)
    except OSError as exc:
        raise MotionFormatError(f"{path}: expected a readable BVH file, got {exc.strerror}") from None
    joints, n_channels, motion_at = _parse_hierarchy(path, lines)
    n_frames, frame_time_s = _parse_motion_header(path, lines, motion_at)
    _check_frames_fit(path, motion_at + 2, n_frames, n_channels)
    parents = check_parents(np.array([j.parent for j in joints]), path)
    offsets = np.array([j.offset for j in joints])
    dtype = np.dtype(np.float32 if n_frames > FLOAT32_ABOVE_FRAMES else np.float64)
    return _BvhHeader(joints, tuple(j.name for j in joints), parents, offsets, n_channels, motion_at + 3,
                      n_frames, _fps_from_frame_time(frame_time_s), dtype, *_bvh_scale(path, offsets, parents, unit_m))


def _scaled(header: _BvhHeader, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posed frames in :func:`read_bvh`'s dtype, metres and Z up (the same operations, the same values)."""
    pos = pos.astype(header.dtype, copy=False)  # a float64 block: the posed arrays themselves
    rot = rot.astype(header.dtype, copy=False)
    to_z_up(pos, rot, header.up_axis)
    pos *= header.scale
    return pos, rot


def _bvh_reference_frames(path: Path, header: _BvhHeader, step: int) -> tuple[np.ndarray, np.ndarray]:
    """First pass: count the frame lines (raise on a wrong count) and pose every ``step``-th frame
    (file units and axes, float64)."""
    rows: list[str] = []
    numbers: list[int] = []
    done = 0
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            _read_bvh_header(f)
            for chunk in _frame_chunks(f):
                for k in range(-done % step, len(chunk), step):
                    rows.append(chunk[k])
                    numbers.append(done + k)
                done += len(chunk)
    except OSError as exc:
        raise MotionFormatError(f"{path}: expected a readable BVH file, got {exc.strerror}") from None
    _check_frame_count(path, header.first, header.n_frames, done)
    frames = np.concatenate([_parse_chunk(path, [row], header.first + k, header.n_channels)
                             for row, k in zip(rows, numbers)]) if rows else np.zeros((0, header.n_channels))
    pos, rot = _pose_chunk(header.joints, header.parents, header.offsets, frames)
    return np.ascontiguousarray(pos.transpose(2, 0, 1)), np.ascontiguousarray(rot.transpose(3, 0, 1, 2))


def _bvh_blocks(path: Path, header: _BvhHeader) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Second pass: the clip's frames, posed and scaled, :data:`BVH_CHUNK_FRAMES` at a time."""
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            _read_bvh_header(f)
            done = 0
            for pos, rot in _posed_blocks(path, f, header.first, header.joints, header.parents, header.offsets,
                                          header.n_channels, header.n_frames):
                pos, rot = _scaled(header, pos, rot)
                check_positions(path, pos, header.names, first_frame=done)
                yield pos, rot
                done += len(pos)
    except OSError as exc:
        raise MotionFormatError(f"{path}: expected a readable BVH file, got {exc.strerror}") from None


def _pose_chunk(joints: list[_BvhJoint], parents: np.ndarray, offsets: np.ndarray,
                frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World positions (J, 3, T) in file units and axes, and rotations (J, 3, 3, T), of some frames
    (T, channels). The root's position channels replace its OFFSET, as every joint's do."""
    local, trans = _local_rotations(joints, np.ascontiguousarray(frames.T))
    root = trans[0] if trans[0] is not None else offsets[0][:, None]
    return _pose_components(parents, offsets, local, np.broadcast_to(root, (3, len(frames))),
                            [None, *trans[1:]])


def to_z_up(positions: np.ndarray, rotations: np.ndarray | None, up: str) -> None:
    """Turn world positions (..., 3) and rotations (..., 3, 3) from a file's axes to Z up, in place.

    The turn is :data:`UP_TO_Z_UP` ``[up]``, a signed permutation of the axes, so the values are
    exact (the same numbers, moved and maybe negated), and it is done :data:`BVH_CHUNK_FRAMES` frames
    at a time (a long clip's working memory does not double).
    """
    turn = UP_TO_Z_UP[up]
    if up == "z":
        return
    order = np.argmax(np.abs(turn), axis=1)
    sign = turn[np.arange(3), order].astype(positions.dtype)
    for at in range(0, len(positions), BVH_CHUNK_FRAMES):
        keep = slice(at, at + BVH_CHUNK_FRAMES)
        positions[keep] = positions[keep][..., order] * sign
        if rotations is not None:
            rotations[keep] = rotations[keep][..., order, :] * sign[:, None]


def _check_frame_count(path: Path, first: int, n_frames: int, n_rows: int) -> None:
    """Raise unless the file has as many frame lines as its ``Frames:`` line says."""
    if n_rows != n_frames:
        raise MotionFormatError(
            f"{path}: line {first + n_rows}: expected {n_frames} frame lines (Frames:), found {n_rows}")


def _fps_from_frame_time(frame_time_s: float) -> float:
    """1 / frame time, snapped to the nearest integer when within 0.01 % (``.0083333`` -> 120)."""
    fps = 1.0 / frame_time_s
    return float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps


def _checked_unit_m(unit_m: float) -> float:
    """``unit_m`` as a float if it is a positive finite length in metres, else UserError."""
    if isinstance(unit_m, bool) or not (isinstance(unit_m, (int, float)) and math.isfinite(unit_m) and unit_m > 0):
        raise UserError(f"unit_m: expected a positive length in metres, got {unit_m!r}")
    return float(unit_m)


def rest_pose(offsets: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Joint positions (J, 3) of the rest pose: every OFFSET, no rotation, in file units and axes."""
    rest = np.zeros_like(offsets)
    for j, p in enumerate(parents):
        rest[j] = offsets[j] + (rest[p] if p >= 0 else 0.0)
    return rest


def _bvh_scale(path: Path, offsets: np.ndarray, parents: np.ndarray, unit_m: float | None) -> tuple[float, str]:
    """Metres per file unit and how it was decided: ``unit_m`` if given (checked), else detected from
    the rest pose's size along its longest axis (the OFFSETs, whatever way the rest pose lies: a body
    lying along x in its rest pose, or a T-pose whose arm span is its height, measure the same)."""
    if unit_m is not None:
        return _checked_unit_m(unit_m), "given (--unit-m)"
    extent = np.ptp(rest_pose(offsets, parents), axis=0)
    size = float(extent.max())
    try:
        name, scale = detect_bvh_unit_m(size)
    except UserError:
        lo, hi = STATURE_RANGE_M
        raise MotionFormatError(
            f"{path}: expected a skeleton whose rest pose is {lo}-{hi} m tall in one of the units "
            f"{', '.join(n for n, _ in BVH_UNITS_M)}, found a rest-pose height of {size:.4g} file units "
            f"(its longest axis; give the unit: --unit-m M)"
        ) from None
    return scale, f"rest pose {size:.4g} units along {'xyz'[int(extent.argmax())]} -> {name} ({scale:g} m)"


# --------------------------------------------------------------------------------------------
# npz (retargeted AMP clips)

_NPZ_KEYS = ("fps", "node_names", "parent_indices", "local_translation", "rotation_xyzw_local",
             "root_translation")


def read_npz_motion(
    path: str | Path,
    *,
    end_sites_m: Mapping[str, Sequence[tuple[str, Sequence[float]]]] | None = None,
) -> Motion:
    """Read a retargeted skeleton-motion ``.npz`` (the AMP humanoid clips): metres, Z up.

    Keys (see ``motion_and_physiology_PROVENANCE.md``): ``fps``, ``node_names`` (J,),
    ``parent_indices`` (J,), ``local_translation`` (J, 3) m, ``rotation_xyzw_local`` (T, J, 4)
    local quaternions x, y, z, w, ``root_translation`` (T, 3) m.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file (loaded with ``allow_pickle=False``).
    end_sites_m : mapping, optional
        ``body -> ((end_name, (x, y, z)), ...)``: extra end points fixed in a body's frame, added as
        joints so terminal segments (head, hands, feet) have a distal end. Defaults to
        :data:`AMP_END_SITES_M`; bodies not present are ignored.

    Returns
    -------
    Motion

    Raises
    ------
    MotionFormatError
        Unreadable file, missing key or inconsistent shapes (named in the message).
    """
    path = Path(path)
    data = _load_npz(path)
    names = [str(n) for n in np.atleast_1d(data["node_names"])]
    parents = np.atleast_1d(data["parent_indices"])
    offsets = _float_array(path, data, "local_translation")
    quats = _float_array(path, data, "rotation_xyzw_local")
    root = _float_array(path, data, "root_translation")
    n_joints = len(names)
    if parents.shape != (n_joints,) or offsets.shape != (n_joints, 3) or quats.shape[1:] != (n_joints, 4) \
            or root.shape != (quats.shape[0], 3):
        raise MotionFormatError(
            f"{path}: expected parent_indices ({n_joints},), local_translation ({n_joints}, 3), "
            f"rotation_xyzw_local (T, {n_joints}, 4) and root_translation (T, 3), got {parents.shape}, "
            f"{offsets.shape}, {quats.shape}, {root.shape}"
        )
    fps = _npz_fps(path, data["fps"])
    parents = check_parents(parents, path)
    _check_npz_values(path, offsets, quats, root)
    names, parents, offsets, local_rot = _add_end_sites(
        names, parents, offsets, quaternions_xyzw_to_matrices(quats),
        AMP_END_SITES_M if end_sites_m is None else end_sites_m,
    )
    pos, rot = forward_kinematics(parents, offsets, local_rot, root)
    check_positions(path, pos, names)
    return Motion(tuple(names), parents, pos, rot, fps, str(path),
                  reading={"unit_m": 1.0, "unit_from": "the format (metres)", "up_axis": "z",
                           "up_from": "the format (Z up)"})


def _float_array(path: Path, data: Mapping[str, np.ndarray], key: str) -> np.ndarray:
    """``data[key]`` as a float array, or raise naming the file and key if it is not numeric."""
    value = np.asarray(data[key])
    if value.dtype.kind not in "biuf":
        raise MotionFormatError(f"{path}: {key}: expected numbers, found {value.dtype} values")
    return value.astype(float)


def _npz_fps(path: Path, value: np.ndarray) -> float:
    """The clip's frame rate: one finite number above 0, or raise naming the file and its fps."""
    value = np.asarray(value)
    if value.size != 1 or value.dtype.kind not in "iuf" or not (np.isfinite(value) & (value > 0)).all():
        shown = value.tolist() if value.size <= 4 else f"an array of shape {value.shape}"
        raise MotionFormatError(f"{path}: fps: expected one positive frame rate, found {shown}")
    fps = float(value.reshape(()))
    if not BOUNDS["motion_fps"].contains(fps):
        raise MotionFormatError(f"{path}: fps: expected {BOUNDS['motion_fps'].describe()}, found {fps:g}")
    return fps


def _check_npz_values(path: Path, offsets: np.ndarray, quats: np.ndarray, root: np.ndarray) -> None:
    """Raise naming the file (and first bad frame) for non-finite values or zero quaternions."""
    check_finite(path, "local_translation", offsets, frame_axis=False)
    check_finite(path, "rotation_xyzw_local", quats)
    check_finite(path, "root_translation", root)
    if quats.shape[0] < 1:
        raise MotionFormatError(f"{path}: rotation_xyzw_local: expected at least one frame, found 0")
    zero = np.linalg.norm(quats, axis=-1) < 1e-12
    if zero.any():
        frame, joint = (int(i[0]) for i in np.nonzero(zero))
        raise MotionFormatError(
            f"{path}: rotation_xyzw_local: expected unit quaternions, found (0, 0, 0, 0) at frame "
            f"{frame}, joint {joint}")


def _is_lone_npy(path: Path) -> bool:
    """True if ``path`` starts with the ``.npy`` magic (a single array, not an archive)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(6) == b"\x93NUMPY"
    except OSError:
        return False


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    """Load the npz arrays (no pickle) and check the keys are present."""
    if _is_lone_npy(path):
        raise MotionFormatError(f"{path}: expected a .npz archive of arrays, found a single .npy array")
    loaded = load_npz(path, MotionFormatError, "a readable .npz motion file")
    missing = [k for k in _NPZ_KEYS if k not in loaded]
    if missing:
        raise MotionFormatError(f"{path}: expected keys {', '.join(_NPZ_KEYS)}; missing {', '.join(missing)}")
    return loaded


def _add_end_sites(
    names: list[str],
    parents: np.ndarray,
    offsets: np.ndarray,
    local_rot: np.ndarray,
    end_sites_m: Mapping[str, Sequence[tuple[str, Sequence[float]]]],
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Append fixed end points (identity local rotation) as joints after all existing ones."""
    extra = [(names.index(body), end, off)
             for body, ends in end_sites_m.items() if body in names for end, off in ends]
    if not extra:
        return names, parents, offsets, local_rot
    names = names + [end for _, end, _ in extra]
    parents = np.concatenate([parents, [p for p, _, _ in extra]])
    offsets = np.concatenate([offsets, np.array([off for _, _, off in extra], dtype=float)])
    eye = np.broadcast_to(np.eye(3), (local_rot.shape[0], len(extra), 3, 3))
    return names, parents, offsets, np.concatenate([local_rot, eye], axis=1)
